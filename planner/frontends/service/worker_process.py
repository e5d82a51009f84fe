"""The planning worker process: receives job tasks over a pipe, plans them with :func:`planner.plan`, saves the
job file and sends back progress and the result. One job at a time; cancelled by being killed (the planner's
progress callback comes too rarely during a long fit to stop within a second).

Kept free of web and database imports: a spawned worker imports only the planner.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import time
from pathlib import Path

#: Niceness added to worker processes (PLANNER_WORKER_NICE, default 10).
WORKER_NICE = int(os.environ.get("PLANNER_WORKER_NICE", "10") or 0)
#: Seconds between progress messages.
PROGRESS_EVERY = 0.2


def name_process(name: str) -> None:
    """Linux: the process's name in ``ps`` and ``/proc/PID/comm`` (at most 15 bytes): planner-work, planner-plot,
    planner-exec."""
    with contextlib.suppress(Exception):
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(15, name.encode()[:15] + b"\0", 0, 0, 0)  # PR_SET_NAME


def _die_with_parent(parent_pid: int) -> None:
    """Linux: the kernel kills this process when the service dies (even by SIGKILL)."""
    with contextlib.suppress(Exception):
        import ctypes

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, int(signal.SIGKILL))  # PR_SET_PDEATHSIG
    if os.getppid() != parent_pid:
        os._exit(1)


def plain(value):
    """JSON-safe values: numpy scalars and arrays to Python, non-finite floats to None."""
    import numpy as np

    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def run_task(task: dict, send) -> None:
    """Plan one job and ``send`` ("progress", stage, done, total) messages and one result:
    ("done", result dict) or ("failed", kind, message), kind "input" (the user's) or "internal"."""
    import numpy as np

    from planner.errors import NumericalError, PlannerError
    from planner.plan import plan
    from planner.settings import PlanSettings

    parent = task["parent_pid"]
    last = [0.0]

    def progress(stage: str, done: int, total: int) -> None:
        if os.getppid() != parent:
            os._exit(1)
        t = time.monotonic()
        if t - last[0] >= PROGRESS_EVERY or done >= total:
            last[0] = t
            send(("progress", str(stage), int(done), int(total)))

    try:
        settings = PlanSettings.from_dict(task["settings"])
        if task["kind"] == "file":
            job = plan(Path(task["input_path"]), settings, read_options=task["read_options"], progress=progress)
        else:
            data = json.loads(task["input_json"])
            feeds = data.get("feeds")
            if feeds is not None:
                feeds = np.array([np.nan if f is None else f for f in feeds], dtype=float)
            job = plan(np.asarray(data["waypoints"], dtype=float), settings, axes=data.get("axes"), feeds=feeds,
                       progress=progress)
        size = job.save(task["out_path"])
        send(("done", {"summary": plain(job.summary()), "describe": list(job.describe()),
                       "job_bytes": int(size), "planning_s": float(sum(v for k, v in job.timings.items()
                                                                       if k in ("parse", "plan", "reach")))}))
    except PlannerError as exc:
        send(("failed", "input", str(exc)))
    except NumericalError as exc:
        send(("failed", "internal", str(exc)))
    except MemoryError:
        send(("failed", "internal", "out of memory while planning"))
    except Exception as exc:  # a bug of ours: say what, never a traceback to the client
        send(("failed", "internal", f"internal error: {type(exc).__name__}: {exc}"))


def worker_main(conn, parent_pid: int) -> None:
    """The worker's loop: a task dict in, messages out, until the pipe closes or None arrives."""
    _die_with_parent(parent_pid)
    name_process("planner-work")
    with contextlib.suppress(OSError):
        os.nice(WORKER_NICE)  # batch work: the service's requests come first on a busy machine
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C goes to the service, which stops its workers
    import planner.plan  # noqa: F401  (imported before the first job: its time is not the job's)

    try:
        conn.send(("ready",))  # the slot hands out jobs (and starts their clocks) from here on
    except OSError:
        return

    while True:
        try:
            task = conn.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        try:
            run_task(task, conn.send)
        except (BrokenPipeError, OSError):
            return
