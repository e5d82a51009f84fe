"""The FastAPI application: ``create_app(config)`` wires the routes (one module per resource under
:mod:`.routes`), the dependencies (:mod:`.deps`), the request body limit and the fast submit path, and the lifespan.

The lifespan opens (and migrates) the store, re-queues jobs a previous run left running, and starts the worker pool;
``planner serve`` runs the app under uvicorn.

Errors: the database unreachable (restarted, the network) is 503 with the reason and ``Retry-After``, until it
answers again; a user's mistake (bad JSON, a bad setting, a file the reader refuses) is 422 with ``detail`` a list of
``{"loc": [...], "msg": ...}`` naming the field (and, for a file, the reader's message with its line); a job of
another key is 404 exactly like a job that does not exist; an export of a job that is not done is 409.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import sys
import time
from collections.abc import AsyncIterator

from fastapi import FastAPI, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse
from sqlalchemy import select
from sqlalchemy.exc import InterfaceError, OperationalError

from planner.errors import PlannerError
from planner.frontends.service.body_limit import BodyLimit
from planner.frontends.service.config import ServiceConfig
from planner.frontends.service.deps import API, Service
from planner.frontends.service.fast_submit import FastSubmit
from planner.frontends.service.routes import api_router
from planner.frontends.service.routes import service as service_routes
from planner.frontends.service.schemas import UNITS, WaypointJob
from planner.frontends.service.submit import _checked_settings

#: The interpreter's thread switch interval in the service, s (Python's default 5 ms makes a request that needs the
#: lock held by a busy thread wait for it; the service's threads mostly wait on I/O).
SWITCH_INTERVAL = 0.001
#: Threads (and database connections) made ready at start-up.
WARM_THREADS = 20


def create_app(cfg: ServiceConfig | None = None, *, fast_submit: bool = True) -> FastAPI:
    """The service's ASGI app (``cfg`` default: from the environment). ``fast_submit=False`` leaves every submit to
    the route (the fast path answers the same; a test compares them)."""
    cfg = cfg or ServiceConfig.from_env()

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        svc = Service(cfg)
        svc.start()
        app.state.service = svc
        # warm the request path before the first client: worker threads, database connections, validators
        await asyncio.gather(*[run_in_threadpool(_warm, svc) for _ in range(WARM_THREADS)])
        gc.collect()
        gc.freeze()  # the start-up objects (modules, schemas) are never scanned again: no long collection pauses
        sys.setswitchinterval(SWITCH_INTERVAL)
        try:
            yield
        finally:
            await run_in_threadpool(svc.stop)

    app = FastAPI(title="planner service", version="1", lifespan=lifespan, docs_url=None, redoc_url=None,
                  description="Path jobs for robot tool-orientation planning: submit waypoints or a toolpath file, "
                              "watch the job, download the trajectory (CSV, JSON), the URScript program and the plot, "
                              "run it on a robot. " + UNITS)
    if fast_submit:
        app.add_middleware(FastSubmit)
    app.add_middleware(BodyLimit, limit=cfg.max_request_bytes)  # (added last: outside FastSubmit)

    @app.exception_handler(PlannerError)
    async def _planner_error(request: Request, exc: PlannerError):
        return JSONResponse({"detail": [{"loc": [], "msg": str(exc), "type": "planner_error"}]}, status_code=422)

    @app.exception_handler(OperationalError)
    @app.exception_handler(InterfaceError)
    async def _store_unreachable(request: Request, exc: Exception):
        return JSONResponse({"detail": store_unreachable(exc)}, status_code=503, headers={"Retry-After": "2"})

    app.include_router(service_routes.router)
    app.include_router(api_router, prefix=API)

    def openapi() -> dict:
        if app.openapi_schema is None:
            from fastapi.openapi.utils import get_openapi

            spec = get_openapi(title=app.title, version=app.version, description=app.description, routes=app.routes)
            schema = WaypointJob.model_json_schema(ref_template="#/components/schemas/{model}")
            comps = spec.setdefault("components", {}).setdefault("schemas", {})
            comps.update(schema.pop("$defs", {}))
            comps["WaypointJob"] = schema
            app.openapi_schema = spec
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]  # the JSON body is parsed by hand (two content types)
    from planner.frontends.service.docs import add_docs

    add_docs(app)
    return app


def store_unreachable(exc: Exception) -> str:
    """The one-line reason of a 503 while the database does not answer."""
    orig = getattr(exc, "orig", None) or exc
    first = next((line.strip() for line in str(orig).splitlines() if line.strip()), type(orig).__name__)
    return f"the job store (database) does not answer; try again shortly ({first[:200]})"


def _warm(svc: Service) -> None:
    from planner.plan import waypoints_toolpath

    with svc.sessions() as s:
        s.execute(select(1))
        time.sleep(0.05)  # hold the connection: the others open their own
    req = WaypointJob.model_validate_json(b'{"waypoints": [[0, 0, 0], [1, 0, 0], [1, 1, 0]]}')
    waypoints_toolpath(req.waypoints)
    _checked_settings(req.settings, "waypoints", False, [])
