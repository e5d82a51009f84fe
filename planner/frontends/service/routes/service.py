"""The service itself: health (``/healthz``), metrics (``/metrics``, Prometheus text) and the page (``/``)."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import HTMLResponse, PlainTextResponse
from sqlalchemy import select

from planner.frontends.service.deps import ServiceDep
from planner.frontends.service.schemas import Health

router = APIRouter(tags=["service"])


@router.get("/", include_in_schema=False)
def page() -> HTMLResponse:
    from planner.frontends.service.page import PAGE

    return HTMLResponse(PAGE)


@router.get("/healthz", response_model=Health)
def healthz(svc: ServiceDep) -> dict:
    """The database answers; the planning workers alive and busy; whether keys are needed."""
    with svc.sessions() as s:
        s.execute(select(1))
    return {"status": "ok", "workers": svc.pool.alive, "busy": svc.pool.busy, "dev_no_auth": svc.cfg.dev_no_auth}


@router.get("/metrics", response_class=PlainTextResponse)
def metrics(svc: ServiceDep) -> PlainTextResponse:
    """Prometheus text: jobs and executions by state, workers, request figures."""
    text = svc.metrics.text(svc.pool.counts(), svc.pool.alive, svc.pool.busy, svc.executions.counts(),
                            svc.executions.running())
    return PlainTextResponse(text, media_type="text/plain; version=0.0.4; charset=utf-8")
