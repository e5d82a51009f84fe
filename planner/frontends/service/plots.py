"""Plots drawn in a process of their own, never in the service process (matplotlib is slow to import, holds a
global lock and would stall the event loop's threads): :class:`Plotter` keeps one spawned process
(``concurrent.futures.ProcessPoolExecutor``, started on the first picture asked for) that loads a saved job and
writes the picture ``planner plan --plot`` draws, atomically, into the service's cache folder. Requests for a
picture being drawn share its future.

Kept free of web and database imports (the drawing process imports only the planner).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import threading
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool


def _start(parent_pid: int) -> None:
    """In the drawing process: die with the service, yield to requests, and import matplotlib now (not on the
    first picture)."""
    from planner.frontends.service.tasks.child import WORKER_NICE, die_with_parent, name_process

    die_with_parent(parent_pid)
    name_process("planner-plot")
    try:
        os.nice(WORKER_NICE)
    except OSError:
        pass
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot  # noqa: F401

    import planner.export.plot  # noqa: F401


def draw(plan: bytes, input_name: str, target: str) -> int:
    """The CLI's plot of the saved job ``plan`` (its bytes; the export verb's, same title) written atomically to
    ``target``; its bytes."""
    from planner.export import write
    from planner.job import load_job

    job = load_job(plan)
    write(job, target, parameters={"input": input_name})
    return os.stat(target).st_size


class Plotter:
    """One drawing process; :meth:`draw` gives a future of the target's size (shared while it is drawn)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._pool: ProcessPoolExecutor | None = None
        self._inflight: dict[str, Future] = {}

    def start(self) -> None:
        """Ready to draw: the drawing process itself is started by the first picture asked for (a service that
        draws none keeps no matplotlib process)."""
        with self._lock:
            self._pool = self._new_pool()

    def _new_pool(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(max_workers=1, mp_context=mp.get_context("spawn"), initializer=_start,
                                   initargs=(os.getpid(),))

    def stop(self) -> None:
        with self._lock:
            pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)

    def draw(self, plan: bytes, input_name: str, target: str) -> Future:
        """Draw the picture of the saved job (``plan``: its bytes) into ``target`` (unless it is being drawn
        already)."""
        with self._lock:
            running = self._inflight.get(target)
            if running is not None:
                return running
            if self._pool is None:
                raise RuntimeError("the plotter is stopped")
            try:
                future = self._pool.submit(draw, plan, input_name, target)
            except BrokenProcessPool:  # the drawing process died (e.g. killed for memory): a new one
                self._pool.shutdown(wait=False)
                self._pool = self._new_pool()
                future = self._pool.submit(draw, plan, input_name, target)
            self._inflight[target] = future
        future.add_done_callback(lambda _f: self._forget(target))
        return future

    def _forget(self, target: str) -> None:
        with self._lock:
            self._inflight.pop(target, None)
