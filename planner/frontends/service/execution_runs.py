"""Executions in the service process: one process per execution (:func:`.execution_process.execution_main`),
a thread relaying its messages into the store, at most
one active execution per robot (checked here and kept by a partial unique index in the database), stops.

- Stop (``DELETE /v1/executions/{id}``): "stop" goes to the process, whose driver ends the run with a controlled
  stop (the arm at rest within a second); a process that has not ended :data:`STOP_GRACE` s later is killed (its
  connection drops, and the controller stops the arm).
- Service shutdown: running executions are stopped the same way and end "cancelled" with the reason.
- Restart: executions a stopped service left active are failed with the reason (:meth:`Executions.recover`); an
  execution is never started again by itself (a robot moves only when an operator asks).
"""

from __future__ import annotations

import contextlib
import json
import logging
import multiprocessing as mp
import os
import threading
import time
import uuid

from sqlalchemy import func, select, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import sessionmaker

from planner.frontends.service.config import RobotConfig, ServiceConfig
from planner.frontends.service.metrics import Metrics
from planner.frontends.service.store import ACTIVE_EXECUTION_STATES, EXECUTION_STATES, Execution, now

log = logging.getLogger("planner.frontends.service")

#: Seconds a stopped execution's process has to end before it is killed.
STOP_GRACE = 3.0
#: Seconds between progress writes to the store for one execution.
PROGRESS_WRITE_EVERY = 0.25


class RobotBusy(Exception):
    """The robot has an active execution."""


class Executions:
    """The service's executions: :meth:`create` (and run), :meth:`stop`, :meth:`recover`, :meth:`shutdown`."""

    def __init__(self, sessions: sessionmaker, cfg: ServiceConfig, write_lock: threading.Lock,
                 metrics: Metrics | None = None):
        self.sessions = sessions
        self.cfg = cfg
        self.write_lock = write_lock
        self.metrics = metrics or Metrics()
        self._lock = threading.Lock()
        self.runners: dict[str, Runner] = {}
        self.stopping = threading.Event()

    # -- start-up and shutdown ------------------------------------------------------------------
    def recover(self) -> int:
        """Executions left active by a stopped service: failed with the reason. Their number."""
        with self.write_lock, self.sessions() as s:
            n = s.execute(update(Execution).where(Execution.state.in_(ACTIVE_EXECUTION_STATES)).values(
                state="failed", finished_at=now(), error_kind="interrupted",
                error="the service stopped during this execution (the controller stops the arm when its connection "
                      "drops); it is not started again")).rowcount
            s.commit()
        for _ in range(n):
            self.metrics.count_execution("failed", None, "interrupted")
        return int(n)

    def shutdown(self, timeout: float = STOP_GRACE + 5.0) -> None:
        """Stop every running execution (the arm stopped), waiting for their processes to end."""
        self.stopping.set()
        with self._lock:
            runners = list(self.runners.values())
        for r in runners:
            r.request_stop("the service is shutting down")
        for r in runners:
            r.join(timeout)

    # -- figures ----------------------------------------------------------------------------------
    def counts(self) -> dict[str, int]:
        """Stored executions by state (every state, zeros included)."""
        with self.sessions() as s:
            rows = dict(s.execute(select(Execution.state, func.count()).group_by(Execution.state)).tuples().all())
        return {state: int(rows.get(state, 0)) for state in EXECUTION_STATES}

    def running(self) -> dict[str, int]:
        """Active executions of each configured robot (0 or 1; a robot no longer configured is listed while one of
        its executions is active)."""
        with self.sessions() as s:
            rows = dict(s.execute(select(Execution.robot, func.count()).where(
                Execution.state.in_(ACTIVE_EXECUTION_STATES)).group_by(Execution.robot)).tuples().all())
        return {**{r.name: 0 for r in self.cfg.robots}, **{k: int(v) for k, v in rows.items()}}

    # -- requests ---------------------------------------------------------------------------------
    def busy(self, robot: str) -> bool:
        with self.sessions() as s:
            q = select(Execution.id).where(Execution.robot == robot, Execution.state.in_(ACTIVE_EXECUTION_STATES))
            return s.scalar(q.limit(1)) is not None

    def create(self, owner: str, job_id: str, job_path: str, robot: RobotConfig, mode: str) -> str:
        """Store a new execution of the saved job at ``job_path`` on ``robot`` and start it; its id.
        RobotBusy if the robot has an active execution."""
        if self.stopping.is_set():
            raise RobotBusy("the service is shutting down")
        execution_id = uuid.uuid4().hex
        row = Execution(id=execution_id, job_id=job_id, owner=owner, robot=robot.name, mode=mode, state="starting",
                        created_at=now(), stage="starting", done=0, total=0)
        with self._lock:
            if self.busy(robot.name):
                raise RobotBusy(robot.name)
            try:
                with self.write_lock, self.sessions() as s:
                    s.add(row)
                    s.commit()
            except IntegrityError:  # another service process on the same database took the robot meanwhile
                raise RobotBusy(robot.name) from None
            task = {"job_path": job_path, "mode": mode, "robot": {
                "name": robot.name, "host": robot.host, "model": robot.model, "io": robot.io,
                "modbus_port": robot.modbus_port, "sim_speed": robot.sim_speed, "approach_speed": robot.approach_speed,
                "approach_acceleration": robot.approach_acceleration, "driver": robot.driver_options()}}
            runner = Runner(self, execution_id, task, row.created_at)
            self.runners[execution_id] = runner
        runner.start()
        return execution_id

    def stop(self, execution_id: str) -> bool:
        """Ask a running execution to stop; False if it is not running in this service."""
        with self._lock:
            runner = self.runners.get(execution_id)
        if runner is None:
            return False
        runner.request_stop()
        return True

    def wait(self, execution_id: str, timeout: float) -> None:
        """Wait until the execution's thread has stored its end (or ``timeout`` s)."""
        with self._lock:
            runner = self.runners.get(execution_id)
        if runner is not None:
            runner.join(timeout)

    # -- store transitions ----------------------------------------------------------------------------
    def _update(self, execution_id: str, states: tuple[str, ...], **values) -> bool:
        with self.write_lock, self.sessions() as s:
            n = s.execute(update(Execution).where(Execution.id == execution_id, Execution.state.in_(states))
                          .values(**values)).rowcount
            s.commit()
        return n == 1

    def _done(self, execution_id: str) -> None:
        with self._lock:
            self.runners.pop(execution_id, None)


class Runner(threading.Thread):
    """One execution's process and the thread that relays its messages."""

    def __init__(self, owner: Executions, execution_id: str, task: dict, created_at: float):
        super().__init__(name=f"execution-{execution_id[:8]}", daemon=True)
        self.owner = owner
        self.id = execution_id
        self.task = task
        self.created_at = created_at
        self._stop_reason: str | None = None
        self._stop_asked = threading.Event()

    def request_stop(self, reason: str = "stopped by the operator") -> None:
        if self._stop_reason is None:
            self._stop_reason = reason
        self._stop_asked.set()

    def run(self) -> None:
        try:
            self._run()
        except Exception:  # never leave the robot marked busy: fail the execution with the reason
            log.exception("execution %s failed in the service", self.id)
            self._finish("failed", {"kind": "internal", "reason": "internal error in the service (see its log)"})
        finally:
            self.owner._done(self.id)

    def _run(self) -> None:
        from planner.frontends.service.execution_process import execution_main

        ctx = mp.get_context("spawn")
        control_r, control_w = ctx.Pipe(duplex=False)
        results_r, results_w = ctx.Pipe(duplex=False)
        proc = ctx.Process(target=execution_main, args=(control_r, results_w, os.getpid(), self.task),
                           name=f"planner-execution-{self.id[:8]}", daemon=True)
        proc.start()
        control_r.close()
        results_w.close()
        stop_sent: float | None = None
        last_write = 0.0
        result: tuple = ("failed", {"kind": "internal", "reason": "no result"})
        try:
            while True:
                if self._stop_asked.is_set() and stop_sent is None:
                    stop_sent = time.monotonic()
                    with contextlib.suppress(OSError):
                        control_w.send("stop")
                    self.owner._update(self.id, ("starting", "running"), state="stopping")
                if stop_sent is not None and time.monotonic() - stop_sent > STOP_GRACE:
                    proc.kill()
                    result = ("failed", {"kind": "cancelled", "reason": f"{self._stop_reason}; the execution's "
                                         f"process did not end within {STOP_GRACE:g} s and was killed"})
                    break
                try:
                    msg = results_r.recv() if results_r.poll(0.05) else None
                except (EOFError, OSError):
                    proc.join(2.0)
                    result = ("failed", {"kind": "internal", "reason": "the execution's process ended without a "
                                         f"result (exit code {proc.exitcode})"})
                    break
                if msg is None:
                    continue
                if msg[0] == "stage":
                    values: dict = {"stage": msg[1]}
                    if msg[1] == "run":
                        values.update(state="running", started_at=now())
                        states: tuple[str, ...] = ("starting",)
                        if not self.owner._update(self.id, states, **values):
                            self.owner._update(self.id, ("stopping",), stage="run", started_at=values["started_at"])
                    else:
                        self.owner._update(self.id, ACTIVE_EXECUTION_STATES, **values)
                elif msg[0] == "progress":
                    t = time.monotonic()
                    if t - last_write >= PROGRESS_WRITE_EVERY or msg[2] >= msg[3]:
                        last_write = t
                        self.owner._update(self.id, ACTIVE_EXECUTION_STATES, stage=msg[1], done=msg[2], total=msg[3])
                elif msg[0] in ("report", "failed"):
                    result = msg
                    break
        finally:
            control_w.close()
            results_r.close()
            proc.join(5.0)
            if proc.is_alive():
                proc.kill()
                proc.join(5.0)
        if result[0] == "report":
            figures: dict = result[1]
            failure: dict | None = figures.get("failure")
            state = "done" if figures["ok"] else ("cancelled" if failure and failure["kind"] == "cancelled"
                                                  else "failed")
            self._finish(state, failure, report=figures)
        else:  # refused or failed before the run: after a stop (e.g. the approach move halted) it was cancelled
            error: dict = result[1]
            stopped = error["kind"] == "cancelled" or self._stop_reason is not None
            self._finish("cancelled" if stopped else "failed", error)

    def _finish(self, state: str, error: dict | None, report: dict | None = None) -> None:
        values: dict = {"state": state, "finished_at": now()}
        if report is not None:
            values["report"] = json.dumps(report)
        if error is not None:
            values.update(error_kind=str(error["kind"])[:32], error=error["reason"], error_t=error.get("t"),
                          error_pose=None if error.get("pose") is None else json.dumps(error["pose"]),
                          error_line=error.get("line"))
        if state == "cancelled" and self._stop_reason:
            values["note"] = self._stop_reason
        if self.owner._update(self.id, ACTIVE_EXECUTION_STATES, **values):
            self.owner.metrics.count_execution(state, values["finished_at"] - self.created_at,
                                               None if error is None else str(error["kind"]))
