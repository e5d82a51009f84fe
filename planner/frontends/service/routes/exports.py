"""A done job's exports: the trajectory (CSV, JSON) and the URScript program streamed from the saved job by the
export verb, and the plot (drawn once, in the drawing process)."""

from __future__ import annotations

import asyncio
from typing import Literal

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import FileResponse, Response, StreamingResponse

from planner.errors import PlannerError
from planner.frontends.service.deps import API, Caller, Service, own_job
from planner.frontends.service.deps import service as _service
from planner.frontends.service.errors import Unprocessable
from planner.frontends.service.store import Job
from planner.frontends.service.workers import job_dir

router = APIRouter()


@router.get(f"{API}/jobs/{{job_id}}/trajectory", tags=["exports"],
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


@router.get(f"{API}/jobs/{{job_id}}/plot.png", tags=["exports"], response_class=FileResponse,
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


def _load_done(svc: Service, row: Job):
    from planner.job import load_job

    if row.state != "done" or not row.job_file:
        raise HTTPException(409, f"job {row.id} is {row.state}; exports exist once it is done")
    return load_job(job_dir(svc.cfg, row.id) / row.job_file)
