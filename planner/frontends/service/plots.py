"""Plots drawn in a process of their own, never in the service process (matplotlib is slow to import, holds a
global lock and would stall the event loop's threads): :class:`Plotter` keeps one spawned process
(``concurrent.futures.ProcessPoolExecutor``, started on the first picture asked for) that loads a saved job and
writes the picture ``planner plan --plot`` draws (:func:`draw`), or an execution's picture as ``planner run --plot``
draws it (:func:`draw_run`: the job with the run drawn over it, from the run's stored figures and trace), atomically,
into the service's cache folder. Requests for a picture being drawn share its future.

Kept free of web and database imports (the drawing process imports only the planner).
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import threading
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool


def _start(parent_pid: int, nice: int) -> None:
    """In the drawing process: die with the service, yield to requests, and import matplotlib now (not on the
    first picture)."""
    from planner.frontends.service.tasks.child import die_with_parent, name_process

    die_with_parent(parent_pid)
    name_process("planner-plot")
    if nice:
        try:
            os.nice(nice)
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


def stored_run(figures: dict, trace: bytes):
    """The :class:`drivers.report.ExecutionReport` the plot draws, from an execution's stored figures (the JSON of
    ``GET /v1/executions/{id}``'s report) and trace (the npz :func:`.tasks.functions.trace_files` stores; read without
    pickle)."""
    import io
    import math

    import numpy as np

    from drivers.recording import ExecutionTrace
    from drivers.report import ExecutionReport, IOSwitch

    def num(value) -> float:
        return math.nan if value is None else float(value)

    with np.load(io.BytesIO(trace), allow_pickle=False) as z:
        tr = ExecutionTrace(z["t"], z["xyz"], z["speed"], z["io"], float(z["spacing"]))
    events = tuple(IOSwitch(int(e["bit"]), bool(e["value"]), num(e["planned_s_m"]), num(e["actual_s_m"]),
                            num(e["distance_mm"]), num(e["planned_t_s"]), num(e["actual_t_s"]), num(e["resolution_mm"]))
                   for e in figures.get("io_events", ()))
    return ExecutionReport(mode=str(figures["mode"]), ok=bool(figures["ok"]), reason=figures.get("reason") or "",
                           planned_duration=num(figures.get("planned_duration_s")),
                           duration=num(figures.get("duration_s")), samples=int(figures.get("samples") or 0),
                           max_path_error=num(figures.get("max_path_error_m")), io_events=events,
                           joint_limit_margin=num(figures.get("joint_limit_margin_rad")), trace=tr)


def draw_run(plan: bytes, figures: dict, trace: bytes, target: str) -> int:
    """The picture ``planner run --plot`` draws (:func:`drivers.execute.plot_run`: the saved job ``plan`` with the
    run drawn over it, actual over planned) of a stored execution, written atomically to ``target``; its bytes."""
    from drivers.execute import plot_run
    from planner.job import load_job

    plot_run(load_job(plan), stored_run(figures, trace), target)
    return os.stat(target).st_size


class Plotter:
    """One drawing process (at ``nice`` above the service: the configuration's ``worker_nice``); :meth:`draw` gives
    a future of the target's size (shared while it is drawn)."""

    def __init__(self, nice: int = 0) -> None:
        self.nice = nice
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
                                   initargs=(os.getpid(), self.nice))

    def stop(self) -> None:
        """Stop drawing: a picture being drawn is abandoned, its process killed (a stopping service never waits for
        a picture: on a busy machine one takes tens of seconds; it is drawn again when next asked for)."""
        with self._lock:
            pool, self._pool = self._pool, None
        if pool is not None:
            for proc in list((getattr(pool, "_processes", None) or {}).values()):  # (public from Python 3.14 only)
                with contextlib.suppress(Exception):
                    proc.kill()
            pool.shutdown(wait=True, cancel_futures=True)

    def draw(self, plan: bytes, input_name: str, target: str) -> Future:
        """Draw the picture of the saved job (``plan``: its bytes) into ``target`` (unless it is being drawn
        already)."""
        return self._submit(target, draw, plan, input_name, target)

    def draw_run(self, plan: bytes, figures: dict, trace: bytes, target: str) -> Future:
        """Draw the picture of an execution (:func:`draw_run`) into ``target`` (unless it is being drawn already)."""
        return self._submit(target, draw_run, plan, figures, trace, target)

    def _submit(self, target: str, fn, *args) -> Future:
        with self._lock:
            running = self._inflight.get(target)
            if running is not None:
                return running
            if self._pool is None:
                raise RuntimeError("the plotter is stopped")
            try:
                future = self._pool.submit(fn, *args)
            except BrokenProcessPool:  # the drawing process died (e.g. killed for memory): a new one
                self._pool.shutdown(wait=False)
                self._pool = self._new_pool()
                future = self._pool.submit(fn, *args)
            self._inflight[target] = future
        future.add_done_callback(lambda _f: self._forget(target))
        return future

    def _forget(self, target: str) -> None:
        with self._lock:
            self._inflight.pop(target, None)
