"""The service itself: health, metrics (Prometheus text) and the page."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse, PlainTextResponse
from sqlalchemy import select

from planner.frontends.service.deps import service as _service

router = APIRouter()


@router.get("/", include_in_schema=False)
def page() -> HTMLResponse:
    from planner.frontends.service.page import PAGE

    return HTMLResponse(PAGE)


@router.get("/healthz", tags=["service"])
def healthz(request: Request) -> dict:
    svc = _service(request)
    with svc.sessions() as s:
        s.execute(select(1))
    return {"status": "ok", "workers": svc.pool.alive, "busy": svc.pool.busy, "dev_no_auth": svc.cfg.dev_no_auth}


@router.get("/metrics", tags=["service"], response_class=PlainTextResponse)
def metrics(request: Request) -> PlainTextResponse:
    svc = _service(request)
    text = svc.metrics.text(svc.pool.counts(), svc.pool.alive, svc.pool.busy, svc.executions.counts(),
                            svc.executions.running())
    return PlainTextResponse(text, media_type="text/plain; version=0.0.4; charset=utf-8")
