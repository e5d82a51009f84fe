"""Robot executions: ``POST /v1/jobs/{id}/executions`` runs a done job on a robot the operator configured
(:class:`.config.RobotConfig`, by name: a request never carries a host), one execution per robot at
a time; ``GET /v1/executions/{id}`` shows its state, progress and the execution report's figures (or the failure's
reason, job time, pose and source line); ``DELETE /v1/executions/{id}`` stops it (the arm stopped within a
second); ``GET /v1/robots`` lists the configured robots. Only keys of the ``operator`` role may execute or stop.
The runs themselves: the task layer (:mod:`planner.frontends.service.tasks`), on whichever backend.
"""

from __future__ import annotations

import json
import time
import uuid
from typing import Annotated

from fastapi import APIRouter, HTTPException, Query
from fastapi.responses import JSONResponse
from sqlalchemy import select

from planner.frontends.service.auth import Principal
from planner.frontends.service.deps import API, JOB_ID, Caller, Service, ServiceDep, own_job
from planner.frontends.service.errors import Unprocessable
from planner.frontends.service.schemas import (
    ExecutionCreated,
    ExecutionList,
    ExecutionRequest,
    ExecutionView,
    RobotList,
)
from planner.frontends.service.store import Execution, now
from planner.frontends.service.tasks.lifecycle import EXECUTION
from planner.frontends.service.tasks.runner import STOP_GRACE
from planner.frontends.service.tasks.transitions import RobotBusy

router = APIRouter(tags=["executions"])


def require_operator(who: Principal) -> None:
    if who.role != "operator":
        raise HTTPException(403, "running a job on a robot needs a key of the operator role")


def execution_view(row: Execution) -> dict:
    """The JSON of ``GET /v1/executions/{id}``."""
    error = None
    if row.error is not None:
        error = {"kind": row.error_kind or "", "reason": row.error, "t": row.error_t,
                 "pose": None if row.error_pose is None else json.loads(row.error_pose), "line": row.error_line}
    return {"id": row.id, "job_id": row.job_id, "robot": row.robot, "mode": row.mode, "state": row.state,
            "created_at": row.created_at, "started_at": row.started_at, "finished_at": row.finished_at,
            "progress": {"stage": row.stage, "done": row.done, "total": row.total},
            "report": None if row.report is None else json.loads(row.report), "error": error, "note": row.note,
            "links": {"self": f"{API}/executions/{row.id}", "job": f"{API}/jobs/{row.job_id}"}}


def own_execution(svc: Service, who: Principal, execution_id: str) -> Execution:
    """The caller's execution, or 404 (also for another key's: its existence is not revealed)."""

    if JOB_ID.match(execution_id):
        with svc.sessions() as s:
            row = s.scalars(select(Execution).where(Execution.id == execution_id,
                                                    Execution.owner == who.key_id)).first()
        if row is not None:
            return row
    raise HTTPException(404, f"no execution {execution_id}")


@router.post("/jobs/{job_id}/executions", status_code=202, response_model=ExecutionCreated,
             responses={403: {"description": "not an operator key"}, 404: {"description": "no such job of this key"},
                        409: {"description": "job not done, planned without a robot, not executable on "
                                                    "its robot (summary.not_executable), or the robot is busy"},
                        422: {"description": "unknown robot, or a robot of another model"}})
def create_execution(svc: ServiceDep, job_id: str, body: ExecutionRequest, who: Caller) -> JSONResponse:
    """Run a done job on a configured robot (by name), in "stream" (servoJ) or "program" (URScript) mode."""
    require_operator(who)
    job = own_job(svc, who, job_id)
    robot = svc.cfg.robot(body.robot)
    if robot is None:
        names = ", ".join(r.name for r in svc.cfg.robots)
        raise Unprocessable(["body", "robot"], f"no robot named {body.robot!r} in this service's configuration "
                                               f"(configured: {names})")
    if job.state != "done" or not job.job_file:
        raise HTTPException(409, f"job {job_id} is {job.state}; only a done job can be executed")
    model = json.loads(job.settings).get("robot")
    if not model:
        raise HTTPException(409, f"job {job_id} was planned without a robot model (settings.robot); plan it for "
                                 "the robot to execute it")
    if robot.model is not None and robot.model != model:
        raise Unprocessable(["body", "robot"], f"robot {robot.name!r} is a {robot.model}; job {job_id} is planned "
                                               f"for a {model}")
    reason = json.loads(job.summary).get("not_executable") if job.summary else None
    if reason:  # refused before a controller is started or a robot is reached (PlannedJob.not_executable)
        raise HTTPException(409, f"job {job_id} cannot run on its robot: {reason}")
    execution_id = uuid.uuid4().hex
    try:
        svc.backend.start_execution(dict(id=execution_id, job_id=job.id, owner=who.key_id, robot=robot.name,
                                         mode=body.mode, state="starting", created_at=now(), stage="starting", done=0,
                                         total=0))
    except RobotBusy:
        raise HTTPException(409, f"robot {robot.name!r} is busy with another execution; one execution per robot "
                                 "at a time") from None
    location = f"{API}/executions/{execution_id}"
    return JSONResponse({"id": execution_id, "state": "starting", "location": location}, status_code=202,
                        headers={"Location": location})


@router.get("/executions", response_model=ExecutionList)
def list_executions(svc: ServiceDep, who: Caller, limit: Annotated[int, Query(ge=1, le=500)] = 50,
                    job_id: Annotated[str | None, Query(max_length=32, description="only this job's")] = None
                    ) -> dict:
    """The caller's executions, newest first."""

    q = select(Execution).where(Execution.owner == who.key_id)
    if job_id is not None:
        q = q.where(Execution.job_id == job_id)
    with svc.sessions() as s:
        rows = list(s.scalars(q.order_by(Execution.seq.desc()).limit(limit)))
    return {"executions": [execution_view(r) for r in rows]}


@router.get("/executions/{execution_id}", response_model=ExecutionView,
            responses={404: {"description": "no such execution of this key"}})
def get_execution(svc: ServiceDep, execution_id: str, who: Caller) -> dict:
    """An execution's state, progress, report figures and failure (reason, job time, pose, source line)."""
    return execution_view(own_execution(svc, who, execution_id))


@router.delete("/executions/{execution_id}", response_model=ExecutionView,
               responses={403: {"description": "not an operator key"},
                          404: {"description": "no such execution of this key"},
                          409: {"description": "the execution has ended"}})
def stop_execution(svc: ServiceDep, execution_id: str, who: Caller) -> dict:
    """Stop an execution: the arm is brought to rest (controlled stop) and the job's outputs switched off; answers
    once the execution has ended (a few seconds at most)."""

    require_operator(who)
    row = own_execution(svc, who, execution_id)
    if row.state not in EXECUTION.active:
        raise HTTPException(409, f"execution {execution_id} is {row.state}; only a running one can be stopped")
    if svc.backend.stop_execution(row.id):  # wherever it runs: its runner reads the stop in the store
        deadline = time.monotonic() + STOP_GRACE + 5.0
        while svc.store.state(EXECUTION, row.id) in EXECUTION.active and time.monotonic() < deadline:
            time.sleep(0.05)
    return execution_view(own_execution(svc, who, execution_id))


@router.get("/robots", response_model=RobotList)
def list_robots(svc: ServiceDep, who: Caller) -> dict:
    """The robots jobs can be executed on: name, model (null: a simulated robot of the job's model), simulated,
    busy."""
    return {"robots": [{"name": r.name, "model": r.model, "simulated": r.simulated, "mode_default": "stream",
                        "busy": svc.store.robot_busy(r.name)} for r in svc.cfg.robots]}
