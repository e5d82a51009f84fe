"""The process that executes one job on one robot through the driver layer (:mod:`drivers`), started by the
service for each execution (:mod:`planner.frontends.service.execution_runs`).

It loads the saved job, starts a simulated controller when the robot is simulated (stopped again at the end; it
also dies with this process), connects :class:`drivers.ur.URDriver` to the robot's host only, executes the job and
sends back messages over a pipe:

- ``("stage", name)``: "controller", "connecting", "approach" (the joint move onto the job's start), "run";
- ``("progress", stage, done, total)``: the driver's progress, at most every :data:`PROGRESS_EVERY` s;
- one result: ``("report", figures)`` (the run happened: :func:`report_figures`, with its failure if any) or
  ``("failed", error)`` (refused or failed before the run; ``error`` as :func:`error_figures`).

A ``"stop"`` on the control pipe sets the driver's cancel event: the run ends with the arm stopped (a controlled
stop) and the job's outputs off; before the run's loop has begun (connecting, or the approach move onto the job's
start, which the cancel event does not reach), the controller's program is stopped through its dashboard server.
The process ends with ``os._exit`` once its result is sent (ur_rtde 1.6.5 aborts
the interpreter when it destroys interfaces whose connection dropped). Kept free of web and database imports.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import threading
import time
from pathlib import Path

#: Seconds between progress messages.
PROGRESS_EVERY = 0.2
#: I/O switches listed one by one in the figures (all are counted).
IO_EVENTS_LISTED = 200
#: Seconds between dashboard stops while a stopped execution has not reached its run's loop.
DASHBOARD_STOP_EVERY = 0.25


def error_figures(exc) -> dict:
    """A :class:`drivers.base.DriverError` as JSON: kind, reason, job time t (s), planned pose p[x, y, z, rx, ry, rz]
    (m, rad) and source line (each None when not known)."""
    from planner.frontends.service.worker_process import plain

    return plain({"kind": getattr(exc, "kind", "failure"), "reason": getattr(exc, "reason", str(exc)),
                  "t": getattr(exc, "t", None), "pose": None if getattr(exc, "pose", None) is None else list(exc.pose),
                  "line": getattr(exc, "line", None)})


def report_figures(report) -> dict:
    """The figures of a :class:`drivers.report.ExecutionReport` as JSON (SI units, names with their unit; NaN as
    null), its lines of text (``describe``) and its failure (:func:`error_figures`) or None."""
    from drivers.report import bit_name
    from planner.frontends.service.worker_process import plain

    events = list(report.io_events)
    made = [e for e in events if e.switched]
    worst = report.max_io_distance_mm
    return plain({
        "mode": report.mode, "ok": bool(report.ok), "reason": report.reason,
        "planned_duration_s": report.planned_duration, "duration_s": report.duration, "samples": report.samples,
        "path_length_m": getattr(report, "path_length", math.nan),
        "max_path_error_m": report.max_path_error, "max_path_error_t_s": report.max_path_error_t,
        "joint_limit_margin_rad": report.joint_limit_margin,
        "recorded_every_s": report.recorded_every, "recording_gaps": report.gaps,
        "recording_samples_missed": report.missed, "recording_longest_gap_s": report.longest_gap,
        "io_switches_planned": len(events), "io_switches_made": len(made),
        "max_io_distance_mm": None if math.isinf(worst) else worst,
        "io_events": [{"bit": e.bit, "output": bit_name(e.bit), "value": bool(e.value), "planned_s_m": e.planned_s,
                       "actual_s_m": e.actual_s, "distance_mm": e.distance_mm, "planned_t_s": e.planned_t,
                       "actual_t_s": e.actual_t, "resolution_mm": e.resolution_mm}
                      for e in events[:IO_EVENTS_LISTED]],
        "describe": list(report.describe()),
        "failure": None if report.failure is None else error_figures(report.failure),
    })


class Phase:
    """Where the execution is, for a stop arriving from the service: the controller's host once known, and whether
    the run itself (the driver's loop, which watches the cancel event) has begun."""

    def __init__(self) -> None:
        self.host: str | None = None
        self.running = False
        self.ended = threading.Event()


def stop_from_dashboard(host: str) -> None:
    """Stop the controller's program through its dashboard server ("stop"): the arm halts. Used for a stop before the
    run's loop has begun (the approach move onto the job's start is one blocking joint move the cancel event does not
    reach)."""
    import dashboard_client

    dash = dashboard_client.DashboardClient(host)
    try:
        dash.connect(2000)
        dash.stop()
    finally:
        with contextlib.suppress(Exception):
            dash.disconnect()


def run_execution(task: dict, send, cancel: threading.Event, phase: Phase | None = None) -> None:
    """Execute ``task`` (job_path, mode, robot: RobotConfig fields) and ``send`` its messages (module doc)."""
    from drivers.base import DriverError
    from drivers.execute import execute_job, start_sim
    from planner.job import load_job

    robot = task["robot"]
    mode = task["mode"]
    phase = phase or Phase()
    job = load_job(Path(task["job_path"]))
    last = [0.0]

    def progress(stage: str, done: int, total: int) -> None:
        if not phase.running:
            phase.running = True
            send(("stage", "run"))
        t = time.monotonic()
        if t - last[0] >= PROGRESS_EVERY or done >= total:
            last[0] = t
            send(("progress", str(stage), int(done), int(total)))

    sim = None
    try:
        if robot["host"] is None:
            send(("stage", "controller"))
            speed = float(robot["sim_speed"]) if mode == "program" else 1.0
            sim = start_sim(str(job.settings.robot), modbus=robot["io"] == "modbus", speed=speed)
            host, modbus_port = sim.host, sim.modbus_port or robot["modbus_port"]
        else:
            host, modbus_port = robot["host"], robot["modbus_port"]
        phase.host = host
        if cancel.is_set():
            raise _cancelled()
        send(("stage", "connecting"))
        report = execute_job(job, host, mode=mode, io=robot["io"], modbus_port=modbus_port, progress=progress,
                             cancel=cancel, **_approach(task))
        send(("report", report_figures(report)))
    except DriverError as exc:
        send(("failed", error_figures(exc)))
    finally:
        phase.ended.set()
        if sim is not None:
            with contextlib.suppress(Exception):
                sim.stop()


def _approach(task: dict) -> dict:
    """The driver's options of the task's robot (RobotConfig.driver_options: approach, servo, deviation, program
    size); a task of an older service carries the approach only."""
    robot = task["robot"]
    return robot.get("driver") or {k: float(robot[k]) for k in ("approach_speed", "approach_acceleration")}


def _cancelled():
    from drivers.base import CancelledError

    return CancelledError("cancelled by the caller")


def execution_main(control, results, parent_pid: int, task: dict) -> None:
    """The process: ``control`` (service -> here: "stop"), ``results`` (here -> service: messages)."""
    from planner.frontends.service.worker_process import _die_with_parent, name_process

    _die_with_parent(parent_pid)
    name_process("planner-exec")
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C goes to the service, which stops its executions
    cancel = threading.Event()
    phase = Phase()

    def halt_until_the_run_ends() -> None:
        # connecting or on the approach move: halt the program now, and again until the driver gives up (a move
        # it starts right after a halt is halted too); from the run's loop on, the cancel event stops it
        while not phase.running and not phase.ended.is_set():
            if phase.host is not None:
                with contextlib.suppress(Exception):
                    stop_from_dashboard(phase.host)
            phase.ended.wait(DASHBOARD_STOP_EVERY)

    def stop() -> None:
        if cancel.is_set():
            return
        cancel.set()
        threading.Thread(target=halt_until_the_run_ends, name="execution-halt", daemon=True).start()

    def listen() -> None:
        while True:
            try:
                msg = control.recv()
            except (EOFError, OSError):  # the service is gone: stop the arm
                stop()
                return
            if msg == "stop":
                stop()

    threading.Thread(target=listen, name="execution-control", daemon=True).start()
    code = 0
    try:
        run_execution(task, results.send, cancel, phase)
    except BaseException as exc:  # a bug of ours: say what, never a traceback to the client
        code = 1
        with contextlib.suppress(Exception):
            results.send(("failed", {"kind": "internal", "reason": f"internal error: {type(exc).__name__}: {exc}",
                                     "t": None, "pose": None, "line": None}))
    with contextlib.suppress(Exception):
        results.close()
    os._exit(code)
