"""Submitting a job: a JSON job (:class:`.schemas.WaypointJob`) or a multipart upload of a toolpath file, checked as
the planner will read it and stored, queued (:func:`accept_json`, :func:`accept_file`). Used by the route
(:mod:`.routes.jobs`) and the fast submit path (:mod:`.fast_submit`) alike.
"""

from __future__ import annotations

import functools
import json
import re
import shutil
import tempfile
import uuid
from pathlib import Path
from typing import Any

from fastapi import HTTPException, Request
from fastapi.concurrency import run_in_threadpool
from pydantic import ValidationError
from starlette.datastructures import UploadFile

from planner.errors import PlannerError
from planner.frontends.service.auth import Principal
from planner.frontends.service.deps import Service
from planner.frontends.service.errors import Unprocessable, _validation_detail
from planner.frontends.service.schemas import ReadOptions, SettingsModel, WaypointJob
from planner.frontends.service.store import now


def _safe_name(filename: str | None) -> str:
    """A file name of our own making from an upload's name: its base name, [A-Za-z0-9._-] only, no leading dot."""
    base = re.split(r"[\\/]", filename or "")[-1]
    name = re.sub(r"[^A-Za-z0-9._-]", "_", base).lstrip(".")[:120]
    return name or "upload.txt"


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
    await svc.inserter.store_job(row)
    svc.metrics.count_submitted()
    return job_id


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
        raise Unprocessable(prefix if exc.field is None else prefix + [exc.field], str(exc)) from None


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


async def accept_file(svc: Service, who: Principal, request: Request) -> str:
    """A multipart upload of a toolpath file (and its settings and read options) checked and stored: its id.
    HTTPException 422 naming the field or the file's line, before any row is stored, if it is bad."""
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
        row, data = await run_in_threadpool(_create_file_job, svc, who, job_id, upload, settings_model, options)
        await svc.inserter.store_job(row, data)  # handed over: committed even if the client goes away meanwhile
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
                     options: ReadOptions) -> tuple[dict, bytes]:
    """The upload read as the planner will read it (from a temporary folder): the job's row and the file's bytes
    (stored in the database: any worker plans it) (422 naming the field or the file's line if it is bad)."""
    from planner.io import detect_format, read_toolpath
    from planner.io.options import ReaderArgumentError

    name = _safe_name(upload.filename)
    with tempfile.TemporaryDirectory(prefix="planner-upload-") as folder:
        path = Path(folder) / name
        with open(path, "wb") as f:
            upload.file.seek(0)
            shutil.copyfileobj(upload.file, f, 1 << 20)
        data = path.read_bytes()
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
    return _row(job_id, who, input_kind="file", input_name=name, input_format=fmt, input_bytes=len(data),
                input_json=None, settings=settings, read_options=json.dumps(read_options)), data
