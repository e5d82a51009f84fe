"""The routes, one module per resource (the layout of FastAPI's full-stack template): :mod:`.jobs` (submit, list,
show, cancel), :mod:`.exports` (a done job's trajectory, program and plot), :mod:`.executions` (runs on robots,
the robots), :mod:`.view` (the page's 3D view: a job's scene, its path in detail, an execution's live
joint states) under ``/v1`` (:data:`api_router`), and :mod:`.service` (health, metrics, the page) at the root."""

from fastapi import APIRouter, Security

from planner.frontends.service.auth import API_KEY
from planner.frontends.service.routes import executions, exports, jobs, view

#: Every versioned route (included under ``/v1``), each needing a key (the schema's security scheme ``APIKey``: the
#: key in ``X-API-Key``; checked by ``deps.principal``).
api_router = APIRouter(dependencies=[Security(API_KEY)])
api_router.include_router(jobs.router)
api_router.include_router(exports.router)
api_router.include_router(executions.router)
api_router.include_router(view.router)
