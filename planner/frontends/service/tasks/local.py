"""The local backend (the default, ``planner serve`` alone): the service's own worker processes, no broker.

``workers`` planning slots, each a thread of the service driving one worker process (:class:`.runner.Slot`): when
idle it claims the oldest queued job from the store and runs it. An execution gets a slot (and a process) of its
own when it is created: a robot moves when an operator asks, never behind a queue of planning jobs.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from sqlalchemy.exc import DBAPIError

from planner.frontends.service.config import ServiceConfig
from planner.frontends.service.live import HUB
from planner.frontends.service.tasks.lifecycle import EXECUTION, JOB, Kind, Outcome
from planner.frontends.service.tasks.runner import STOP_GRACE, Slot
from planner.frontends.service.tasks.transitions import Transitions

log = logging.getLogger("planner.frontends.service")

#: Seconds between a slot's looks at its task's row: every cancel and stop of this process pokes the slot holding
#: the task, so the look is a safety net (the celery backend's slots look every CANCEL_POLL s: a cancel comes from
#: another machine).
POKED_POLL = 2.0


class LocalBackend:
    """Planning slots and execution slots of this process over one store."""

    name = "local"

    def __init__(self, store: Transitions, cfg: ServiceConfig, on_finish: Callable[[Kind, Outcome, float], None]):
        self.store = store
        self.cfg = cfg
        self.on_finish = on_finish
        self.live = HUB  # executions' live samples: this process runs them
        self.stopping = threading.Event()
        self._cond = threading.Condition()
        self._lock = threading.Lock()
        self.slots = [Slot(store, cfg.job_timeout_s, self.stopping, on_finish=on_finish, cancel_poll=POKED_POLL,
                           nice=cfg.worker_nice) for _ in range(cfg.workers)]
        self._threads = [threading.Thread(target=self._serve, args=(s,), name=f"planner-worker-{i}", daemon=True)
                         for i, s in enumerate(self.slots)]
        self.executions: dict[str, tuple[Slot, threading.Thread]] = {}

    # -- life ---------------------------------------------------------------------------------------------------------
    def start(self) -> dict:
        """Recover what a stopped service left active (every active task: no other process runs this store's tasks),
        then start the planning slots. The recovery's figures."""
        recovered = self.store.recover(float("inf"), self.cfg.max_attempts, "a restart of the service",
                                       "restarts of the service")
        recovered.pop("requeued_ids")
        for t in self._threads:
            t.start()
        return recovered

    def stop(self) -> None:
        """Stop: running jobs go back to the queue (their start not counted), running executions are stopped (the arm
        at rest) and end cancelled with the reason."""
        self.stopping.set()
        self.wake(all_slots=True)
        with self._lock:
            running = list(self.executions.values())
        for _, thread in running:
            thread.join(STOP_GRACE + 5.0)
        for t in self._threads:
            t.join(10.0)

    def _serve(self, slot: Slot) -> None:
        slot.start_process()
        while not self.stopping.is_set():
            try:
                claimed = self.store.claim_job()
            except DBAPIError as exc:  # the database away (a restart of its server): wait and look again
                log.warning("cannot claim a job: %s", str(exc).splitlines()[0])
                self.stopping.wait(1.0)
                continue
            if claimed is None:
                slot.settle()  # (a fresh process started after a cancel or a failure: counted alive once ready)
                with self._cond:
                    self._cond.wait(0.5)
                continue
            slot.run(JOB, *claimed)
        slot.stop_process()

    def wake(self, all_slots: bool = False) -> None:
        with self._cond:
            if all_slots:
                self._cond.notify_all()
            else:
                self._cond.notify()

    # -- requests ------------------------------------------------------------------------------------------------------
    def submitted(self, job_ids: list[str]) -> None:
        """Jobs were stored (queued): a slot claims them."""
        self.wake(all_slots=len(job_ids) > 1)

    def cancel_job(self, job_id: str) -> str | None:
        """Cancel a queued or running job (its state before, or None if it had ended)."""
        before = self.store.cancel_job(job_id)
        if before == "running":
            for slot in self.slots:
                if slot.current is not None and slot.current[0] == job_id:
                    slot.poke.set()
        return before

    def start_execution(self, values: dict) -> None:
        """Store the execution (its robot's lease taken: RobotBusy if held) and run it in a process of its own."""
        if self.stopping.is_set():
            from planner.frontends.service.tasks.transitions import RobotBusy

            raise RobotBusy("the service is shutting down")
        self.store.create_execution(values)
        slot = Slot(self.store, self.cfg.job_timeout_s, self.stopping, name="planner-exec", on_finish=self.on_finish,
                    cancel_poll=POKED_POLL, nice=self.cfg.worker_nice)
        thread = threading.Thread(target=self._execute, args=(slot, values["id"]),
                                  name=f"execution-{values['id'][:8]}", daemon=True)
        with self._lock:
            self.executions[values["id"]] = (slot, thread)
        thread.start()

    def _execute(self, slot: Slot, execution_id: str) -> None:
        try:
            claimed = self.store.claim_execution(execution_id, self.cfg.robots)
            if claimed is not None:
                slot.run(EXECUTION, *claimed)
        finally:
            slot.stop_process(kill=True)
            with self._lock:
                self.executions.pop(execution_id, None)

    def stop_execution(self, execution_id: str, reason: str = "stopped by the operator") -> bool:
        """Ask an active execution to stop; False if it has ended."""
        ok = self.store.stop_execution(execution_id, reason)
        with self._lock:
            running = self.executions.get(execution_id)
        if running is not None:
            running[0].poke.set()
        return ok

    # -- figures -------------------------------------------------------------------------------------------------------
    def workers(self) -> tuple[int, int]:
        """Planning worker processes alive and busy."""
        return sum(s.alive for s in self.slots), sum(s.current is not None for s in self.slots)

    def queue_depth(self) -> int:
        return self.store.counts(JOB)["queued"]
