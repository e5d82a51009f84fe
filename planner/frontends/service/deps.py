"""What the routes share, as FastAPI dependencies (``Annotated`` types a route takes as parameters): the service
(:data:`ServiceDep`: configuration, store, task backend, metrics), the caller (:data:`Caller`) and the caller's team's
job of the path (:data:`OwnJob`, 404 for another team's).
"""

from __future__ import annotations

import re
from typing import Annotated

from fastapi import Depends, HTTPException, Request
from sqlalchemy import select

from planner.frontends.service.auth import CHALLENGE, DEV_PRINCIPAL, NO_KEY, Principal, authenticate
from planner.frontends.service.config import ServiceConfig
from planner.frontends.service.inserter import Inserter
from planner.frontends.service.metrics import Metrics
from planner.frontends.service.plots import Plotter
from planner.frontends.service.store import Checkpointer, Job, JobData, import_legacy_files, open_store
from planner.frontends.service.tasks.lifecycle import JOB, Kind, Outcome
from planner.frontends.service.tasks.transitions import Transitions

#: The prefix of every versioned route.
API = "/v1"
#: A job's (and an execution's) id: 32 hex digits.
JOB_ID = re.compile(r"^[0-9a-f]{32}$")
#: The largest cursor of a list (422 above): a signed 64-bit integer, what SQLite binds.
MAX_CURSOR = 2**63 - 1


class Service:
    """What the routes share: configuration, store, task backend, metrics."""

    def __init__(self, cfg: ServiceConfig):
        self.cfg = cfg
        bg = cfg.db_url.startswith("sqlite")  # WAL checkpoints (and their fsync) out of the commits requests wait for
        self.engine, self.sessions = open_store(cfg.db_url, background_checkpoints=bg)
        #: The largest seq a row can have (PostgreSQL's serial is 32-bit): a cursor above it is no limit at all,
        #: and never bound (PostgreSQL refuses a parameter out of its column's range).
        self.max_seq = 2**31 - 1 if self.engine.dialect.name == "postgresql" else MAX_CURSOR
        self.checkpointer = Checkpointer(self.engine) if bg else None
        self.metrics = Metrics()
        self.store = Transitions(self.engine)
        self.backend = make_backend(cfg, self.store, self.finished)
        self.inserter = Inserter(self.store, self.backend.submitted)
        self.plotter = Plotter(cfg.worker_nice)

    def finished(self, kind: Kind, outcome: Outcome, seconds: float) -> None:
        """A task's end was stored by this process: counted."""
        if kind is JOB:
            self.metrics.count_finished(outcome.state, outcome.planning_s)
        else:
            self.metrics.count_execution(outcome.state, seconds, outcome.error_kind)

    def start(self) -> dict:
        (self.cfg.data_dir / "plots").mkdir(parents=True, exist_ok=True)  # this replica's cache of pictures
        imported = import_legacy_files(self.engine, self.cfg.data_dir)  # the files of jobs stored by 0.1
        recovered = self.backend.start()
        recovered["legacy_files_imported"] = imported
        for _ in range(recovered.get("executions_failed", 0)):
            self.metrics.count_execution("failed", None, "interrupted")
        self.plotter.start()
        if self.checkpointer is not None:
            self.checkpointer.start()
        return recovered

    def stop(self) -> None:
        self.plotter.stop()
        self.inserter.close()
        self.backend.stop()
        if self.checkpointer is not None:
            self.checkpointer.stop()
        self.engine.dispose()

    def plan_bytes(self, job: Job) -> bytes:
        """The saved plan of a done job (from the store: any replica serves any job's exports)."""
        data = self.job_data(job, "plan")
        if data is None:
            raise HTTPException(500, f"job {job.id} is done but its plan is not in the store")
        return data

    def job_data(self, job: Job, name: str) -> bytes | None:
        """A job's stored bytes ``name`` ("input", "plan", "view"), or None."""
        with self.engine.connect() as conn:
            data = conn.scalar(select(JobData.data).where(JobData.job_id == job.id, JobData.name == name))
        return None if data is None else bytes(data)

    def keep_job_data(self, job: Job, name: str, data: bytes) -> None:
        """Store bytes made from a job after its end (the 3D view's data of a job whose planning task did not make
        them), unless another replica stored them first."""
        self.store.keep_data(job.id, name, data)


def make_backend(cfg: ServiceConfig, store: Transitions, finished):
    """The task backend of ``cfg.queue``: local worker processes (the default) or Celery workers."""
    if cfg.queue == "celery":
        from planner.frontends.service.tasks.celery_backend import CeleryBackend

        return CeleryBackend(store, cfg, finished)
    from planner.frontends.service.tasks.local import LocalBackend

    return LocalBackend(store, cfg, finished)


def service(request: Request) -> Service:
    return request.app.state.service


async def principal(request: Request) -> Principal:
    """The caller: the key of ``X-API-Key`` (or ``Authorization: Bearer``), or the development operator (checked in
    the event loop: one indexed read, no thread hand-over)."""
    return caller(service(request), request.headers.get("x-api-key"), request.headers.get("authorization", ""))


def caller(svc: Service, api_key: str | None, authorization: str) -> Principal:
    """The principal of a request's ``X-API-Key`` / ``Authorization`` header values; 401 if the key is not valid."""
    if svc.cfg.dev_no_auth:
        return DEV_PRINCIPAL
    key = api_key
    if authorization.lower().startswith("bearer "):
        key = authorization[7:].strip()
    with svc.sessions() as s:
        who = authenticate(s, key)
    if who is None:
        raise HTTPException(401, NO_KEY, headers=CHALLENGE)
    return who


Caller = Annotated[Principal, Depends(principal)]


def own_job(svc: Service, who: Principal, job_id: str) -> Job:
    """The caller's team's job, or 404 (also for another team's job: its existence is not revealed)."""
    if JOB_ID.match(job_id):
        with svc.sessions() as s:
            job = s.scalars(select(Job).where(Job.id == job_id, Job.team == who.team)).first()
        if job is not None:
            return job
    raise HTTPException(404, f"no job {shown_id(job_id)}")


def shown_id(value: str) -> str:
    """An id from a request as a 404 names it: itself if it has an id's shape, else its first characters (a path of
    any length is answered in one line)."""
    if JOB_ID.match(value):
        return value
    return f"{value[:40]!r}{'...' if len(value) > 40 else ''} (an id is 32 hex digits)"


ServiceDep = Annotated[Service, Depends(service)]


def caller_job(job_id: str, svc: ServiceDep, who: Caller) -> Job:
    """The caller's team's job named by the path's ``job_id``, or 404 (:func:`own_job`)."""
    return own_job(svc, who, job_id)


#: The caller's team's job of the path (``/jobs/{job_id}...``), or 404.
OwnJob = Annotated[Job, Depends(caller_job)]
