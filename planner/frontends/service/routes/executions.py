"""Robot executions: ``POST /v1/jobs/{id}/executions`` runs a done job on a robot the operator configured
(:class:`.config.RobotConfig`, by name: a request never carries a host), one execution per robot at
a time; ``GET /v1/executions/{id}`` shows its state, progress and the execution report's figures (or the failure's
reason, job time, pose and source line); ``DELETE /v1/executions/{id}`` stops it (the arm stopped within a
second); ``GET /v1/robots`` lists the team's robots. A team's keys see its executions; only keys of the
``operator`` role may execute (on the team's robots, :mod:`..teams`) or stop. An execution belongs to its job's team.
The runs themselves: the task layer (:mod:`planner.frontends.service.tasks`), on whichever backend.
"""

from __future__ import annotations

import asyncio
import json
import time
import uuid
from typing import Annotated

from fastapi import APIRouter, HTTPException, Query
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse, JSONResponse
from sqlalchemy import select

from drivers.base import DEFAULT_MODE
from planner.errors import PlannerError
from planner.frontends.service.auth import NOT_OPERATOR, Principal
from planner.frontends.service.deps import API, JOB_ID, Caller, Service, ServiceDep, own_job, shown_id
from planner.frontends.service.errors import CheckedRoute, Unprocessable, documented
from planner.frontends.service.schemas import (
    ExecutionCreated,
    ExecutionList,
    ExecutionRequest,
    ExecutionView,
    RobotList,
    links,
)
from planner.frontends.service.store import Execution, JobData, now
from planner.frontends.service.tasks.lifecycle import EXECUTION, progress_view
from planner.frontends.service.tasks.runner import STOP_GRACE
from planner.frontends.service.tasks.transitions import RobotBusy
from planner.frontends.service.teams import team_robots

router = APIRouter(tags=["executions"], route_class=CheckedRoute)


def require_operator(who: Principal) -> None:
    if who.role != "operator":
        raise HTTPException(403, NOT_OPERATOR)


def execution_view(row: Execution) -> dict:
    """The JSON of ``GET /v1/executions/{id}``."""
    error = None
    if row.error is not None:
        error = {"kind": row.error_kind or "", "reason": row.error, "t": row.error_t,
                 "pose": None if row.error_pose is None else json.loads(row.error_pose), "line": row.error_line}
    return {"id": row.id, "job_id": row.job_id, "robot": row.robot, "mode": row.mode, "state": row.state,
            "created_at": row.created_at, "started_at": row.started_at, "finished_at": row.finished_at,
            "progress": progress_view("execution", row.state, row.stage, row.done, row.total),
            "report": None if row.report is None else json.loads(row.report), "error": error, "note": row.note,
            "links": {"self": f"{API}/executions/{row.id}", "job": f"{API}/jobs/{row.job_id}",
                      **({"plot": f"{API}/executions/{row.id}/plot.png"} if _plotted(row) else {})}}


def _plotted(row: Execution) -> bool:
    """Whether the execution has a picture of its run: it ended after its run began (its trace stored as it
    ended)."""
    return row.state not in EXECUTION.active and row.started_at is not None


def own_execution(svc: Service, who: Principal, execution_id: str) -> Execution:
    """The caller's team's execution, or 404 (also for another team's: its existence is not revealed)."""

    if JOB_ID.match(execution_id):
        with svc.sessions() as s:
            row = s.scalars(select(Execution).where(Execution.id == execution_id,
                                                    Execution.team == who.team)).first()
        if row is not None:
            return row
    raise HTTPException(404, f"no execution {shown_id(execution_id)}")


@router.post("/jobs/{job_id}/executions", status_code=202, response_model=ExecutionCreated,
             responses={202: {"links": links("execution_id", "get_execution", "stop_execution", "execution_plot")},
                        **documented(403, 404, 409, 413, 422,
                                     e404="no such job of this key's team",
                                     e409="the job is not done, was planned without a robot, cannot run on its robot "
                                          "(summary.not_executable: the reason), or the robot is busy",
                                     e422="no robot of that name for this key's team, a robot of another model, or a "
                                          "refused body (not a JSON object, not UTF-8, an unknown field)")})
def create_execution(svc: ServiceDep, job_id: str, body: ExecutionRequest, who: Caller) -> JSONResponse:
    """Run a done job of the team on one of the team's robots (by name), in "program" (URScript, the default) or
    "stream" (servoJ) mode."""
    require_operator(who)
    job = own_job(svc, who, job_id)
    robots = _team_robots(svc, who)
    robot = next((r for r in robots if r.name == body.robot), None)
    if robot is None:  # (a robot of another team is refused as one that is not configured)
        names = ", ".join(r.name for r in robots) or "none"
        raise Unprocessable(["body", "robot"], f"no robot named {body.robot!r} for team {who.team!r} (its robots: "
                                               f"{names})")
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
        svc.backend.start_execution(dict(id=execution_id, job_id=job.id, owner=who.key_id, team=job.team,
                                         robot=robot.name, mode=body.mode, state="starting", created_at=now(),
                                         stage="starting", done=0, total=0))
    except RobotBusy:
        raise HTTPException(409, f"robot {robot.name!r} is busy with another execution; one execution per robot "
                                 "at a time") from None
    location = f"{API}/executions/{execution_id}"
    return JSONResponse({"id": execution_id, "state": "starting", "location": location}, status_code=202,
                        headers={"Location": location})


@router.get("/executions", response_model=ExecutionList, responses=documented(422))
def list_executions(svc: ServiceDep, who: Caller, limit: Annotated[int, Query(ge=1, le=500)] = 50,
                    job_id: Annotated[str | None, Query(max_length=32, description="only this job's")] = None
                    ) -> dict:
    """The caller's team's executions, newest first."""

    q = select(Execution).where(Execution.team == who.team)
    if job_id is not None:
        q = q.where(Execution.job_id == job_id)
    with svc.sessions() as s:
        rows = list(s.scalars(q.order_by(Execution.seq.desc()).limit(limit)))
    return {"executions": [execution_view(r) for r in rows]}


@router.get("/executions/{execution_id}", response_model=ExecutionView,
            responses=documented(404, e404="no such execution of this key's team"))
def get_execution(svc: ServiceDep, execution_id: str, who: Caller) -> dict:
    """An execution's state, progress, report figures and failure (reason, job time, pose, source line)."""
    return execution_view(own_execution(svc, who, execution_id))


@router.delete("/executions/{execution_id}", response_model=ExecutionView,
               responses=documented(403, 404, 409, e404="no such execution of this key's team",
                                    e409="the execution has ended: only a running one can be stopped"))
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


@router.get("/executions/{execution_id}/plot.png", response_class=FileResponse,
            responses={200: {"content": {"image/png": {}}},
                       **documented(404, 409, e404="no such execution of this key's team, or no plot of it: it ended "
                                                   "before its run recorded anything",
                                    e409="the execution has not ended: its plot is drawn once it has")})
async def execution_plot(svc: ServiceDep, execution_id: str, who: Caller) -> FileResponse:
    """The picture of the job with the run drawn over it (actual over planned), as ``planner run --plot`` draws it
    (from the run's trace stored as it ended; drawn once, in the drawing process, then kept in this replica's cache
    folder)."""
    row = await run_in_threadpool(own_execution, svc, who, execution_id)
    if row.state in EXECUTION.active:
        raise HTTPException(409, f"execution {execution_id} is {row.state}; its plot is drawn once it has ended")
    target = svc.cfg.data_dir / "plots" / f"run-{row.id}.png"
    if not target.is_file():
        trace, plan = await run_in_threadpool(_run_data, svc, row)
        if trace is None or plan is None or row.report is None:
            raise HTTPException(404, f"execution {execution_id} has no plot: it ended ({row.state}) before its run "
                                     "recorded anything")
        try:
            await asyncio.wrap_future(svc.plotter.draw_run(plan, json.loads(row.report), trace, str(target)))
        except PlannerError as exc:  # the service's own folder holds something it must not replace
            raise HTTPException(500, f"execution {row.id}: the picture cannot be stored: {exc}") from None
    return FileResponse(target, media_type="image/png")


def _run_data(svc: Service, row: Execution) -> tuple[bytes | None, bytes | None]:
    """An execution's stored trace and its job's saved plan (None where missing)."""
    with svc.engine.connect() as conn:
        data = dict(conn.execute(select(JobData.job_id, JobData.data).where(
            ((JobData.job_id == row.id) & (JobData.name == "run.trace")) |
            ((JobData.job_id == row.job_id) & (JobData.name == "plan")))).all())
    trace, plan = data.get(row.id), data.get(row.job_id)
    return None if trace is None else bytes(trace), None if plan is None else bytes(plan)


@router.get("/robots", response_model=RobotList, responses=documented())
def list_robots(svc: ServiceDep, who: Caller) -> dict:
    """The robots the caller's team may execute jobs on: name, model (null: a simulated robot of the job's model),
    simulated, the execution mode a request without one runs in, busy."""
    return {"robots": [{"name": r.name, "model": r.model, "simulated": r.simulated, "mode_default": DEFAULT_MODE,
                        "busy": svc.store.robot_busy(r.name)} for r in _team_robots(svc, who)]}


def _team_robots(svc: Service, who: Principal):
    """The configured robots of the caller's team."""
    with svc.sessions() as s:
        return team_robots(s, who.team, svc.cfg.robots)
