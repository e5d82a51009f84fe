"""One task run in a worker process and relayed into the store: the one runner of both kinds of task and both
backends (the local backend's slots, the threads of a ``planner worker``).

A :class:`Slot` owns one spawned worker process (:func:`.child.child_main`) and drives one task at a time in it:
it sends the specification, writes the task's progress and heartbeats into the store, looks at the task's row for a
cancellation every :data:`.transitions.CANCEL_POLL` s, enforces the time limit of a planning job, and stores the
outcome (conditionally: :meth:`.transitions.Transitions.finish`).

- Cancel of a job: its process is killed (within ~0.2 s of the request, in whichever process or machine runs it) and
  a fresh one started, importing while the runner goes on to its next task (which waits only for what is left of
  that start).
- Stop of an execution: "stop" goes to its process, whose driver ends the run with a controlled stop (the arm at
  rest within a second); a process that has not ended :data:`STOP_GRACE` s later is killed (its connection drops and
  the controller stops the arm).
- A worker process that dies fails its task with the exit code; a job running longer than ``job_timeout_s`` is
  killed and failed with the reason.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing as mp
import os
import threading
import time
from collections.abc import Callable
from typing import Any

from sqlalchemy.exc import DBAPIError

from planner.frontends.service.live import HUB
from planner.frontends.service.tasks.lifecycle import EXECUTION, JOB, Files, Kind, Live, Outcome, Progress, failed
from planner.frontends.service.tasks.transitions import CANCEL_POLL, HEARTBEAT_EVERY, Transitions

log = logging.getLogger("planner.frontends.service")

#: Seconds a stopped execution's process has to end before it is killed.
STOP_GRACE = 3.0
#: Seconds a new worker process may take to import the planner before it is given up.
WORKER_START_TIMEOUT = 120.0
#: Seconds between progress writes of a job and of an execution.
PROGRESS_WRITE_EVERY = {"job": 0.5, "execution": 0.25}

#: Called with (kind, outcome, seconds the task ran) once a task's end is stored.
Finished = Callable[[Kind, Outcome, float], None]


class Slot:
    """One worker process and the driving of the task it runs.

    Parameters
    ----------
    store : Transitions
    job_timeout_s : float
        Wall time a planning job may take, s.
    stopping : threading.Event
        Set when this process is stopping: a job is put back in the queue, an execution stopped.
    name : str
        The worker process's name (planner-work, planner-exec).
    on_finish : callable or None
        Told of every end this slot stored.
    cancel_poll : float
        Seconds between looks at the task's row for a cancellation (a backend whose requests :attr:`poke` the slot
        looks rarely: the look is then only a safety net).
    live : LiveHub or RedisLive, optional
        Where an execution's live samples go (:mod:`planner.frontends.service.live`; default this process's
        :data:`~planner.frontends.service.live.HUB`).
    nice : int
        Niceness the worker process adds to this one's (0..19; the local backend's ``worker_nice``; a ``planner
        worker`` runs at its own niceness already, its processes add none).
    """

    def __init__(self, store: Transitions, job_timeout_s: float, stopping: threading.Event,
                 name: str = "planner-work", on_finish: Finished | None = None, cancel_poll: float = CANCEL_POLL,
                 live: Any = None, nice: int = 0):
        self.store = store
        self.nice = nice
        self.cancel_poll = cancel_poll
        self.live = HUB if live is None else live
        self.job_timeout_s = job_timeout_s
        self.stopping = stopping
        self.name = name
        self.on_finish = on_finish
        self.process: Any = None
        self.conn: Any = None
        self.ready = False
        self._start_by = 0.0
        self.current: tuple[str, int] | None = None
        #: Set by the process's own request path (the local backend): look at the row now, not at the next poll.
        self.poke = threading.Event()

    # -- process ----------------------------------------------------------------------------------------------------
    def start_process(self, beat: Callable[[], None] | None = None, wait: bool = True) -> None:
        """Start the worker process and (``wait``) wait until it has imported the planner; ``beat`` (the claimed
        task's heartbeat) is called every HEARTBEAT_EVERY s meanwhile (on a busy machine the imports take tens of
        seconds: the task must not look dead). Not ``wait``: the process imports while this thread goes on (a
        fresh process after a task's cancel or failure; the next task waits for what is left of its start)."""
        from planner.frontends.service.tasks.child import child_main

        ctx = mp.get_context("spawn")
        parent, child = ctx.Pipe()
        proc = ctx.Process(target=child_main, args=(child, os.getpid(), self.name, self.nice), name=self.name,
                           daemon=True)
        proc.start()
        child.close()
        self.process, self.conn = proc, parent
        self.ready = False
        self._start_by = time.monotonic() + WORKER_START_TIMEOUT
        if wait:
            self._wait_ready(beat)

    def _wait_ready(self, beat: Callable[[], None] | None) -> None:
        """Wait for the started process's "ready" (its imports done: a job's time limit counts from its start, not
        from the worker's), until WORKER_START_TIMEOUT s after its start."""
        while self.conn is not None and time.monotonic() < self._start_by:
            if self._take_ready(min(HEARTBEAT_EVERY, max(self._start_by - time.monotonic(), 0.0))):
                break
            if beat is not None:
                with contextlib.suppress(DBAPIError):
                    beat()
        if not self.ready:
            log.error("worker process %s did not start within %g s", self.name, WORKER_START_TIMEOUT)

    def settle(self) -> None:
        """Take the "ready" of a process started in the background if it has come (without waiting; from the thread
        that runs this slot's tasks, between them: :attr:`alive` then counts it)."""
        if not self.ready and self.conn is not None:
            self._take_ready(0.0)

    def _take_ready(self, timeout: float) -> bool:
        """The process's first message read if it comes within ``timeout`` s: True once it has come (``ready`` says
        whether it was "ready"; a process that died is not)."""
        try:
            if not self.conn.poll(timeout):
                return False
            self.ready = self.conn.recv() == ("ready",)
        except (EOFError, OSError):
            self.ready = False
        return True

    def stop_process(self, kill: bool = False) -> None:
        proc, conn = self.process, self.conn
        self.process = self.conn = None
        self.ready = False
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
        """The worker process is running and ready for tasks."""
        return self.ready and self.process is not None and self.process.is_alive()

    # -- one task ---------------------------------------------------------------------------------------------------
    def run(self, kind: Kind, task_id: str, attempt: int, spec: Any) -> None:
        """Run the claimed task (its row active, this attempt) to its end and store the end."""
        self.current = (task_id, attempt)
        t0 = time.monotonic()
        try:
            outcome = self._run(kind, task_id, attempt, spec)
        except Exception:  # never lose the slot: fail the task with the reason
            log.exception("the runner failed on %s %s", kind.name, task_id)
            self.stop_process(kill=True)
            outcome = failed("internal", "internal error in the task runner (see the log of the process running "
                                         "it)")
        finally:
            self.current = None
            self.poke.clear()
        try:
            if outcome is not None and self._finish(kind, task_id, attempt, outcome):
                if self.on_finish:
                    self.on_finish(kind, outcome, time.monotonic() - t0)
                if outcome.later:
                    self._later(task_id)
        finally:
            if kind is EXECUTION:  # (after its end is stored: the live stream's end names the final state)
                self.live.end(task_id)

    def _later(self, task_id: str) -> None:
        """What the task's process left to make after the task's end (a large job's 3D view data: the job is done,
        its exports served, meanwhile), made and stored; not if this process stops first (the view's first request
        makes them then), nor if the worker process dies."""
        if self.conn is None:  # (the process was stopped with the task)
            return
        self.current = (task_id, 0)
        try:
            self.conn.send(("later", task_id))
            while not self.stopping.is_set():
                if not self.conn.poll(0.2):
                    continue
                msg = self.conn.recv()
                if isinstance(msg, Files):
                    for name, data in msg.files.items():
                        self.store.keep_data(task_id, name, data)
                    return
        except (EOFError, OSError):  # the process died: the next task starts another
            self.stop_process(kill=True)
        except DBAPIError as exc:
            log.warning("cannot store what %s left: %s", task_id, str(exc).splitlines()[0])
        finally:
            self.current = None
        if self.stopping.is_set():
            self.stop_process(kill=True)

    def _finish(self, kind: Kind, task_id: str, attempt: int, outcome: Outcome) -> bool:
        """Store the end; the database away for a moment is waited for (1, 2, 4 ... s, up to a minute in all)."""
        delay = 1.0
        for _ in range(6):
            try:
                return self.store.finish(kind, task_id, attempt, outcome)
            except DBAPIError as exc:
                log.warning("cannot store the end of %s %s yet: %s", kind.name, task_id, str(exc).splitlines()[0])
                time.sleep(delay)
                delay *= 2
        return self.store.finish(kind, task_id, attempt, outcome)

    def ask(self, task_id: str, attempt: int, spec: Any, *, beat: Callable[[], None] | None = None,
            live: Callable[[str], bool] | None = None, on_stopping: Callable[[], None] | None = None,
            progress: bool = True, deadline: float | None = None) -> Outcome | None:
        """One step of a planning job in this slot's process (a split job's pieces, a piece's fits, the join:
        :mod:`.split`), its end not stored: the step's outcome, or None if it was stopped (the job no longer
        ``live``, by its state; or this worker stopping, after ``on_stopping``). ``beat``: the heartbeat (default: the
        job's); ``progress``: the step's progress written to the job's row; ``deadline``: time.monotonic() by which
        the step is failed "limit" (default: the job time limit from now)."""
        self.current = (task_id, attempt)
        try:
            return self._run(JOB, task_id, attempt, spec, beat=beat, live=live, on_stopping=on_stopping,
                             progress=progress, deadline=deadline)
        except Exception:  # never lose the slot: fail the step with the reason
            log.exception("the runner failed on a step of job %s", task_id)
            self.stop_process(kill=True)
            return failed("internal", "internal error in the task runner (see the log of the process running it)")
        finally:
            self.current = None
            self.poke.clear()

    def _run(self, kind: Kind, task_id: str, attempt: int, spec: Any, *, beat: Callable[[], None] | None = None,
             live: Callable[[str], bool] | None = None, on_stopping: Callable[[], None] | None = None,
             progress: bool = True, deadline: float | None = None) -> Outcome | None:
        """The task's outcome to store, or None if the task's end is stored already (cancelled) or it went back to
        the queue."""
        if beat is None:
            def beat() -> None:
                self.store.heartbeat(kind, task_id, attempt)

        def write(p: Progress) -> None:
            """Store the task's progress (a missed write: shown at the next one)."""
            with contextlib.suppress(DBAPIError):
                self.store.progress(kind, task_id, attempt, p)

        if not self.alive:
            starting = (not self.ready and self.process is not None and self.process.is_alive()
                        and time.monotonic() < self._start_by)
            if not starting:
                self.stop_process(kill=True)
                self.start_process(beat, wait=False)
            self._wait_ready(beat)
        if not self.alive:
            return failed("internal", f"the worker process did not start within {WORKER_START_TIMEOUT:g} s")
        assert self.conn is not None and self.process is not None
        self.conn.send(("plan" if kind is JOB else "execute", spec))
        start = time.monotonic()
        if deadline is None:
            deadline = start + self.job_timeout_s if kind is JOB else float("inf")
        next_look = start + self.cancel_poll
        next_beat = start + HEARTBEAT_EVERY
        # progress is written at most every PROGRESS_WRITE_EVERY s, the latest message at the latest that long after
        # the write before (a stage that lasts, "preparing the 3D view", shows within it); a job shorter than that
        # writes none (its claim and end are its two commits); an execution writes its first message at once
        last_write = start if kind is JOB else 0.0
        pending: Progress | None = None
        stop_sent: float | None = None
        while True:
            t = time.monotonic()
            if t >= next_look or self.poke.is_set() or self.stopping.is_set():
                self.poke.clear()
                next_look = t + self.cancel_poll
                try:
                    state = self.store.state(kind, task_id)
                except DBAPIError:  # the database away for a moment: the work goes on, the next look tries again
                    state = None
                if state is None:
                    pass
                elif kind is JOB:
                    alive = state == "running" if live is None else live(state)
                    if self.stopping.is_set() or not alive:  # cancelled (or ended) meanwhile; or stopping
                        self.stop_process(kill=True)
                        if self.stopping.is_set() and alive:
                            if on_stopping is None:
                                self.store.requeue(task_id, attempt)
                            else:
                                on_stopping()
                        else:
                            self.start_process(wait=False)
                        return None
                elif (state == "stopping" or self.stopping.is_set()) and stop_sent is None:
                    if self.stopping.is_set():
                        self.store.stop_execution(task_id, "the service is shutting down")
                    stop_sent = t
                    with contextlib.suppress(OSError):
                        self.conn.send(("stop",))
            if stop_sent is not None and t - stop_sent > STOP_GRACE:
                self.stop_process(kill=True)
                return Outcome("cancelled", error_kind="cancelled", error=f"stopped; the execution's process did not "
                                                                          f"end within {STOP_GRACE:g} s and was killed")
            if t > deadline:
                self.stop_process(kill=True)
                self.start_process(wait=False)
                return failed("limit", f"planning took longer than the service's limit of {self.job_timeout_s:g} s")
            if pending is not None and t - last_write >= PROGRESS_WRITE_EVERY[kind.name]:
                write(pending)
                last_write, next_beat, pending = t, t + HEARTBEAT_EVERY, None
            if t >= next_beat:
                next_beat = t + HEARTBEAT_EVERY
                with contextlib.suppress(DBAPIError):  # (a missed beat: the next one tries again)
                    beat()
            try:
                ready = self.conn.poll(0.05)
                msg = self.conn.recv() if ready else None
            except (EOFError, OSError):
                ready, msg = True, None
            if not ready:
                continue
            if msg is None:  # the process died
                self.process.join(1.0)
                code = self.process.exitcode
                self.stop_process(kill=True)
                if kind is JOB:
                    self.start_process(wait=False)
                    return failed("internal", f"the worker process planning this job died (exit code {code}); the "
                                              "job may need more memory than the worker has")
                return failed("internal", f"the execution's process ended without a result (exit code {code})")
            if isinstance(msg, Progress):
                if not progress:
                    continue
                if msg.started or t - last_write >= PROGRESS_WRITE_EVERY[kind.name] or (
                        kind is EXECUTION and msg.done >= msg.total > 0):
                    write(msg)
                    last_write, next_beat, pending = t, t + HEARTBEAT_EVERY, None
                else:
                    pending = msg  # written once PROGRESS_WRITE_EVERY s have passed, unless a newer one comes
            elif isinstance(msg, Live):  # the execution's joint states, for the page's live view
                self.live.add(task_id, msg.t, msg.q, msg.xyz, msg.io)
            elif isinstance(msg, Outcome):
                if kind is EXECUTION:  # its process ends after it
                    self.stop_process()
                return msg
