"""The service itself: health (``/healthz``), metrics (``/metrics``, Prometheus text) and the page (``/``)."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import HTMLResponse, PlainTextResponse
from sqlalchemy import select

from planner.frontends.service.deps import ServiceDep
from planner.frontends.service.schemas import Health
from planner.frontends.service.tasks.lifecycle import EXECUTION, JOB

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
    alive, busy = svc.backend.workers()
    return {"status": "ok", "workers": alive, "busy": busy, "dev_no_auth": svc.cfg.dev_no_auth}


@router.get("/metrics", response_class=PlainTextResponse)
def metrics(svc: ServiceDep) -> PlainTextResponse:
    """Prometheus text: jobs and executions by state (the whole cluster's, from the store), queue depth (from the
    queue itself), workers alive and busy, this process's request figures."""
    alive, busy = svc.backend.workers()
    text = svc.metrics.text(svc.store.counts(JOB), alive, busy, svc.store.counts(EXECUTION),
                            svc.store.robots_running([r.name for r in svc.cfg.robots]),
                            queue_depth=svc.backend.queue_depth())
    return PlainTextResponse(text, media_type="text/plain; version=0.0.4; charset=utf-8")
