"""The pool of planning worker processes, driven from the service process.

Each :class:`Slot` is a thread of the service owning one worker process (``multiprocessing`` spawn context,
:func:`planner.frontends.service.worker_process.worker_main`): when idle it claims the oldest queued job from the store,
sends it to its process and relays progress and the result into the store. CPU-bound planning therefore never
runs in the event loop (nor in the service process at all).

- Cancel: the slot kills its process (within ~0.1 s of the request) and starts a fresh one.
- Time limit: a job running longer than ``job_timeout_s`` is killed and failed with the reason.
- A worker that dies (killed for memory, crashed) fails its job with the exit code.
- Completion is conditional on (state running, same attempt): a job cancelled meanwhile, or started again after
  a restart, is never completed twice; the saved file of an attempt that lost is removed.
- Restart: :func:`recover` re-queues jobs that were running (each start counted in ``attempts``) and fails those
  that already had ``max_attempts`` starts, with the reason.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import multiprocessing as mp
import os
import shutil
import threading
import time
from pathlib import Path
from typing import Any

from sqlalchemy import Table, bindparam, func, select, update
from sqlalchemy.engine import Engine
from sqlalchemy.orm import sessionmaker

from planner.frontends.service.config import ServiceConfig
from planner.frontends.service.metrics import Metrics
from planner.frontends.service.store import STATES, Job, now

log = logging.getLogger("planner.frontends.service")
#: The jobs table itself (inserts without the ORM's per-row bookkeeping).
JOBS: Table = Job.__table__  # type: ignore[assignment]

#: Claim the oldest queued job: running, one more attempt; its id, attempt and input (no row if none is queued; the
#: state test in the outer WHERE keeps two claimers from both taking one job).
_CLAIM = (update(Job).where(Job.id == select(Job.id).where(Job.state == "queued").order_by(Job.seq).limit(1)
                            .scalar_subquery(), Job.state == "queued")
          .values(state="running", started_at=bindparam("now"), attempts=Job.attempts + 1, stage="starting", done=0,
                  total=0)
          .returning(Job.id, Job.attempts, Job.input_kind, Job.input_json, Job.input_name, Job.settings,
                     Job.read_options))

#: Seconds between progress writes to the store for one job.
PROGRESS_WRITE_EVERY = 0.5
#: Seconds a new worker process may take to import the planner before it is given up.
WORKER_START_TIMEOUT = 120.0


def job_dir(cfg: ServiceConfig, job_id: str) -> Path:
    """The folder of a job's files (its id is ours: 32 hex digits)."""
    if len(job_id) != 32 or any(c not in "0123456789abcdef" for c in job_id):
        raise ValueError(f"not a job id: {job_id!r}")
    return cfg.data_dir / "jobs" / job_id


def recover(sessions: sessionmaker, cfg: ServiceConfig) -> dict[str, int]:
    """At start-up: jobs left running by a stopped service run again (or fail after ``max_attempts`` starts)."""
    with sessions() as s:
        again = s.execute(update(Job).where(Job.state == "running", Job.attempts < cfg.max_attempts).values(
            state="queued", stage="", done=0, total=0,
            note="interrupted by a restart of the service while running; queued again")).rowcount
        failed = s.execute(update(Job).where(Job.state == "running").values(
            state="failed", finished_at=now(), error_kind="interrupted",
            error=f"interrupted by restarts of the service {cfg.max_attempts} times while running; not started again"
        )).rowcount
        s.commit()
    return {"requeued": again, "failed": failed}


class Slot(threading.Thread):
    """One worker process and the thread that feeds it."""

    def __init__(self, pool: WorkerPool, index: int):
        super().__init__(name=f"planner-worker-{index}", daemon=True)
        self.pool = pool
        self.index = index
        self.process: mp.process.BaseProcess | None = None
        self.conn: Any = None
        self.current: tuple[str, int] | None = None
        self.ready = False

    # -- process ------------------------------------------------------------------------------
    def start_process(self) -> None:
        from planner.frontends.service.worker_process import worker_main

        ctx = mp.get_context("spawn")
        parent, child = ctx.Pipe()
        proc = ctx.Process(target=worker_main, args=(child, os.getpid()), name=f"planner-worker-{self.index}",
                           daemon=True)
        proc.start()
        child.close()
        self.process, self.conn = proc, parent
        self.ready = False
        try:  # its imports done: a job's time limit counts from its start, not from the worker's
            if parent.poll(WORKER_START_TIMEOUT) and parent.recv() == ("ready",):
                self.ready = True
        except (EOFError, OSError):
            pass
        if not self.ready:
            log.error("planning worker %d did not start within %g s", self.index, WORKER_START_TIMEOUT)

    def stop_process(self, kill: bool = False) -> None:
        proc, conn = self.process, self.conn
        self.process = self.conn = None
        if proc is None:
            return
        if not kill and conn is not None:
            with contextlib.suppress(OSError):
                conn.send(None)
            proc.join(2.0)
        if proc.is_alive():
            proc.kill()
            proc.join(5.0)
        if conn is not None:
            conn.close()

    @property
    def alive(self) -> bool:
        """The worker process is running and ready for jobs."""
        return self.ready and self.process is not None and self.process.is_alive()

    # -- loop ---------------------------------------------------------------------------------
    def run(self) -> None:
        self.start_process()
        while not self.pool.stopping.is_set():
            job = self.pool.claim()
            if job is None:
                continue
            try:
                self.execute(job)
            except Exception:  # never lose the slot: fail the job with the reason
                log.exception("worker slot %d failed on job %s", self.index, job["id"])
                self.pool.finish(job["id"], job["attempts"], "failed", error_kind="internal",
                                 error="internal error in the worker pool (see the service log)")
                self.stop_process(kill=True)
                self.start_process()
            finally:
                self.current = None
        self.stop_process()

    def execute(self, job: dict) -> None:
        job_id, attempt = job["id"], job["attempts"]
        self.current = (job_id, attempt)
        try:
            self._execute(job, job_id, attempt)
        finally:
            self.pool.cancelled.discard(job_id)

    def _execute(self, job: dict, job_id: str, attempt: int) -> None:
        pool = self.pool
        if not self.alive:
            self.stop_process(kill=True)
            self.start_process()
        assert self.conn is not None and self.process is not None
        out = job_dir(pool.cfg, job_id) / f"plan.{attempt}.job"
        task = {"id": job_id, "kind": job["input_kind"], "input_json": job["input_json"],
                "input_path": str(job_dir(pool.cfg, job_id) / "input" / job["input_name"]),
                "settings": json.loads(job["settings"]), "read_options": json.loads(job["read_options"]),
                "out_path": str(out), "parent_pid": os.getpid()}
        self.conn.send(task)
        deadline = time.monotonic() + pool.cfg.job_timeout_s
        last_write = time.monotonic()  # a job of less than PROGRESS_WRITE_EVERY writes no progress
        while True:
            if job_id in pool.cancelled or pool.stopping.is_set():
                self.stop_process(kill=True)
                with contextlib.suppress(OSError):
                    out.unlink()
                if pool.stopping.is_set():
                    pool.requeue(job_id, attempt)
                    return
                self.start_process()
                return  # the request already marked the job cancelled
            if time.monotonic() > deadline:
                self.stop_process(kill=True)
                self.start_process()
                pool.finish(job_id, attempt, "failed", error_kind="limit",
                            error=f"planning took longer than the service's limit of {pool.cfg.job_timeout_s:g} s")
                return
            try:
                ready = self.conn.poll(0.1)
                msg = self.conn.recv() if ready else None
            except (EOFError, OSError):
                ready, msg = True, None
            if not ready:
                continue
            if msg is None:  # the process died
                assert self.process is not None
                self.process.join(1.0)
                code = self.process.exitcode
                self.stop_process(kill=True)
                self.start_process()
                pool.finish(job_id, attempt, "failed", error_kind="internal",
                            error=f"the worker process planning this job died (exit code {code}); the job may need "
                                  "more memory than the worker has")
                return
            if msg[0] == "progress":
                t = time.monotonic()
                if t - last_write >= PROGRESS_WRITE_EVERY:
                    last_write = t
                    pool.progress(job_id, attempt, msg[1], msg[2], msg[3])
            elif msg[0] == "done":
                r = msg[1]
                pool.finish(job_id, attempt, "done", stage="done", job_file=out.name, job_bytes=r["job_bytes"],
                            summary=json.dumps(r["summary"]), describe=json.dumps(r["describe"]),
                            planning_s=r["planning_s"])
                return
            elif msg[0] == "failed":
                with contextlib.suppress(OSError):
                    out.unlink()
                pool.finish(job_id, attempt, "failed", error_kind=msg[1], error=msg[2])
                return


class WorkerPool:
    """``n`` slots over one store; :meth:`wake` after a submit, :meth:`cancel` for DELETE."""

    def __init__(self, sessions: sessionmaker, cfg: ServiceConfig, metrics: Metrics):
        self.sessions = sessions
        self.engine: Engine = sessions.kw["bind"]  # the transitions below: Core, one short transaction each
        self.cfg = cfg
        self.metrics = metrics
        self.stopping = threading.Event()
        self._cond = threading.Condition()
        #: One writer at a time in this process: SQLite serializes writers anyway, and its busy handler sleeps
        #: (up to 100 ms a time) when they collide; a lock hands the write over at once.
        self.write_lock = threading.Lock()
        self.cancelled: set[str] = set()
        self.slots = [Slot(self, i) for i in range(cfg.workers)]

    def start(self) -> None:
        for slot in self.slots:
            slot.start()

    def stop(self) -> None:
        self.stopping.set()
        self.wake(all_slots=True)
        for slot in self.slots:
            slot.join(10.0)

    def wake(self, all_slots: bool = False) -> None:
        with self._cond:
            if all_slots:
                self._cond.notify_all()
            else:
                self._cond.notify()

    @property
    def alive(self) -> int:
        return sum(slot.alive for slot in self.slots)

    @property
    def busy(self) -> int:
        return sum(slot.current is not None for slot in self.slots)

    # -- store transitions ----------------------------------------------------------------------
    def claim(self) -> dict | None:
        """The oldest queued job, now running with one more attempt; None after a short wait if none. One statement
        (UPDATE ... RETURNING on SQLite 3.35+ and PostgreSQL) through SQLAlchemy Core: a slot thread holds the GIL
        briefly, so the event loop it shares the process with is not kept waiting."""
        with self.write_lock, self.engine.begin() as conn:
            row = conn.execute(_CLAIM, {"now": now()}).mappings().first()
        if row is not None:
            return dict(row)
        with self._cond:
            self._cond.wait(0.5)
        return None

    def progress(self, job_id: str, attempt: int, stage: str, done: int, total: int) -> None:
        with self.write_lock, self.engine.begin() as conn:
            conn.execute(update(Job).where(Job.id == job_id, Job.state == "running", Job.attempts == attempt).values(
                stage=stage, done=done, total=total))

    def finish(self, job_id: str, attempt: int, state: str, **values) -> bool:
        """Move a running job of this attempt to ``state``; False (and its file removed) if it is no longer so."""
        with self.write_lock, self.engine.begin() as conn:
            n = conn.execute(update(Job).where(Job.id == job_id, Job.state == "running", Job.attempts == attempt)
                             .values(state=state, finished_at=now(), **values)).rowcount
        if n != 1 and values.get("job_file"):
            with contextlib.suppress(OSError):
                (job_dir(self.cfg, job_id) / values["job_file"]).unlink()
        if n == 1:
            self.metrics.count_finished(state, values.get("planning_s"))
        return n == 1

    def requeue(self, job_id: str, attempt: int) -> None:
        """A job whose service is stopping: queued again, its start not counted."""
        with self.write_lock, self.sessions() as s:
            s.execute(update(Job).where(Job.id == job_id, Job.state == "running", Job.attempts == attempt).values(
                state="queued", attempts=attempt - 1, stage="", done=0, total=0))
            s.commit()

    def cancel(self, job_id: str) -> str | None:
        """Cancel a queued or running job: its state before ("queued"/"running"), or None if it had ended."""
        with self.write_lock, self.sessions() as s:
            before = s.scalar(select(Job.state).where(Job.id == job_id))
            if before not in ("queued", "running"):
                return None
            n = s.execute(update(Job).where(Job.id == job_id, Job.state == before).values(
                state="cancelled", finished_at=now())).rowcount
            s.commit()
        if n != 1:
            return self.cancel(job_id)  # it moved meanwhile: look again
        self.metrics.count_finished("cancelled")
        if before == "running":
            self.cancelled.add(job_id)  # its slot kills the worker within its next poll (0.1 s)
        return before

    def counts(self) -> dict[str, int]:
        with self.sessions() as s:
            rows = dict(s.execute(select(Job.state, func.count()).group_by(Job.state)).tuples().all())
        return {state: int(rows.get(state, 0)) for state in STATES}


class Inserter:
    """New jobs stored by the event loop itself, every row that arrives in one turn of the loop committed in one
    transaction (group commit): a burst of submissions costs one commit, not one each.

    Why in the loop and not in a thread of its own: Python's sqlite3 releases the GIL around every statement step
    (one per row of an executemany), and a thread taking it back waits for the busy event loop to give it up (up to
    the interpreter's switch interval each time), so a commit of 20 rows took 7-15 ms in a thread against well under
    a millisecond here; the requests waiting for it waited that long. The loop is blocked for the commit itself only
    (SQLite in WAL mode with synchronous=NORMAL: no fsync in a commit)."""

    def __init__(self, pool: WorkerPool):
        self.pool = pool
        self._pending: list[tuple[dict, asyncio.Future]] = []

    async def store(self, row: dict) -> None:
        """Store a job row (the columns of :class:`Job`); returns once it is committed (raises what the commit
        raised, e.g. the database is gone)."""
        loop = asyncio.get_running_loop()
        done = loop.create_future()
        self._pending.append((row, done))
        if len(self._pending) == 1:  # the first of this turn: the commit runs after the turn's other requests
            loop.call_soon(self._commit)
        await asyncio.shield(done)  # a request cancelled meanwhile (its client went away) is committed all the same

    def _commit(self) -> None:
        batch, self._pending = self._pending, []
        try:
            with self.pool.write_lock, self.pool.engine.begin() as conn:
                conn.execute(JOBS.insert(), [row for row, _ in batch])  # one executemany, Core
        except Exception as exc:  # every waiting request gets the error
            for _, done in batch:
                done.set_exception(exc)
                done.exception()  # (retrieved: no 'never retrieved' warning for a request that went away)
            return
        for _, done in batch:
            done.set_result(None)
        self.pool.wake(all_slots=len(batch) > 1)


def remove_job_files(cfg: ServiceConfig, job_id: str) -> None:
    shutil.rmtree(job_dir(cfg, job_id), ignore_errors=True)
