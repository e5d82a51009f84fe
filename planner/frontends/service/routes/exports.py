"""A done job's exports (``/v1/jobs/{id}/...``): the trajectory (CSV, JSON) and the URScript program streamed from
the saved job by the export verb (:mod:`planner.export.verb`: the bytes ``planner plan -o`` writes), and the plot
(drawn once by the same verb in the drawing process, then kept in this replica's cache folder)."""

from __future__ import annotations

import asyncio
from typing import Any, Literal

from fastapi import APIRouter, HTTPException
from fastapi.responses import FileResponse, Response, StreamingResponse

from planner.errors import PlannerError
from planner.frontends.service.deps import OwnJob, Service, ServiceDep
from planner.frontends.service.errors import Unprocessable
from planner.frontends.service.store import Job

router = APIRouter(prefix="/jobs", tags=["exports"])
_NOT_YOURS: dict[int | str, dict[str, Any]] = {404: {"description": "no such job of this key"},
                                               409: {"description": "job not done"}}


@router.get("/{job_id}/trajectory",
            responses={200: {"content": {"text/csv": {}, "application/json": {}, "text/plain": {}}}, **_NOT_YOURS})
def trajectory(svc: ServiceDep, row: OwnJob,
               format: Literal["csv", "json", "script"] = "csv") -> Response:  # noqa: A002
    """The trajectory (CSV, JSON) or URScript program: the bytes ``planner plan -o`` writes, streamed."""
    from planner.export import file_name, stream
    from planner.export.verb import MEDIA_TYPES

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


@router.get("/{job_id}/plot.png", response_class=FileResponse,
            responses={200: {"content": {"image/png": {}}}, **_NOT_YOURS})
async def plot(svc: ServiceDep, row: OwnJob) -> FileResponse:
    """The picture ``planner plan --plot x.png`` draws (drawn once, in the drawing process, then kept in this
    replica's cache folder)."""
    if row.state != "done" or not row.job_file:
        raise HTTPException(409, f"job {row.id} is {row.state}; exports exist once it is done")
    folder = svc.cfg.data_dir / "plots"  # this replica's cache of pictures drawn from the stored plans
    target = folder / f"{row.id}.{row.attempts}.png"
    if not target.is_file():  # (through a symbolic link: a regular file; anything else is refused by the draw)
        plan = svc.plan_bytes(row)
        try:
            await asyncio.wrap_future(svc.plotter.draw(plan, row.input_name, str(target)))
        except PlannerError as exc:  # the service's own folder holds something it must not replace
            raise HTTPException(500, f"job {row.id}: the picture cannot be stored: {exc}") from None
    return FileResponse(target, media_type="image/png")


def _load_done(svc: Service, row: Job):
    from planner.job import load_job

    if row.state != "done" or not row.job_file:
        raise HTTPException(409, f"job {row.id} is {row.state}; exports exist once it is done")
    return load_job(svc.plan_bytes(row))
