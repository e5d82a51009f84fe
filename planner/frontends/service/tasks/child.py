"""The worker process that runs the task functions (:mod:`.functions`), spawned by a :class:`.runner.Slot`.

Over one duplex pipe: in, ``("plan", PlanSpec)``, ``("execute", ExecuteSpec)``, ``("later", task_id)`` (make what the
last planning task left for after its end, :attr:`~.lifecycle.Outcome.later`), ``("stop",)`` (the running task's
cancel event: an execution ends with the arm at rest) and ``None`` (end); out, ``("ready",)`` once the planner is
imported, then each task's :class:`~.lifecycle.Progress` messages and its one :class:`~.lifecycle.Outcome` (and
the :class:`~.lifecycle.Files` of a "later"). A planning
process serves task after task; a process that executed a job ends after it (``os._exit``: ur_rtde 1.6.5 aborts the
interpreter when it destroys interfaces whose connection dropped). A planning task is cancelled by killing its
process (the planner's progress comes too rarely during a long fit to stop within a second).

Kept free of web and database imports: a spawned worker imports only the planner (and the drivers to execute).
"""

from __future__ import annotations

import contextlib
import os
import queue
import signal
import threading


def name_process(name: str) -> None:
    """Linux: the process's name in ``ps`` and ``/proc/PID/comm`` (at most 15 bytes): planner-work, planner-plot,
    planner-exec."""
    with contextlib.suppress(Exception):
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(15, name.encode()[:15] + b"\0", 0, 0, 0)  # PR_SET_NAME


def die_with_parent(parent_pid: int) -> None:
    """Linux: the kernel kills this process when its parent dies (even by SIGKILL)."""
    with contextlib.suppress(Exception):
        import ctypes

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, int(signal.SIGKILL))  # PR_SET_PDEATHSIG
    if os.getppid() != parent_pid:
        os._exit(1)


def child_main(conn, parent_pid: int, name: str = "planner-work", nice: int = 0) -> None:
    """The worker's loop: tasks in, messages out, until the pipe closes or None arrives. ``name``: the process's
    name (planner-work plans, planner-exec executes); ``nice``: niceness it adds to its own (batch work: the
    service's requests come first on a busy machine)."""
    from planner.frontends.service.tasks.functions import Phase, execute_job, halt_until_the_run_ends, plan_job
    from planner.frontends.service.tasks.lifecycle import Files, failed

    die_with_parent(parent_pid)
    name_process(name)
    if nice:
        with contextlib.suppress(OSError):
            os.nice(nice)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C goes to the service, which stops its workers
    import planner.plan  # noqa: F401  (imported before the first job: its time is not the job's)

    send_lock = threading.Lock()
    tasks: queue.Queue = queue.Queue()
    current: dict = {"cancel": threading.Event(), "phase": Phase()}

    def send(msg) -> None:
        with send_lock:
            conn.send(msg)

    def stop() -> None:
        cancel, phase = current["cancel"], current["phase"]
        if cancel.is_set():
            return
        cancel.set()
        threading.Thread(target=halt_until_the_run_ends, args=(phase,), name="execution-halt", daemon=True).start()

    def listen() -> None:
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError):  # the parent is gone: stop what runs (an arm comes to rest)
                stop()
                tasks.put(None)
                return
            if msg == ("stop",):
                stop()
            else:
                tasks.put(msg)
                if msg is None:
                    return

    try:
        send(("ready",))  # the runner hands out tasks (and starts their clocks) from here on
    except OSError:
        return
    threading.Thread(target=listen, name="worker-control", daemon=True).start()
    later: list = []  # what the last planning task left to make after its end is stored (its 3D view data)
    while True:
        task = tasks.get()
        if task is None:
            return
        kind, spec = task
        if kind == "later":  # the runner stored the end of task ``spec``: make and send what it left
            files: dict = {}
            for make in later:
                with contextlib.suppress(Exception):  # (a convenience: made on the view's first request instead)
                    files.update(make())
            later.clear()
            try:
                send(Files(spec, files))
            except (BrokenPipeError, OSError):
                return
            continue
        later.clear()
        current["cancel"], current["phase"] = threading.Event(), Phase()
        try:
            if kind == "plan":
                outcome = plan_job(spec, send, later)
            else:
                outcome = execute_job(spec, send, current["cancel"], current["phase"])
        except BaseException as exc:  # a bug of ours: say what, never a traceback to the client
            outcome = failed("internal", f"internal error: {type(exc).__name__}: {exc}")
        try:
            send(outcome)
        except (BrokenPipeError, OSError):
            return
        if kind != "plan":
            with contextlib.suppress(Exception):
                conn.close()
            os._exit(0)
