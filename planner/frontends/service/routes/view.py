"""The page's 3D view: its data and its files.

- ``GET /v1/jobs/{id}/view``: a done job's scene (the arm's DH model, the part frame, the I/O stations, the problems
  placed in time, and the path thinned to ``tolerance`` m, or to a pixel of a ``pixels``-wide view of the whole
  job): :mod:`planner.frontends.service.view_data`.
- ``GET /v1/jobs/{id}/view/path?t0=&t1=&tolerance=``: the path between two job times at a finer tolerance (detail on
  demand, as the page zooms in).
- ``GET /v1/executions/{id}/live``: the execution's joint states as Server-Sent Events (``text/event-stream``; each
  event a JSON list of rows [t, q0..q5, x, y, z, io], its id the last row's number: a reconnecting client sends
  ``Last-Event-ID`` and gets what it missed still kept); an ``end`` event once the execution ended. Read with the
  API key's header (fetch and a stream reader: EventSource cannot send one). Any API replica streams any
  execution (the celery backend relays the samples through Redis, :mod:`planner.frontends.service.live`).
- ``GET /view3d/{name}``: the view's script and the vendored three.js (a fixed list of files, gzip'd once).
"""

from __future__ import annotations

import asyncio
import gzip
import json
import threading
from collections import OrderedDict
from functools import lru_cache
from pathlib import Path
from typing import Annotated

import numpy as np
from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.responses import JSONResponse, Response, StreamingResponse
from starlette.concurrency import run_in_threadpool

from planner.errors import PlannerError
from planner.frontends.service import view_data
from planner.frontends.service.deps import Caller, OwnJob, Service, ServiceDep
from planner.frontends.service.errors import CheckedRoute, documented
from planner.frontends.service.routes.executions import own_execution
from planner.frontends.service.store import Job
from planner.frontends.service.tasks.lifecycle import EXECUTION

router = APIRouter(tags=["view"], route_class=CheckedRoute)
#: The view's files (under ``static/view3d``), with their media types.
STATIC = Path(__file__).resolve().parents[1] / "static" / "view3d"
FILES = {"view.js": "text/javascript; charset=utf-8", "view.css": "text/css; charset=utf-8",
         "vendor/three.module.min.js": "text/javascript; charset=utf-8",
         "vendor/OrbitControls.js": "text/javascript; charset=utf-8"}
#: Fine paths kept in memory (jobs).
CACHED = 4
#: Seconds between the live stream's events at most (a comment keeps an idle connection open).
LIVE_IDLE = 5.0

#: Scenes kept in memory (the same view asked again: a page reloaded, another person, another tab).
SCENES = 8

_cache: OrderedDict[tuple[str, int], tuple] = OrderedDict()
_scenes: OrderedDict[tuple, bytes | memoryview] = OrderedDict()
_cache_lock = threading.Lock()
_building: dict[tuple[str, int], threading.Lock] = {}


def _fine(svc: Service, row: Job):
    """(job, fine path, reach) of a done job: the fine path stored with its plan (made by the planning task), read
    once per job and kept (the :data:`CACHED` last)."""
    from planner.job import load_job

    if row.state != "done" or not row.job_file:
        raise HTTPException(409, f"job {row.id} is {row.state}; its view exists once it is done")
    key = (row.id, int(row.attempts))
    with _cache_lock:
        lock = _building.setdefault(key, threading.Lock())
    with lock:  # one build per job at a time; the others wait for it
        with _cache_lock:
            if key in _cache:
                _cache.move_to_end(key)
                return _cache[key]
        job = load_job(svc.plan_bytes(row))
        stored = svc.job_data(row, "view")  # made by the worker after a large job's end, or by a first request
        fine = None
        if stored is not None:
            try:
                fine = view_data.ViewPath.from_bytes(stored)
            except PlannerError:  # another version's: made again (and not stored over the other)
                fine = view_data.fine_path(job)
        if fine is None:  # a small job's first view (or a job planned before the view's data were stored)
            data = view_data.fine_path(job).to_bytes()
            svc.keep_job_data(row, "view", data)
            fine = view_data.ViewPath.from_bytes(data)  # as stored: every replica serves the same scene
        entry = (job, fine, view_data._reach(job))
        with _cache_lock:
            _cache[key] = entry
            while len(_cache) > CACHED:
                _cache.popitem(last=False)
            _building.pop(key, None)
        return entry


@router.get("/jobs/{job_id}/view", responses=documented(404, 409, 422, e404="no such job of this key's team",
                                                         e409="the job is not done"))
def view(svc: ServiceDep, row: OwnJob,
         tolerance: Annotated[float | None, Query(ge=view_data.FINE_TOLERANCE, le=view_data.MAX_TOLERANCE,
                                                  description="path tolerance, m (default: a pixel)")] = None,
         pixels: Annotated[int, Query(ge=100, le=20_000, description="the view's width, px")] = 1000) -> Response:
    """The 3D view's scene of a done job: the arm (DH), part frame, stations, problems and the path within
    ``tolerance`` (default: the size of one pixel of a ``pixels``-wide view of the whole path)."""
    job, fine, reach = _fine(svc, row)
    key = (row.id, int(row.attempts), tolerance, pixels)
    with _cache_lock:
        body = _scenes.get(key)
    if body is None:
        body = JSONResponse(view_data.scene(job, fine, reach, tolerance, pixels)).body
        with _cache_lock:
            _scenes[key] = body
            while len(_scenes) > SCENES:
                _scenes.popitem(last=False)
    return Response(bytes(body), media_type="application/json")


@router.get("/jobs/{job_id}/view/path", responses=documented(404, 409, 422, e404="no such job of this key's team",
                                                              e409="the job is not done"))
def view_path(svc: ServiceDep, row: OwnJob, t0: float, t1: float,
              tolerance: Annotated[float, Query(ge=view_data.FINE_TOLERANCE, le=view_data.MAX_TOLERANCE,
                                                description="path tolerance, m")] = view_data.FINE_TOLERANCE
              ) -> JSONResponse:
    """The path between job times ``t0`` and ``t1`` s within ``tolerance`` m (detail on demand)."""
    view_data.checked_window(tolerance, t0, t1)
    job, fine, reach = _fine(svc, row)
    return JSONResponse(view_data.detail(fine, reach, t0, t1, tolerance))


@router.get("/executions/{execution_id}/live", response_class=StreamingResponse,
            responses={200: {"content": {"text/event-stream": {}}},
                       **documented(404, e404="no such execution of this key's team")})
async def live(svc: ServiceDep, execution_id: str, who: Caller, request: Request) -> StreamingResponse:
    """The execution's joint states as they are recorded (Server-Sent Events, see the module doc)."""
    await run_in_threadpool(own_execution, svc, who, execution_id)
    try:
        seq = int(request.headers.get("last-event-id") or request.query_params.get("after") or 0)
    except ValueError:
        seq = 0

    hub = svc.backend.live  # this process's executions (local backend), or the workers' (celery: Redis)

    async def events():
        nonlocal seq
        yield "retry: 1000\n\n"
        idle = 0.0
        while True:
            feed = await run_in_threadpool(hub.feed, execution_id)
            if feed is None:  # not (or not yet) run by this process: its state tells whether to wait
                state = await run_in_threadpool(svc.store.state, EXECUTION, execution_id)
                if state not in EXECUTION.active:
                    yield f"event: end\ndata: {json.dumps({'state': state})}\n\n"
                    return
                await asyncio.sleep(0.2)
                idle += 0.2
                if idle >= LIVE_IDLE:
                    idle = 0.0
                    yield ": waiting\n\n"
                continue
            rows, ended = await run_in_threadpool(feed.after, seq, 0.1)
            if await request.is_disconnected():
                return
            if len(rows):
                seq = int(rows[-1, 0])
                data = np.round(rows[:, 1:], 6).tolist()
                yield f"id: {seq}\ndata: {json.dumps(data)}\n\n"
                idle = 0.0
            elif ended:  # (its end is stored before the feed ends; a moment more for another replica's read)
                for _ in range(50):
                    state = await run_in_threadpool(svc.store.state, EXECUTION, execution_id)
                    if state not in EXECUTION.active:
                        break
                    await asyncio.sleep(0.1)
                yield f"event: end\ndata: {json.dumps({'state': state})}\n\n"
                return
            else:
                idle += 0.1
                if idle >= LIVE_IDLE:
                    idle = 0.0
                    yield ": idle\n\n"

    return StreamingResponse(events(), media_type="text/event-stream",
                             headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"})


@lru_cache(maxsize=len(FILES))
def _packed(name: str) -> tuple[bytes, bytes]:
    data = (STATIC / name).read_bytes()
    return data, gzip.compress(data, 9, mtime=0)


static_router = APIRouter(include_in_schema=False)


@static_router.get("/view3d/{name:path}")
def asset(name: str, request: Request) -> Response:
    if name not in FILES:  # a fixed list: no name from a request reaches the file system
        raise HTTPException(404, f"no view file {name}")
    plain, packed = _packed(name)
    headers = {"Cache-Control": "no-cache", "Vary": "Accept-Encoding"}
    if "gzip" in request.headers.get("accept-encoding", ""):
        return Response(packed, media_type=FILES[name], headers={**headers, "Content-Encoding": "gzip"})
    return Response(plain, media_type=FILES[name], headers=headers)
