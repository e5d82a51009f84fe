"""The two task functions: :func:`plan_job` and :func:`execute_job`. Each takes its task's specification (everything
it needs, the inputs' bytes included: a worker on another machine reads no file of the service's) and a ``report``
callable for :class:`~.lifecycle.Progress` messages, and returns an :class:`~.lifecycle.Outcome`.

Free of web, database and backend: they run in a worker process (:mod:`.child`) of either backend.
"""

from __future__ import annotations

import contextlib
import json
import math
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from planner.frontends.service.tasks.lifecycle import EXECUTION_TICKS, Live, Outcome, Progress, execution_stage, failed

#: Seconds between progress messages of a task.
PROGRESS_EVERY = 0.2
#: I/O switches listed one by one in an execution's figures (all are counted).
IO_EVENTS_LISTED = 200
#: Seconds between dashboard stops while a stopped execution has not reached its run's loop.
DASHBOARD_STOP_EVERY = 0.25
#: Samples per second of an execution's recording relayed live to the service (the page's 3D view), Hz.
LIVE_RATE = 60.0

Report = Callable[[Progress], None]

#: Poses of a job above which the planning task makes its 3D view's data (the whole NX job's 12.9 million: 67 s
#: after its plan, so that its first view is seconds, not a minute). A smaller job's are made by its first view
#: request (about 3 ms per thousand poses: 26 ms for a job of 7,600), which costs a job never viewed nothing (for
#: the 100-waypoint jobs of bench_service they would add 75 % to the planning task).
VIEW_AT_PLAN_POSES = 1_000_000


@dataclass(frozen=True)
class PlanSpec:
    """A planning job: its input (waypoints as the request's JSON text, or a file's bytes under its name), the
    settings (:meth:`planner.PlanSettings.to_dict`) and the reader's options."""

    job_id: str
    input_kind: str  # "waypoints" or "file"
    input_name: str
    settings: dict
    read_options: dict = field(default_factory=dict)
    input_json: str | None = None
    input_data: bytes | None = None
    #: What to do (a large file split across workers, :mod:`.split`): "plan" the job (with ``pieces``: its moves
    #: planned apart in pieces, in order, to join), find its "pieces" (its cutting passes in at most ``parts``
    #: pieces, with their CAM chords), or plan the "piece" of cutting passes ``piece`` = (first, stop).
    step: str = "plan"
    piece: tuple[int, int] | None = None
    pieces: tuple[bytes, ...] | None = None
    parts: int = 0


@dataclass(frozen=True)
class ExecuteSpec:
    """An execution: the saved plan's bytes, the mode ("stream" or "program") and the robot (the fields of
    :class:`planner.frontends.service.config.RobotConfig`; a host of None: a simulated controller started for it)."""

    execution_id: str
    plan: bytes
    mode: str
    robot: dict


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


def _throttled(report: Report) -> Callable[[str, int, int], None]:
    """A planner/driver progress callback sending at most one message every PROGRESS_EVERY s (and the last)."""
    last = [0.0]

    def progress(stage: str, done: int, total: int) -> None:
        t = time.monotonic()
        if t - last[0] >= PROGRESS_EVERY or done >= total:
            last[0] = t
            report(Progress(str(stage), int(done), int(total)))

    return progress


def plan_job(spec: PlanSpec, report: Report, later: list[Callable[[], dict[str, bytes]]] | None = None) -> Outcome:
    """Plan one job with :func:`planner.plan`: done with its saved plan, summary and describe, or failed with the
    planner's one-line error (kind "input": the user's; "internal": ours). A step of a split job (``spec.step``):
    "pieces", done with ``values["pieces"]`` = [[first, stop, chords, work], ...] (:func:`planner.plan.plan_pieces`);
    "piece", done with the piece's moves as ``plan`` (:func:`planner.job.piece_to_bytes`) and ``values["seconds"]``.
    ``later``: where a large job's 3D view data are deferred to, as a callable, to make after its end is stored
    (the outcome says ``later``); without it they are made here."""
    from planner.errors import NumericalError, PlannerError

    try:
        if spec.step != "plan":
            return _piece_step(spec)
        job = _plan(spec, _throttled(report))
        blob = job.to_bytes()
        summary = plain(job.summary())
        passes = int(summary.get("passes") or 0)
        poses = float(summary.get("duration_s") or 0.0) * float(job.settings.rate)
        files: dict[str, bytes] = {}
        if poses > VIEW_AT_PLAN_POSES:  # (a smaller job's are made by its first view request)
            if later is not None:
                later.append(lambda: view_files(job))  # after the job's end is stored: its exports wait for nothing
            else:
                report(Progress("view", passes, passes))
                files = view_files(job)
        return Outcome("done", values={"summary": json.dumps(summary), "describe": json.dumps(list(job.describe())),
                                       "stage": "done", "done": passes, "total": passes},
                       plan=blob, planning_s=float(sum(v for k, v in job.timings.items()
                                                       if k in ("parse", "plan", "reach"))),
                       files=files, later=bool(later))
    except PlannerError as exc:
        return failed("input", str(exc))
    except NumericalError as exc:
        return failed("internal", str(exc))
    except MemoryError:
        return failed("internal", "out of memory while planning")
    except Exception as exc:  # a bug of ours: say what, never a traceback to the client
        return failed("internal", f"internal error: {type(exc).__name__}: {exc}")


@contextlib.contextmanager
def _input_file(spec: PlanSpec):
    """The job's input file written under its name in a temporary folder (the name the planner reports: summary,
    describe, headers), removed after."""
    if spec.input_data is None:
        raise ValueError(f"job {spec.job_id}: its input file is not in the store")
    with tempfile.TemporaryDirectory(prefix="planner-input-") as folder:
        path = Path(folder) / spec.input_name
        path.write_bytes(spec.input_data)
        yield path


def _piece_step(spec: PlanSpec) -> Outcome:
    """The "pieces" or "piece" step of a split job (its input a file)."""
    import importlib

    from planner.job import piece_to_bytes
    from planner.settings import PlanSettings

    P = importlib.import_module("planner.plan")  # (the package's name plan is the function)
    settings = PlanSettings.from_dict(spec.settings)
    with _input_file(spec) as path:
        if spec.step == "pieces":
            pieces = P.plan_pieces(path, settings, max(spec.parts, 1), read_options=spec.read_options)
            return Outcome("done", values={"pieces": [list(p) for p in pieces]})
        if spec.step != "piece" or spec.piece is None:
            raise ValueError(f"job {spec.job_id}: no such step {spec.step!r}")
        tic = time.perf_counter()
        piece = P.plan_piece(path, settings, spec.piece[0], spec.piece[1], read_options=spec.read_options)
        data = piece_to_bytes(piece)
        return Outcome("done", plan=data, values={"seconds": time.perf_counter() - tic})


def view_files(job) -> dict[str, bytes]:
    """The 3D view's data of a planned job (one of more than :data:`VIEW_AT_PLAN_POSES` poses), stored with its plan:
    {"view": the fine path} (:func:`planner.frontends.service.view_data.fine_path`,
    :meth:`~.view_data.ViewPath.to_bytes`); {} if they cannot be made (the view's first request then makes and
    stores them, and says why where they cannot be made)."""
    from planner.frontends.service.view_data import fine_path

    try:
        return {"view": fine_path(job).to_bytes()}
    except Exception:  # (the view is a convenience: never the plan's failure)
        return {}


def _plan(spec: PlanSpec, progress):
    import numpy as np

    from planner.plan import plan
    from planner.settings import PlanSettings

    settings = PlanSettings.from_dict(spec.settings)
    if spec.input_kind == "file":
        with _input_file(spec) as path:
            pieces = None
            if spec.pieces is not None:
                from planner.job import piece_from_bytes

                pieces = [piece_from_bytes(data) for data in spec.pieces]
            return plan(path, settings, read_options=spec.read_options, progress=progress, pieces=pieces)
    data = json.loads(spec.input_json or "{}")
    feeds = data.get("feeds")
    if feeds is not None:
        feeds = np.array([np.nan if f is None else f for f in feeds], dtype=float)
    return plan(np.asarray(data["waypoints"], dtype=float), settings, axes=data.get("axes"), feeds=feeds,
                progress=progress)


# -- executions ---------------------------------------------------------------------------------------------------
def error_figures(exc) -> dict:
    """A :class:`drivers.base.DriverError` as JSON: kind, reason, job time t (s), planned pose p[x, y, z, rx, ry, rz]
    (m, rad) and source line (each None when not known)."""
    return plain({"kind": getattr(exc, "kind", "failure"), "reason": getattr(exc, "reason", str(exc)),
                  "t": getattr(exc, "t", None), "pose": None if getattr(exc, "pose", None) is None else list(exc.pose),
                  "line": getattr(exc, "line", None)})


def report_figures(report) -> dict:
    """The figures of a :class:`drivers.report.ExecutionReport` as JSON (SI units, names with their unit; NaN as
    null), its lines of text (``describe``) and its failure (:func:`error_figures`) or None."""
    from drivers.report import bit_name

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
    """Where an execution is, for a stop: the controller's host once known, and whether the run itself (the driver's
    loop, which watches the cancel event) has begun."""

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


def halt_until_the_run_ends(phase: Phase) -> None:
    """A stop before the run's loop (connecting, or on the approach move): halt the program now, and again until the
    driver gives up (a move it starts right after a halt is halted too); from the run's loop on, the cancel event
    stops it."""
    while not phase.running and not phase.ended.is_set():
        if phase.host is not None:
            with contextlib.suppress(Exception):
                stop_from_dashboard(phase.host)
        phase.ended.wait(DASHBOARD_STOP_EVERY)


def execute_job(spec: ExecuteSpec, report: Report, cancel: threading.Event, phase: Phase | None = None) -> Outcome:
    """Execute the saved plan on the robot through the driver layer (:func:`drivers.execute.execute_job`): a
    simulated controller is started for a simulated robot (and stopped after); a real one is reached at its
    configured host only. Stages reported: "controller", "connecting", then the driver's (``started`` on the first:
    the run has begun). ``cancel`` stops the run with the arm at rest. Done (the report's figures), failed (the
    driver's kind and reason, job time, pose, line) or cancelled."""
    from drivers.base import CancelledError, DriverError
    from drivers.execute import execute_job as run
    from drivers.execute import start_sim
    from planner.job import load_job
    from planner.trajectory import SamplePlaces

    robot = spec.robot
    phase = phase or Phase()
    job = load_job(spec.plan)
    throttled = _throttled(report)
    places = SamplePlaces(job, job.settings.rate)  # the driver counts samples at the job's rate
    ticks = EXECUTION_TICKS
    last: dict = {}  # the run's last progress: where a failed run stopped

    def progress(stage: str, done: int, total: int) -> None:
        """The driver's (stage, samples done, samples) as job time done of the job's, ms, with the move's place."""
        where = places.at(done)
        of = round(ticks * places.duration)
        now = min(round(ticks * where.t), of) if done < total else of
        stage = execution_stage(where.kind, where.pass_index, where.line)
        last.update(stage=stage, done=now, total=of)
        if not phase.running:
            phase.running = True
            report(Progress(stage, now, of, started=True))
        throttled(stage, now, of)

    sim = None
    try:
        if robot["host"] is None:
            report(Progress("controller"))
            speed = float(robot["sim_speed"]) if spec.mode == "program" else 1.0
            sim = start_sim(str(job.settings.robot), modbus=robot["io"] == "modbus", speed=speed)
            host, modbus_port = sim.host, sim.modbus_port or robot["modbus_port"]
        else:
            host, modbus_port = robot["host"], robot["modbus_port"]
        phase.host = host
        if cancel.is_set():
            raise CancelledError("cancelled by the caller")
        report(Progress("connecting"))
        relay = LiveRelay(report)
        result = run(job, host, mode=spec.mode, io=robot["io"], modbus_port=modbus_port, progress=progress,
                     cancel=cancel, samples=relay.samples, **robot["driver"])
        relay.close()
        figures = report_figures(result)
        failure = figures.get("failure")
        files = trace_files(result)
        if figures["ok"]:
            of = round(ticks * places.duration)
            return Outcome("done", values={"report": json.dumps(figures), "stage": "done", "done": of, "total": of},
                           files=files)
        state = "cancelled" if failure and failure["kind"] == "cancelled" else "failed"
        outcome = _ended(state, failure, report=json.dumps(figures), **last)  # (progress: where it stopped)
        return Outcome(outcome.state, outcome.error_kind, outcome.error, outcome.values, files=files)
    except DriverError as exc:  # refused or failed before the run: after a stop, cancelled
        error = error_figures(exc)
        return _ended("cancelled" if error["kind"] == "cancelled" or cancel.is_set() else "failed", error)
    finally:
        phase.ended.set()
        if sim is not None:
            with contextlib.suppress(Exception):
                sim.stop()


class LiveRelay:
    """The run's recorded samples thinned to :data:`LIVE_RATE` and sent as :class:`~.lifecycle.Live` messages by a
    thread of their own (the driver's loop only hands a batch over)."""

    def __init__(self, report: Report) -> None:
        import queue

        self.report = report
        self.queue: queue.SimpleQueue = queue.SimpleQueue()
        self.last = -1.0
        self.thread = threading.Thread(target=self._send, name="execution-live", daemon=True)
        self.thread.start()

    def samples(self, t, x, q, bits) -> None:
        import numpy as np

        slot = np.floor(np.asarray(t) * LIVE_RATE)
        keep = np.flatnonzero(np.diff(np.r_[self.last, slot]) > 0)  # the first sample of each 1/LIVE_RATE s
        if keep.size:
            self.last = float(slot[keep[-1]])
            self.queue.put(Live(t[keep].copy(), q[keep].copy(), x[keep, :3].copy(), bits[keep].copy()))

    def _send(self) -> None:
        while (msg := self.queue.get()) is not None:
            with contextlib.suppress(Exception):  # (the live view is a convenience: never the run's failure)
                self.report(msg)

    def close(self) -> None:
        self.queue.put(None)
        self.thread.join(2.0)
def trace_files(result) -> dict[str, bytes]:
    """The run's trace (:class:`drivers.recording.ExecutionTrace`: job time, actual TCP position and speed, output
    bits; at most ~20,000 samples) as the bytes stored with the execution's end, {"run.trace": npz}, from which the
    service draws the run's plot when asked (:func:`planner.frontends.service.plots.draw_run`); {} when the run
    recorded nothing (it ended before it began)."""
    import io

    import numpy as np

    trace = getattr(result, "trace", None)
    if trace is None or len(trace) < 2:
        return {}
    buf = io.BytesIO()
    np.savez_compressed(buf, t=np.asarray(trace.t, float), xyz=np.asarray(trace.xyz, float),
                        speed=np.asarray(trace.speed, float), io=np.asarray(trace.io, np.int64),
                        spacing=np.float64(trace.spacing))
    return {"run.trace": buf.getvalue()}


def _ended(state, error: dict | None, **values) -> Outcome:
    if error is not None:
        values.update(error_t=error.get("t"), error_pose=None if error.get("pose") is None else
                      json.dumps(error["pose"]), error_line=error.get("line"))
    return Outcome(state, error_kind=None if error is None else str(error["kind"])[:32],
                   error=None if error is None else error["reason"], values=values)
