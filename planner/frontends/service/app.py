"""The FastAPI application: job routes, exports streamed from the saved job, health, metrics and the page.

``create_app(config)`` builds an app whose lifespan opens (and migrates) the store, re-queues jobs a previous
run left running, and starts the worker pool; ``planner serve`` runs it under uvicorn.

Errors: a user's mistake (bad JSON, a bad setting, a file the reader refuses) is 422 with ``detail`` a list of
``{"loc": [...], "msg": ...}`` naming the field (and, for a file, the reader's message with its line); a job of
another key is 404 exactly like a job that does not exist; an export of a job that is not done is 409.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import gc
import json
import re
import shutil
import sys
import time
import uuid
from collections.abc import AsyncIterator
from typing import Annotated, Any, Literal

from fastapi import FastAPI, HTTPException, Query, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, PlainTextResponse, Response, StreamingResponse
from pydantic import ValidationError
from sqlalchemy import select
from starlette.datastructures import UploadFile

from planner.errors import PlannerError
from planner.frontends.service.auth import Principal
from planner.frontends.service.config import ServiceConfig
from planner.frontends.service.deps import API, Caller, Service, caller, own_job, principal
from planner.frontends.service.deps import service as _service
from planner.frontends.service.schemas import JobCreated, JobList, JobView, ReadOptions, SettingsModel, WaypointJob
from planner.frontends.service.store import Job, now
from planner.frontends.service.workers import job_dir, remove_job_files


# -- errors ------------------------------------------------------------------------------------------
class Unprocessable(HTTPException):
    """422 naming the field: ``detail`` = [{"loc": [...], "msg": ..., "type": ...}]."""

    def __init__(self, loc: list, msg: str, kind: str = "value_error"):
        super().__init__(422, [{"loc": loc, "msg": msg, "type": kind}])


def _validation_detail(exc: ValidationError, prefix: list) -> list[dict]:
    """pydantic errors without the (possibly huge or non-JSON) input values."""
    return [{"loc": prefix + list(e["loc"]), "msg": e["msg"], "type": e["type"]}
            for e in exc.errors(include_url=False, include_context=False, include_input=False)]


def _settings_loc(message: str, prefix: list) -> list:
    """The first setting a PlanSettings message names (``"tolerance must be ..."``), else the settings object."""
    known = set(SettingsModel.model_fields)
    name = next((w for w in re.findall(r"[a-z_]+", message) if w in known), None)
    return prefix if name is None else prefix + [name]


# -- the request body limit (pure ASGI: counts the bytes as they arrive) --------------------------------
class BodyLimit:
    def __init__(self, app, limit: int):
        self.app = app
        self.limit = limit

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        for name, value in scope.get("headers", []):
            if name == b"content-length" and value.isdigit() and int(value) > self.limit:
                return await self._too_large(send)
        seen = 0

        async def counted():
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.limit:
                    raise _TooLarge()
            return message

        try:
            await self.app(scope, counted, send)
        except _TooLarge:
            with contextlib.suppress(Exception):
                await self._too_large(send)

    async def _too_large(self, send):
        body = json.dumps({"detail": f"request body larger than the service's limit of {self.limit} bytes"}).encode()
        await send({"type": "http.response.start", "status": 413,
                    "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]})
        await send({"type": "http.response.body", "body": body})


class _TooLarge(Exception):
    pass


def job_view(svc: Service, job: Job) -> dict:
    """The JSON of ``GET /v1/jobs/{id}``."""
    base = f"{API}/jobs/{job.id}"
    t = {"queued_s": ((job.started_at or job.finished_at or now()) - job.created_at),
         "running_s": None if job.started_at is None else (job.finished_at or now()) - job.started_at,
         "planning_s": job.planning_s}
    links: dict[str, str] = {"self": base}
    if job.state == "done":
        links.update({"csv": f"{base}/trajectory?format=csv", "json": f"{base}/trajectory?format=json",
                      "plot": f"{base}/plot.png"})
        if json.loads(job.settings).get("robot"):
            links["script"] = f"{base}/trajectory?format=script"
    return {
        "id": job.id, "state": job.state, "created_at": job.created_at, "started_at": job.started_at,
        "finished_at": job.finished_at,
        "progress": {"stage": job.stage, "done": job.done, "total": job.total},
        "attempts": job.attempts,
        "input": {"kind": job.input_kind, "name": job.input_name, "format": job.input_format,
                  "bytes": job.input_bytes},
        "settings": json.loads(job.settings), "read_options": json.loads(job.read_options), "timings": t,
        "summary": json.loads(job.summary) if job.summary else None,
        "describe": json.loads(job.describe) if job.describe else None,
        "error": {"kind": job.error_kind or "", "message": job.error} if job.error else None,
        "note": job.note,
        "storage_bytes": job.input_bytes + job.job_bytes + len(job.settings) + len(job.summary or ""),
        "links": links,
    }


def _safe_name(filename: str | None) -> str:
    """A file name of our own making from an upload's name: its base name, [A-Za-z0-9._-] only, no leading dot."""
    base = re.split(r"[\\/]", filename or "")[-1]
    name = re.sub(r"[^A-Za-z0-9._-]", "_", base).lstrip(".")[:120]
    return name or "upload.txt"


_JOB_BODY = {
    "requestBody": {
        "required": True,
        "content": {
            "application/json": {"schema": {"$ref": "#/components/schemas/WaypointJob"}},
            "multipart/form-data": {"schema": {
                "type": "object", "required": ["file"],
                "properties": {
                    "file": {"type": "string", "format": "binary",
                             "description": "toolpath file: APT/CLSF, 5-axis G-code, CSV or JSON"},
                    "settings": {"type": "string", "description": "JSON of SettingsModel"},
                    "read_options": {"type": "string", "description": "JSON of ReadOptions (units, machine)"},
                }}},
        },
    },
}


def create_app(cfg: ServiceConfig | None = None) -> FastAPI:
    """The service's ASGI app (``cfg`` default: from the environment)."""
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
                              "watch the job, download the trajectory (CSV, JSON), the URScript program and the plot.")
    app.add_middleware(FastSubmit)
    app.add_middleware(BodyLimit, limit=cfg.max_request_bytes)  # (added last: outside FastSubmit)

    @app.exception_handler(PlannerError)
    async def _planner_error(request: Request, exc: PlannerError):
        return JSONResponse({"detail": [{"loc": [], "msg": str(exc), "type": "planner_error"}]}, status_code=422)

    @app.get("/", include_in_schema=False)
    def page() -> HTMLResponse:
        from planner.frontends.service.page import PAGE

        return HTMLResponse(PAGE)

    @app.get("/healthz", tags=["service"])
    def healthz(request: Request) -> dict:
        svc = _service(request)
        with svc.sessions() as s:
            s.execute(select(1))
        return {"status": "ok", "workers": svc.pool.alive, "busy": svc.pool.busy, "dev_no_auth": svc.cfg.dev_no_auth}

    @app.get("/metrics", tags=["service"], response_class=PlainTextResponse)
    def metrics(request: Request) -> PlainTextResponse:
        svc = _service(request)
        text = svc.metrics.text(svc.pool.counts(), svc.pool.alive, svc.pool.busy, svc.executions.counts(),
                                svc.executions.running())
        return PlainTextResponse(text, media_type="text/plain; version=0.0.4; charset=utf-8")

    @app.post(f"{API}/jobs", status_code=202, response_model=JobCreated, tags=["jobs"], openapi_extra=_JOB_BODY,
              responses={413: {"description": "request too large"}, 415: {"description": "not JSON or multipart"},
                         422: {"description": "bad input, naming the field"}})
    async def submit(request: Request) -> JSONResponse:
        """Submit a job: JSON waypoints (WaypointJob) or a multipart upload of a toolpath file."""
        svc = _service(request)
        who = await principal(request)  # called directly: FastAPI's dependency solving costs more than the check
        ctype = request.headers.get("content-type", "").lower()
        if ctype.startswith("application/json"):
            job_id = await accept_json(svc, who, await request.body())
        elif ctype.startswith("multipart/form-data"):
            job_id = await _submit_file(svc, who, request)
        else:
            raise HTTPException(415, "send application/json (waypoints) or multipart/form-data (a toolpath file)")
        location = f"{API}/jobs/{job_id}"
        return JSONResponse({"id": job_id, "state": "queued", "location": location}, status_code=202,
                            headers={"Location": location})

    @app.get(f"{API}/jobs", response_model=JobList, tags=["jobs"])
    def list_jobs(request: Request, who: Caller, limit: Annotated[int, Query(ge=1, le=500)] = 50,
                  cursor: Annotated[int | None, Query(ge=0, description="next_cursor of the previous page")] = None
                  ) -> dict:
        """The caller's jobs, newest first."""
        svc = _service(request)
        q = select(Job).where(Job.owner == who.key_id)
        if cursor is not None:
            q = q.where(Job.seq < cursor)
        with svc.sessions() as s:
            rows = list(s.scalars(q.order_by(Job.seq.desc()).limit(limit + 1)))
        more = len(rows) > limit
        rows = rows[:limit]
        return {"jobs": [job_view(svc, j) for j in rows], "next_cursor": rows[-1].seq if more else None}

    @app.get(f"{API}/jobs/{{job_id}}", response_model=JobView, tags=["jobs"],
             responses={404: {"description": "no such job of this key"}})
    def get_job(request: Request, job_id: str, who: Caller) -> dict:
        """State, progress, timings, the summary the CLI prints, or the planner's error."""
        svc = _service(request)
        return job_view(svc, own_job(svc, who, job_id))

    @app.delete(f"{API}/jobs/{{job_id}}", response_model=JobView, tags=["jobs"],
                responses={404: {"description": "no such job of this key"}, 409: {"description": "job has ended"}})
    def cancel_job(request: Request, job_id: str, who: Caller) -> dict:
        """Cancel a queued or running job (a running job's worker is stopped within a second)."""
        svc = _service(request)
        job = own_job(svc, who, job_id)
        if svc.pool.cancel(job.id) is None:
            job = own_job(svc, who, job_id)
            raise HTTPException(409, f"job {job_id} is {job.state}; only queued or running jobs can be cancelled")
        return job_view(svc, own_job(svc, who, job_id))

    @app.get(f"{API}/jobs/{{job_id}}/trajectory", tags=["exports"],
             responses={200: {"content": {"text/csv": {}, "application/json": {}, "text/plain": {}}},
                        404: {"description": "no such job of this key"}, 409: {"description": "job not done"}})
    def trajectory(request: Request, job_id: str, who: Caller,
                   format: Literal["csv", "json", "script"] = "csv") -> Response:  # noqa: A002
        """The trajectory (CSV, JSON) or URScript program: the bytes ``planner plan -o`` writes, streamed."""
        from planner.export import file_name, stream
        from planner.export.verb import MEDIA_TYPES

        svc = _service(request)
        row = own_job(svc, who, job_id)
        job = _load_done(svc, row)
        name = file_name(row.input_name, format)
        try:  # the header (and the whole program) is made before the response starts
            pieces = stream(job, format, parameters={"input": row.input_name})
        except PlannerError as exc:
            raise Unprocessable(["query", "format"], str(exc)) from None
        headers = {"Content-Disposition": f'attachment; filename="{name}"'}
        if format == "script":  # one piece, made already: sent with its length
            return Response(b"".join(pieces), media_type=MEDIA_TYPES[format], headers=headers)
        return StreamingResponse(pieces, media_type=MEDIA_TYPES[format], headers=headers)

    @app.get(f"{API}/jobs/{{job_id}}/plot.png", tags=["exports"], response_class=FileResponse,
             responses={200: {"content": {"image/png": {}}}, 404: {"description": "no such job of this key"},
                        409: {"description": "job not done"}})
    async def plot(request: Request, job_id: str, who: Caller) -> FileResponse:
        """The picture ``planner plan --plot x.png`` draws (drawn once, in the drawing process, then kept beside the
        saved job)."""
        svc = _service(request)
        row = own_job(svc, who, job_id)
        if row.state != "done" or not row.job_file:
            raise HTTPException(409, f"job {row.id} is {row.state}; exports exist once it is done")
        folder = job_dir(svc.cfg, row.id)
        target = folder / f"plot.{row.attempts}.png"
        if not target.is_file():  # (through a symbolic link: a regular file; anything else is refused by the draw)
            try:
                await asyncio.wrap_future(svc.plotter.draw(str(folder / row.job_file), row.input_name, str(target)))
            except PlannerError as exc:  # the service's own folder holds something it must not replace
                raise HTTPException(500, f"job {row.id}: the picture cannot be stored: {exc}") from None
        return FileResponse(target, media_type="image/png")

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
    from planner.frontends.service.executions import router as executions_router

    app.include_router(executions_router, prefix=API)
    return app


#: The interpreter's thread switch interval in the service, s (Python's default 5 ms makes a request that needs the
#: lock held by a busy thread wait for it; the service's threads mostly wait on I/O).
SWITCH_INTERVAL = 0.001
#: Threads (and database connections) made ready at start-up.
WARM_THREADS = 20


def _warm(svc: Service) -> None:
    from planner.plan import waypoints_toolpath

    with svc.sessions() as s:
        s.execute(select(1))
        time.sleep(0.05)  # hold the connection: the others open their own
    req = WaypointJob.model_validate_json(b'{"waypoints": [[0, 0, 0], [1, 0, 0], [1, 1, 0]]}')
    waypoints_toolpath(req.waypoints)
    _checked_settings(req.settings, "waypoints", False, [])


def _load_done(svc: Service, row: Job):
    from planner.job import load_job

    if row.state != "done" or not row.job_file:
        raise HTTPException(409, f"job {row.id} is {row.state}; exports exist once it is done")
    return load_job(job_dir(svc.cfg, row.id) / row.job_file)


# -- submitting ------------------------------------------------------------------------------------------
#: JSON jobs up to this many waypoints are checked in the event loop (no thread hand-over); larger ones in a thread.
INLINE_WAYPOINTS = 2000


async def accept_json(svc: Service, who: Principal, body: bytes) -> str:
    """A JSON job (WaypointJob) checked and stored (committed): its id. HTTPException 422 naming the field, before
    anything is stored, if it is bad."""
    try:
        req = WaypointJob.model_validate_json(body)
    except ValidationError as exc:
        raise HTTPException(422, _validation_detail(exc, ["body"])) from None
    if len(req.waypoints) <= INLINE_WAYPOINTS:  # checked at once: well under a millisecond
        job_id, row = _waypoint_row(svc, who, req, body)
    else:
        job_id, row = await run_in_threadpool(_waypoint_row, svc, who, req, body)
    await svc.inserter.store(row)
    svc.metrics.count_submitted()
    return job_id


class FastSubmit:
    """``POST /v1/jobs`` with a JSON body, accepted without the framework's routing, request and dependency
    machinery (a quarter of the event loop's CPU for a submit of 100 waypoints: with 20 clients submitting at once,
    every request waits for the others' share). The same :func:`accept_json` as the route; a request it does not
    accept (no valid key, a bad body, another content type) goes to the route with its body replayed, which answers
    it exactly as it answers any request."""

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http" or scope["method"] != "POST" or scope["path"] != SUBMIT_PATH:
            return await self.app(scope, receive, send)
        headers = dict(scope["headers"])
        if not headers.get(b"content-type", b"").lower().startswith(b"application/json"):
            return await self.app(scope, receive, send)
        chunks = []
        while True:
            message = await receive()
            if message["type"] != "http.request":  # the client went away
                return
            chunks.append(message.get("body", b""))
            if not message.get("more_body", False):
                break
        body = b"".join(chunks)
        svc: Service = scope["app"].state.service
        try:
            key = headers.get(b"x-api-key")
            who = caller(svc, None if key is None else key.decode("latin-1"),
                         headers.get(b"authorization", b"").decode("latin-1"))
            job_id = await accept_json(svc, who, body)
        except HTTPException:
            return await self.app(scope, _replay(body, receive), send)
        location = f"{SUBMIT_PATH}/{job_id}"
        answer = json.dumps({"id": job_id, "state": "queued", "location": location}, separators=(",", ":")).encode()
        await send({"type": "http.response.start", "status": 202, "headers": [
            (b"content-length", str(len(answer)).encode()), (b"content-type", b"application/json"),
            (b"location", location.encode())]})
        await send({"type": "http.response.body", "body": answer})


SUBMIT_PATH = f"{API}/jobs"


def _replay(body: bytes, receive):
    """``receive`` that gives ``body`` (already read) first."""
    sent = False

    async def replayed():
        nonlocal sent
        if not sent:
            sent = True
            return {"type": "http.request", "body": body, "more_body": False}
        return await receive()

    return replayed


def _row(job_id: str, who: Principal, **values: Any) -> dict:
    """The columns of a new queued job."""
    return dict(id=job_id, owner=who.key_id, state="queued", created_at=now(), stage="", done=0, total=0, attempts=0,
                job_bytes=0, **values)


def _checked_settings(model: SettingsModel, fmt: str, has_axes: bool, prefix: list) -> str:
    """The settings as the planner will take them for this input, as the JSON stored with the job (422 naming the
    setting if they are refused)."""
    try:
        return _settings_json(model.model_dump_json(), fmt, has_axes)
    except PlannerError as exc:
        raise Unprocessable(_settings_loc(str(exc), prefix), str(exc)) from None


@functools.lru_cache(maxsize=256)
def _settings_json(model_json: str, fmt: str, has_axes: bool) -> str:
    """Checked settings by their JSON (clients send the same settings again and again: checked once each)."""
    from planner.plan import resolve

    settings = SettingsModel.model_validate_json(model_json).to_settings()
    resolve(settings, fmt, has_axes)
    return json.dumps(settings.to_dict())


def _waypoint_row(svc: Service, who: Principal, req: WaypointJob, body: bytes) -> tuple[str, dict]:
    """A JSON job checked as the planner will read it: its id and row (422 naming the field if it is bad). The
    input stored is the request's JSON itself (validated: the worker reads its waypoints, axes and feeds)."""
    from planner.plan import waypoints_toolpath

    n = len(req.waypoints)
    if n > svc.cfg.max_waypoints:
        raise Unprocessable(["body", "waypoints"], f"{n} waypoints; the service takes at most {svc.cfg.max_waypoints}")
    feeds = None if req.feeds is None else [float("nan") if f is None else f for f in req.feeds]
    try:
        waypoints_toolpath(req.waypoints, req.axes, feeds)
    except PlannerError as exc:
        msg = str(exc)
        field = next((f for f in ("axes", "feeds") if msg.startswith(f)), "waypoints")
        raise Unprocessable(["body", field], msg) from None
    settings = _checked_settings(req.settings, "waypoints", req.axes is not None, ["body", "settings"])
    job_id = uuid.uuid4().hex
    return job_id, _row(job_id, who, input_kind="waypoints", input_name="<waypoints>", input_format="waypoints",
                        input_bytes=len(body), input_json=body.decode("utf-8"), settings=settings,
                        read_options="{}")


async def _submit_file(svc: Service, who: Principal, request: Request) -> str:
    try:
        form = await request.form(max_files=1, max_fields=10)
    except HTTPException:
        raise
    except Exception as exc:
        raise Unprocessable(["body"], f"not a readable multipart form ({exc})") from None
    try:
        unknown = sorted(set(form.keys()) - {"file", "settings", "read_options"})
        if unknown:
            raise Unprocessable(["body", unknown[0]], f"unknown form field {unknown[0]!r} (known: file, settings, "
                                                      "read_options)")
        upload = form.get("file")
        if not isinstance(upload, UploadFile):
            raise Unprocessable(["body", "file"], "a toolpath file is needed in the form field 'file'")
        settings_model = _form_json(form.get("settings"), SettingsModel, "settings")
        options = _form_json(form.get("read_options"), ReadOptions, "read_options")
        job_id = uuid.uuid4().hex
        try:
            row = await run_in_threadpool(_create_file_job, svc, who, job_id, upload, settings_model, options)
        except BaseException:
            remove_job_files(svc.cfg, job_id)
            raise
        try:
            await svc.inserter.store(row)  # handed over: committed even if the client goes away meanwhile
        except Exception:  # the commit failed: no job refers to the files
            remove_job_files(svc.cfg, job_id)
            raise
        svc.metrics.count_submitted()  # as accept_json counts a JSON job: once stored
        return job_id
    finally:
        await form.close()


def _form_json(value, model, field: str):
    if value is None or value == "":
        return model()
    if not isinstance(value, str):
        raise Unprocessable(["body", field], f"{field} must be a JSON text field, not a file")
    try:
        return model.model_validate_json(value)
    except ValidationError as exc:
        raise HTTPException(422, _validation_detail(exc, ["body", field])) from None


def _create_file_job(svc: Service, who: Principal, job_id: str, upload: UploadFile, settings_model: SettingsModel,
                     options: ReadOptions) -> dict:
    """The upload saved in the job's folder and read as the planner will read it: the job's row (422 naming the field
    or the file's line if it is bad)."""
    from planner.export.files import atomic_binary
    from planner.io import detect_format, read_toolpath
    from planner.io.options import ReaderArgumentError

    name = _safe_name(upload.filename)
    folder = job_dir(svc.cfg, job_id) / "input"
    folder.mkdir(parents=True)
    path = folder / name
    with atomic_binary(path) as f:
        upload.file.seek(0)
        shutil.copyfileobj(upload.file, f, 1 << 20)
        size = f.tell()
    read_options = options.as_dict()
    try:
        fmt = detect_format(path)
        toolpath = read_toolpath(path, format=fmt, **read_options)
    except ReaderArgumentError as exc:  # an option this reader does not take, an unknown machine, ...
        raise Unprocessable(["body", "read_options", exc.argument], f"{name}: {exc}") from None
    except PlannerError as exc:
        raise Unprocessable(["body", "file"], str(exc)) from None
    except TypeError as exc:  # an option this reader does not take
        raise Unprocessable(["body", "read_options"], f"{name}: {exc}") from None
    except UnicodeError as exc:
        raise Unprocessable(["body", "file"], f"{name}: not a text file ({exc})") from None
    settings = _checked_settings(settings_model, fmt, toolpath.axes is not None, ["body", "settings"])
    return _row(job_id, who, input_kind="file", input_name=name, input_format=fmt, input_bytes=size, input_json=None,
                settings=settings, read_options=json.dumps(read_options))
