"""Every change of a task's row, each one short transaction through SQLAlchemy Core, the same for both backends.

- A job is claimed (queued -> running, one more attempt, its holder and heartbeat), shows progress, and ends: the
  end is conditional on (state active, same attempt), so a job that ran twice (its worker thought dead, a message
  delivered again) stores one result and counts once; its plan is written in the same transaction.
- Cancellation has one path: the request marks the row (a job "cancelled", an execution "stopping" with the
  reason in its note); the runner holding it reads the mark within :data:`CANCEL_POLL` s and stops the work.
- Recovery has one rule: a task whose holder stopped beating (:func:`recover`; at the start of the local backend
  every active task, since no other process runs them) is queued again (a job, until ``max_attempts`` starts) or
  failed "interrupted" (an execution: a robot moves only when an operator asks).
- An execution holds its robot's lease: its active row (one per robot, a partial unique index) whose holder beats
  at least every :data:`HEARTBEAT_EVERY` s; the lease expires :data:`LEASE_S` s after the last beat and a new
  execution then takes the robot over (the stale one failed "interrupted").
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import threading
import time
from typing import Any

from sqlalchemy import Table, bindparam, delete, func, insert, select, update
from sqlalchemy.engine import Engine
from sqlalchemy.exc import IntegrityError

from planner.frontends.service.store import Execution, Job, JobChunk, JobData, Worker
from planner.frontends.service.tasks.functions import ExecuteSpec, PlanSpec
from planner.frontends.service.tasks.lifecycle import EXECUTION, FINAL_STATES, JOB, Kind, Outcome, Progress

#: Seconds between a running task's heartbeats.
HEARTBEAT_EVERY = 2.0
#: Seconds after its last heartbeat that a task's holder is taken for dead (its job queued again, its execution
#: failed and its robot's lease free).
LEASE_S = 15.0
#: Seconds between a runner's looks at its task's row for a cancellation.
CANCEL_POLL = 0.2
#: Seconds between progress writes of one task.
PROGRESS_WRITE_EVERY = 0.5

JOBS: Table = Job.__table__  # type: ignore[assignment]
EXECUTIONS: Table = Execution.__table__  # type: ignore[assignment]
DATA: Table = JobData.__table__  # type: ignore[assignment]


class RobotBusy(Exception):
    """The robot has an active execution whose lease has not expired."""


def holder_id() -> str:
    """This process as a holder of tasks: ``host:pid``."""
    return f"{socket.gethostname()[:48]}:{os.getpid()}"


def now() -> float:
    return time.time()


def _put_data(conn, task_id: str, name: str, data: bytes, *, replace: bool) -> None:
    """Store ``data`` as the task's ``name`` in the transaction ``conn`` (``replace``: over what is there)."""
    if replace:
        conn.execute(delete(JobData).where(JobData.job_id == task_id, JobData.name == name))
    conn.execute(insert(JobData).values(job_id=task_id, name=name, data=data, bytes=len(data), created_at=now()))


def _stale_job(stale_before: float):
    """A running job whose holder has not beaten since ``stale_before``."""
    return (Job.state == "running") & ((Job.heartbeat_at < stale_before) | Job.heartbeat_at.is_(None))


def _stale_execution(stale_before: float):
    """An active execution whose holder has not beaten since ``stale_before``."""
    return Execution.state.in_(EXECUTION.active) & (
        (Execution.heartbeat_at < stale_before) | Execution.heartbeat_at.is_(None))


def _drop_chunks(conn, job_id: str) -> None:
    """Remove a split job's pieces and their planned moves in the transaction ``conn``."""
    conn.execute(delete(JobChunk).where(JobChunk.job_id == job_id))
    conn.execute(delete(JobData).where(JobData.job_id == job_id, JobData.name.like("piece.%")))


def _table(kind: Kind) -> Any:
    return Job if kind is JOB else Execution


#: Claim a job: the oldest queued one (or the one named), now running with one more attempt.
_CLAIM_COLUMNS = (Job.id, Job.attempts, Job.input_kind, Job.input_json, Job.input_name, Job.settings,
                  Job.read_options)


class Transitions:
    """The store's task transitions for one process (``holder``: :func:`holder_id`).

    SQLite serializes writers, and its busy handler sleeps (up to 100 ms a time) when they collide: on SQLite every
    write of this process takes :attr:`write_lock` first (handed over at once); other databases need no lock."""

    def __init__(self, engine: Engine, holder: str | None = None):
        self.engine = engine
        self.holder = holder or holder_id()
        self.sqlite = engine.dialect.name == "sqlite"
        self.write_lock: Any = threading.Lock() if self.sqlite else contextlib.nullcontext()
        self._claim_oldest = (
            update(Job).where(Job.id == select(Job.id).where(Job.state == "queued").order_by(Job.seq).limit(1)
                              .scalar_subquery(), Job.state == "queued")
            .values(state="running", started_at=bindparam("now"), heartbeat_at=bindparam("now"),
                    holder=self.holder, attempts=Job.attempts + 1, stage="starting", done=0, total=0)
            .returning(*_CLAIM_COLUMNS))
        self._claim_one = (
            update(Job).where(Job.id == bindparam("job_id"), Job.state == "queued")
            .values(state="running", started_at=bindparam("now"), heartbeat_at=bindparam("now"),
                    holder=self.holder, attempts=Job.attempts + 1, stage="starting", done=0, total=0)
            .returning(*_CLAIM_COLUMNS))

    # -- jobs -------------------------------------------------------------------------------------------------------
    def claim_job(self, job_id: str | None = None) -> tuple[str, int, PlanSpec] | None:
        """The oldest queued job (or ``job_id`` if it is queued), now running, held by this process, one more attempt:
        its id, attempt and specification; None if there is none (or ``job_id`` is not queued: another worker has
        it, it was cancelled or it has ended)."""
        with self.write_lock, self.engine.begin() as conn:
            if job_id is None:
                row = conn.execute(self._claim_oldest, {"now": now()}).mappings().first()
            else:
                row = conn.execute(self._claim_one, {"now": now(), "job_id": job_id}).mappings().first()
        if row is None:
            return None
        return row["id"], int(row["attempts"]), self._spec(row)

    def _spec(self, row) -> PlanSpec:
        """A job's specification from its row (the columns :data:`_CLAIM_COLUMNS`), its input file read."""
        data = None
        if row["input_kind"] == "file":
            with self.engine.connect() as conn:
                data = conn.scalar(select(JobData.data).where(JobData.job_id == row["id"], JobData.name == "input"))
        return PlanSpec(row["id"], row["input_kind"], row["input_name"], json.loads(row["settings"]),
                        json.loads(row["read_options"]), row["input_json"], data)

    def requeue(self, job_id: str, attempt: int) -> None:
        """A job whose worker is stopping (not failing): queued again, its start not counted."""
        with self.write_lock, self.engine.begin() as conn:
            conn.execute(update(Job).where(Job.id == job_id, Job.state == "running", Job.attempts == attempt).values(
                state="queued", attempts=attempt - 1, stage="", done=0, total=0, holder=None, heartbeat_at=None))

    def cancel_job(self, job_id: str) -> str | None:
        """Cancel a queued or running job: its state before ("queued"/"running"), or None if it had ended. Its runner
        (in any process) stops the work within :data:`CANCEL_POLL` s."""
        for _ in range(10):
            with self.write_lock, self.engine.begin() as conn:
                before = conn.scalar(select(Job.state).where(Job.id == job_id))
                if before not in JOB.active:
                    return None
                n = conn.execute(update(Job).where(Job.id == job_id, Job.state == before).values(
                    state="cancelled", finished_at=now())).rowcount
                if n == 1:  # a split job's pieces and fits: gone with it (their runners stop at their next look)
                    _drop_chunks(conn, job_id)
            if n == 1:
                return before
        return None

    # -- the pieces of a split job (:mod:`.split`) -----------------------------------------------------------------
    def pieces(self, job_id: str, wanted: list[tuple[int, int, int]]) -> list[dict]:
        """The job's pieces: those stored by an earlier attempt if any (their planned moves kept), else ``wanted``
        ((first, stop, chords) each) stored, queued."""
        with self.write_lock, self.engine.begin() as conn:
            if conn.scalar(select(func.count()).select_from(JobChunk).where(JobChunk.job_id == job_id)) == 0:
                conn.execute(insert(JobChunk), [{"job_id": job_id, "first": a, "stop": b, "chords": c,
                                                 "state": "queued", "takes": 0} for a, b, c in wanted])
        return self.chunks(job_id)

    def chunks(self, job_id: str) -> list[dict]:
        """The job's pieces in pass order: first, stop, chords, state, takes, holder, heartbeat_at, seconds,
        error_kind, error."""
        with self.engine.connect() as conn:
            return [dict(r) for r in conn.execute(select(JobChunk).where(JobChunk.job_id == job_id)
                                                  .order_by(JobChunk.first)).mappings()]

    def claim_chunk(self, job_id: str, first: int, stale_before: float | None = None
                    ) -> tuple[int, PlanSpec] | None:
        """Take a queued piece of an active job (or, given ``stale_before`` (Unix s), a running one whose holder's
        last heartbeat is older: its holder is taken for dead): its take number and the specification of its planning;
        None if another worker has it, it has ended or the job has."""
        taken = JobChunk.state == "queued"
        if stale_before is not None:
            taken = taken | ((JobChunk.state == "running") & (JobChunk.heartbeat_at < stale_before))
        active = select(Job.id).where(Job.id == job_id, Job.state.in_(JOB.active)).exists()
        with self.write_lock, self.engine.begin() as conn:
            row = conn.execute(update(JobChunk).where(JobChunk.job_id == job_id, JobChunk.first == first, taken,
                                                      active)
                               .values(state="running", takes=JobChunk.takes + 1, holder=self.holder,
                                       heartbeat_at=now())
                               .returning(JobChunk.takes, JobChunk.stop)).first()
            if row is None:
                return None
            job = conn.execute(select(*_CLAIM_COLUMNS).where(Job.id == job_id)).mappings().first()
        if job is None:
            return None
        from dataclasses import replace

        return int(row[0]), replace(self._spec(job), step="piece", piece=(first, int(row[1])))

    def chunk_beat(self, job_id: str, first: int, takes: int) -> None:
        with self.write_lock, self.engine.begin() as conn:
            conn.execute(update(JobChunk).where(JobChunk.job_id == job_id, JobChunk.first == first,
                                                JobChunk.takes == takes, JobChunk.state == "running")
                         .values(heartbeat_at=now()))

    def release_chunk(self, job_id: str, first: int, takes: int) -> None:
        """A piece whose worker is stopping: queued again (another worker, or the job's own, plans it)."""
        with self.write_lock, self.engine.begin() as conn:
            conn.execute(update(JobChunk).where(JobChunk.job_id == job_id, JobChunk.first == first,
                                                JobChunk.takes == takes, JobChunk.state == "running")
                         .values(state="queued", holder=None, heartbeat_at=None))

    def finish_chunk(self, job_id: str, first: int, takes: int, outcome: Outcome) -> bool:
        """End a piece of this take: done, its planned moves (``outcome.plan``) stored as ``piece.<first>`` in the same
        transaction; or failed with the outcome's error. False if it was no longer this take's (taken over)."""
        values: dict = {"state": "done" if outcome.state == "done" else "failed", "heartbeat_at": now(),
                        "seconds": outcome.values.get("seconds"), "error_kind": outcome.error_kind,
                        "error": outcome.error}
        name = f"piece.{first}"
        with self.write_lock, self.engine.begin() as conn:
            n = conn.execute(update(JobChunk).where(JobChunk.job_id == job_id, JobChunk.first == first,
                                                    JobChunk.takes == takes, JobChunk.state == "running")
                             .values(**values)).rowcount
            if n == 1 and outcome.state == "done" and outcome.plan is not None:
                _put_data(conn, job_id, name, outcome.plan, replace=True)
        return n == 1

    def chunk_pieces(self, job_id: str) -> list[bytes]:
        """The planned moves of the job's pieces (:func:`planner.job.piece_to_bytes`), in pass order."""
        with self.engine.connect() as conn:
            firsts = list(conn.scalars(select(JobChunk.first).where(JobChunk.job_id == job_id)
                                       .order_by(JobChunk.first)))
            data = dict(conn.execute(select(JobData.name, JobData.data).where(
                JobData.job_id == job_id, JobData.name.in_([f"piece.{k}" for k in firsts]))).all())
        missing = [k for k in firsts if f"piece.{k}" not in data]
        if missing:
            raise ValueError(f"job {job_id}: the planned moves of its pieces from pass {missing} are not in the store")
        return [bytes(data[f"piece.{k}"]) for k in firsts]

    def drop_chunks(self, job_id: str) -> None:
        """The job's pieces and their planned moves removed (the job has ended)."""
        with self.write_lock, self.engine.begin() as conn:
            _drop_chunks(conn, job_id)

    def job_ended(self, job_id: str) -> bool:
        """The job has ended (done, failed, cancelled) or is gone."""
        state = self.state(JOB, job_id)
        return state is None or state in FINAL_STATES

    # -- executions -------------------------------------------------------------------------------------------------
    def create_execution(self, values: dict) -> None:
        """Store a new execution (``values``: its columns; state "starting"), taking its robot's lease: RobotBusy if
        another execution holds the robot and its lease has not expired (an expired one is failed "interrupted" and
        the robot taken over)."""
        robot = values["robot"]
        for _ in range(3):
            try:
                with self.write_lock, self.engine.begin() as conn:
                    conn.execute(insert(Execution).values(heartbeat_at=values["created_at"], attempts=0, **values))
                return
            except IntegrityError:  # the robot is held: by a live holder, or by one whose lease expired
                if not self._expire_lease(robot):
                    raise RobotBusy(robot) from None
        raise RobotBusy(robot)

    def _expire_lease(self, robot: str) -> bool:
        stale = now() - LEASE_S
        with self.write_lock, self.engine.begin() as conn:
            n = conn.execute(update(Execution).where(
                Execution.robot == robot, Execution.state.in_(EXECUTION.active), Execution.heartbeat_at < stale)
                .values(state="failed", finished_at=now(), error_kind="interrupted",
                        error=f"its worker stopped answering (no heartbeat for {LEASE_S:g} s) while it held the robot; "
                              "the robot was taken over by a new execution; it is not started again")).rowcount
        return n > 0

    def claim_execution(self, execution_id: str, robots) -> tuple[str, int, ExecuteSpec] | None:
        """Take a starting execution no worker has taken yet (an execution is never started twice): its id, attempt
        (1) and specification with the job's plan; None if it is taken, stopped or ended. ``robots``: this process's
        configured robots (:class:`~planner.frontends.service.config.RobotConfig`): the robot is reached at the host
        configured here, by its name, never at an address from the store."""
        with self.write_lock, self.engine.begin() as conn:
            row = conn.execute(update(Execution).where(
                Execution.id == execution_id, Execution.state == "starting", Execution.attempts == 0)
                .values(attempts=1, holder=self.holder, heartbeat_at=now())
                .returning(Execution.job_id, Execution.mode, Execution.robot)).mappings().first()
        if row is None:
            return None
        robot = next((r for r in robots if r.name == row["robot"]), None)
        with self.engine.connect() as conn:
            plan = conn.scalar(select(JobData.data).where(JobData.job_id == row["job_id"], JobData.name == "plan"))
        reason = (f"no robot named {row['robot']!r} in the configuration of the worker {self.holder}" if robot is None
                  else f"the plan of job {row['job_id']} is not in the store" if plan is None else None)
        if reason is not None:
            self.finish(EXECUTION, execution_id, 1, Outcome("failed", error_kind="internal", error=reason))
            return None
        assert robot is not None and plan is not None
        fields = {"name": robot.name, "host": robot.host, "model": robot.model, "io": robot.io,
                  "modbus_port": robot.modbus_port, "sim_speed": robot.sim_speed,
                  "driver": robot.driver_options()}  # approach, servo, deviation and program size (RobotConfig)
        return execution_id, 1, ExecuteSpec(execution_id, plan, row["mode"], fields)

    def stop_execution(self, execution_id: str, reason: str = "stopped by the operator") -> bool:
        """Ask an active execution to stop (its runner, wherever it runs, sends the stop within :data:`CANCEL_POLL`
        s); False if it has ended. One that no worker has taken yet ends cancelled at once."""
        with self.write_lock, self.engine.begin() as conn:
            n = conn.execute(update(Execution).where(Execution.id == execution_id, Execution.state == "starting",
                                                     Execution.attempts == 0)
                             .values(state="cancelled", finished_at=now(), note=reason)).rowcount
            if n:
                return True
            n = conn.execute(update(Execution).where(Execution.id == execution_id,
                                                     Execution.state.in_(("starting", "running")))
                             .values(state="stopping", note=reason)).rowcount
        return n == 1

    # -- both -------------------------------------------------------------------------------------------------------
    def state(self, kind: Kind, task_id: str) -> str | None:
        """The task's state (None: no such task)."""
        table = _table(kind)
        with self.engine.connect() as conn:
            return conn.scalar(select(table.state).where(table.id == task_id))

    def heartbeat(self, kind: Kind, task_id: str, attempt: int) -> None:
        table = _table(kind)
        with self.write_lock, self.engine.begin() as conn:
            conn.execute(update(table).where(table.id == task_id, table.attempts == attempt,
                                             table.state.in_(kind.active)).values(heartbeat_at=now()))

    def progress(self, kind: Kind, task_id: str, attempt: int, p: Progress) -> None:
        """Store a task's progress (and, for an execution whose run begins, its state running and start time)."""
        table = _table(kind)
        values: dict = {"stage": p.stage, "done": p.done, "total": p.total, "heartbeat_at": now()}
        where = (table.id == task_id, table.attempts == attempt)
        with self.write_lock, self.engine.begin() as conn:
            if p.started and kind is EXECUTION:
                t = now()
                n = conn.execute(update(table).where(*where, table.state == "starting").values(
                    state="running", started_at=t, **values)).rowcount
                if n:
                    return
                values["started_at"] = t
            conn.execute(update(table).where(*where, table.state.in_(kind.active)).values(**values))

    def finish(self, kind: Kind, task_id: str, attempt: int, outcome: Outcome) -> bool:
        """End a task of this attempt with ``outcome`` (and store its plan and files in the same transaction); False if
        it was no longer active in this attempt (cancelled meanwhile, or taken again): nothing is stored then."""
        table = _table(kind)
        values: dict = {"state": outcome.state, "finished_at": now(), **outcome.values}
        if outcome.error is not None:
            values.update(error_kind=outcome.error_kind, error=outcome.error)
        if outcome.planning_s is not None:
            values["planning_s"] = outcome.planning_s
        if outcome.plan is not None:
            values.update(job_file=f"plan.{attempt}.job", job_bytes=len(outcome.plan))
        with self.write_lock, self.engine.begin() as conn:
            n = conn.execute(update(table).where(table.id == task_id, table.attempts == attempt,
                                                 table.state.in_(kind.active)).values(**values)).rowcount
            stored = {**outcome.files, **({} if outcome.plan is None else {"plan": outcome.plan})}
            # (keyed by the task's id: jobs' and executions' never meet; only a task run before may have stored some)
            for name, data in stored.items() if n == 1 else ():
                _put_data(conn, task_id, name, data, replace=attempt > 1)
        return n == 1

    def keep_data(self, task_id: str, name: str, data: bytes) -> None:
        """Store bytes made from a task after its end (a job's 3D view data) under its id, unless stored already
        (by another replica or worker: the same bytes)."""
        try:
            with self.write_lock, self.engine.begin() as conn:
                _put_data(conn, task_id, name, data, replace=False)
        except IntegrityError:
            pass

    def any_stale(self, stale_before: float) -> bool:
        """A running job or an active execution whose holder's last heartbeat is older than ``stale_before`` (Unix s):
        what :meth:`recover` would change, in one read (a keeper's round that finds nothing writes nothing)."""
        jobs = select(Job.id).where(_stale_job(stale_before)).exists()
        executions = select(Execution.id).where(_stale_execution(stale_before)).exists()
        with self.engine.connect() as conn:
            return bool(conn.scalar(select(jobs | executions)))

    def recover(self, stale_before: float, max_attempts: int, why: str, whys: str) -> dict[str, Any]:
        """Tasks whose holder's last heartbeat is older than ``stale_before`` (Unix s; ``inf``: every active task):
        running jobs queued again (failed "interrupted" after ``max_attempts`` starts), active executions failed
        "interrupted" (their robot's lease freed). ``why`` names the cause in the note and error ("a restart of the
        service"), ``whys`` it repeated ("restarts of the service"). The ids of the jobs queued again are in
        "requeued_ids"."""
        t = now()
        stale_job, stale_exec = _stale_job(stale_before), _stale_execution(stale_before)
        with self.write_lock, self.engine.begin() as conn:
            again = [r[0] for r in conn.execute(update(Job).where(stale_job, Job.attempts < max_attempts).values(
                state="queued", stage="", done=0, total=0, holder=None, heartbeat_at=None,
                note=f"interrupted by {why} while running; queued again").returning(Job.id))]
            failed = conn.execute(update(Job).where(stale_job).values(
                state="failed", finished_at=t, error_kind="interrupted",
                error=f"interrupted by {whys} {max_attempts} times while running; not started again")).rowcount
            executions = conn.execute(update(Execution).where(stale_exec, Execution.attempts == 0).values(
                state="failed", finished_at=t, error_kind="interrupted",
                error=f"no worker took this execution within {LEASE_S:g} s (no worker serving the execute queue, or "
                      "the service restarted); it is not started")).rowcount
            executions += conn.execute(update(Execution).where(stale_exec).values(
                state="failed", finished_at=t, error_kind="interrupted",
                error=f"interrupted by {why} during this execution (the controller stops the arm when its "
                      "connection drops); it is not started again")).rowcount
        return {"requeued": len(again), "failed": int(failed), "executions_failed": int(executions),
                "requeued_ids": again}

    def counts(self, kind: Kind) -> dict[str, int]:
        """Stored tasks of ``kind`` by state, every state (zeros included): the whole cluster's."""
        table = _table(kind)
        with self.engine.connect() as conn:
            rows: dict[str, int] = dict(conn.execute(select(table.state, func.count()).group_by(table.state))
                                        .all())
        return {state: int(rows.get(state, 0)) for state in kind.states}

    def robots_running(self, names: list[str]) -> dict[str, int]:
        """Active executions of each robot (0 or 1; a robot no longer configured is listed while it has one)."""
        with self.engine.connect() as conn:
            rows: dict[str, int] = dict(conn.execute(select(Execution.robot, func.count()).where(
                Execution.state.in_(EXECUTION.active)).group_by(Execution.robot)).all())
        return {**{n: 0 for n in names}, **{k: int(v) for k, v in rows.items()}}

    def robot_busy(self, robot: str) -> bool:
        with self.engine.connect() as conn:
            q = select(Execution.id).where(Execution.robot == robot, Execution.state.in_(EXECUTION.active))
            return conn.scalar(q.limit(1)) is not None

    # -- workers (celery backend) -----------------------------------------------------------------------------------
    def worker_beat(self, queues: str, concurrency: int, busy: int, started_at: float) -> None:
        """This worker process is alive (its row in ``workers``)."""
        t = now()
        with self.write_lock, self.engine.begin() as conn:
            n = conn.execute(update(Worker).where(Worker.id == self.holder).values(heartbeat_at=t, busy=busy)).rowcount
            if n == 0:
                conn.execute(insert(Worker).values(id=self.holder, queues=queues, concurrency=concurrency,
                                                   started_at=started_at, heartbeat_at=t, busy=busy))

    def worker_gone(self) -> None:
        with self.write_lock, self.engine.begin() as conn:
            conn.execute(delete(Worker).where(Worker.id == self.holder))

    def workers_alive(self, queue: str | None = None) -> tuple[int, int]:
        """Worker slots (processes) alive and busy, by the heartbeats of the last :data:`LEASE_S` s (of the workers
        serving ``queue``: all if None)."""
        q = select(func.coalesce(func.sum(Worker.concurrency), 0), func.coalesce(func.sum(Worker.busy), 0)).where(
            Worker.heartbeat_at > now() - LEASE_S)
        if queue is not None:
            q = q.where(Worker.queues.contains(queue))
        with self.engine.connect() as conn:
            row = conn.execute(q).first()
        return (0, 0) if row is None else (int(row[0]), int(row[1]))
