"""Jobs: submit (JSON waypoints or a toolpath file), list, show, cancel (``/v1/jobs``)."""

from __future__ import annotations

import json
from typing import Annotated

from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.responses import JSONResponse
from sqlalchemy import select

from planner.frontends.service.deps import API, Caller, OwnJob, Service, ServiceDep, own_job, principal
from planner.frontends.service.deps import service as _service
from planner.frontends.service.fast_submit import created
from planner.frontends.service.schemas import JobCreated, JobList, JobView
from planner.frontends.service.store import Job, now
from planner.frontends.service.submit import accept_file, accept_json

router = APIRouter(prefix="/jobs", tags=["jobs"])


def job_view(svc: Service, job: Job) -> dict:
    """The JSON of ``GET /v1/jobs/{id}`` (:class:`.schemas.JobView`; its routes answer with
    ``response_model_exclude_unset``: a key left out here, such as a robot's figures of a job planned without one or
    the link to an export that does not exist yet, stays out of the JSON)."""
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


@router.post("", status_code=202, response_model=JobCreated, openapi_extra=_JOB_BODY,
             responses={413: {"description": "request too large"}, 415: {"description": "not JSON or multipart"},
                        422: {"description": "bad input, naming the field"}})
async def submit(request: Request) -> JSONResponse:
    """Submit a job: JSON waypoints (WaypointJob) or a multipart upload of a toolpath file. (A JSON job is mostly
    answered by the fast submit path, :mod:`..fast_submit`, with the same answer.)"""
    svc = _service(request)
    who = await principal(request)  # called directly: FastAPI's dependency solving costs more than the check
    ctype = request.headers.get("content-type", "").lower()
    if ctype.startswith("application/json"):
        job_id = await accept_json(svc, who, await request.body())
    elif ctype.startswith("multipart/form-data"):
        job_id = await accept_file(svc, who, request)
    else:
        raise HTTPException(415, "send application/json (waypoints) or multipart/form-data (a toolpath file)")
    body, location = created(job_id)
    return JSONResponse(body, status_code=202, headers={"Location": location})


@router.get("", response_model=JobList, response_model_exclude_unset=True)
def list_jobs(svc: ServiceDep, who: Caller, limit: Annotated[int, Query(ge=1, le=500)] = 50,
              cursor: Annotated[int | None, Query(ge=0, description="next_cursor of the previous page")] = None
              ) -> dict:
    """The caller's jobs, newest first."""
    q = select(Job).where(Job.owner == who.key_id)
    if cursor is not None:
        q = q.where(Job.seq < cursor)
    with svc.sessions() as s:
        rows = list(s.scalars(q.order_by(Job.seq.desc()).limit(limit + 1)))
    more = len(rows) > limit
    rows = rows[:limit]
    return {"jobs": [job_view(svc, j) for j in rows], "next_cursor": rows[-1].seq if more else None}


@router.get("/{job_id}", response_model=JobView, response_model_exclude_unset=True,
            responses={404: {"description": "no such job of this key"}})
def get_job(svc: ServiceDep, job: OwnJob) -> dict:
    """State, progress, timings, the summary the CLI prints, or the planner's error."""
    return job_view(svc, job)


@router.delete("/{job_id}", response_model=JobView, response_model_exclude_unset=True,
               responses={404: {"description": "no such job of this key"}, 409: {"description": "job has ended"}})
def cancel_job(svc: ServiceDep, who: Caller, job: OwnJob) -> dict:
    """Cancel a queued or running job (a running job's worker is stopped within a second)."""
    before = svc.backend.cancel_job(job.id)
    if before is not None:
        svc.metrics.count_finished("cancelled")
    if before is None:
        job = own_job(svc, who, job.id)
        raise HTTPException(409, f"job {job.id} is {job.state}; only queued or running jobs can be cancelled")
    return job_view(svc, own_job(svc, who, job.id))
