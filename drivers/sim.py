"""Dry runs in-process: the simulated controller's motion model without sockets, as a :class:`RobotDriver`.

:class:`SimDriver` holds one :class:`sim.core.Core` (the simulated controller's state, its control period, its
one motion model :class:`sim.motion.MotionModel`, its safety and its URScript interpreter) and drives it
directly, one 2 ms control period per :meth:`sim.core.Core.tick`, as fast as the CPU allows (or paced to
``speed`` times the wall clock). It executes a job the way :class:`drivers.ur.URDriver` does on a controller:

- "stream": a joint move onto ``job.start_joints`` (``moveJ``: the same joint trajectory planner as the
  controller's), then one ``servoj`` target per sample of the job's trajectory (the planner's own joints,
  lookahead and gain as the driver's), through the motion model's servo tracking; the last target held for
  ``settle`` seconds, then a controlled stop (``servoStop``: ``stopl`` at ``deceleration``). Each change of the
  trajectory's I/O bits is switched when the actual TCP reaches its station, by URDriver's own rule.
- "program": the same joint move onto the start, then the job's URScript program
  (:func:`planner.export.job_program`) loaded into the controller core and run by :mod:`sim.urscript`'s
  interpreter (the one the simulated controller runs for its script ports) until it ends.

So for the same job it records the same trajectory as :class:`sim.SimController` (up to the servo following
error a real-time client's late commands add; see ``tests/test_drivers_sim.py``), and a dry run means what a
real run means. The report is :func:`drivers.report.execution_report`, the one every driver returns.

What is not simulated here: the network (no RTDE, dashboard or Modbus: nothing can drop or be late), and a
period overrun (the loop never misses a period). Faults the controller model raises (a target out of the
joint limits or unreachable, a joint speed over its limit, a program outside the interpreter's subset) are
protective stops or runtime errors exactly as on the simulated controller.
"""

from __future__ import annotations

import math
import threading
import time

import numpy as np

from drivers.base import DEFAULT_MODE, MODES, DriverError, NotReadyError, ProtectiveStopError, RobotState
from drivers.feed import HISTORY
from drivers.jobs import check_job, stop_requested
from drivers.plan_window import PlannedPath
from drivers.report import ExecutionReport, check_tolerance, execution_report, new_recording
from drivers.servo import DEFAULT_GAIN, DEFAULT_LOOKAHEAD, ServoModel, ServoShaper, check_servo
from drivers.stations import Station, Stations
from sim.core import RUNTIME_PAUSED, RUNTIME_PLAYING, RUNTIME_STOPPED, SAFETY_PROTECTIVE_STOP, Core
from sim.io_state import IOState
from sim.motion import DT, MotionError, Segment


class _Recorder:
    """One run's samples: into the bounded :class:`drivers.recording.Recording`, and with ``keep`` also whole
    (t, commanded joints, actual joints, TCP pose, output bits) for :attr:`SimDriver.recording`."""

    def __init__(self, rec, keep: bool) -> None:
        self.rec = rec
        self.keep = keep
        self.lists: list[list] = [[], [], [], [], []]
        self.n = 0  # samples so far
        self.last_x = np.full(6, np.nan)  # the last sample's TCP pose

    def sample(self, core, t: float) -> None:
        m = core.motion
        x = core.tcp_pose().copy()
        q = m.q.copy()
        bits = core.io.digital_out
        self.rec.add(t, x, q, bits)
        self.last_x = x
        self.n += 1
        if self.keep:
            for lst, v in zip(self.lists, (t, m.commanded.copy(), q, x, bits), strict=True):
                lst.append(v)


class ProgramError(DriverError):
    """The job's program was refused (outside the interpreter's subset) or halted by a runtime error."""

    kind = "program error"


def _positive(value, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not v > 0 or math.isnan(v):
        raise ValueError(f"{name} must be > 0, got {value!r}")
    return v


class SimDriver:
    """The simulated controller's motion model in-process (see the module doc).

    Parameters
    ----------
    model : str
        UR model (``"ur5e"``, ...), checked against ``job.settings.robot``.
    speed : float
        Simulated seconds per wall-clock second; ``math.inf`` (default): as fast as possible. A finite speed
        paces the run (so that :meth:`pause`, :meth:`stop` and a cancel event act during it as on a robot).
    q0 : array_like (6,), optional
        Initial joints, rad (default: the simulated controller's home position).
    lookahead, gain : float
        servoj lookahead time (s, 0.03..0.2) and gain (100..2000), as :class:`drivers.ur.URDriver`'s.
    compensate : bool
        Shape the servo targets by the servo model (:class:`drivers.servo.ServoShaper`), as URDriver does.
    path_tolerance, fail_on_deviation
        As :class:`drivers.ur.URDriver`'s: the report lists the stretches beyond the path tolerance (m), and with
        ``fail_on_deviation`` such a run fails.
    settle : float
        Seconds the last target of a stream is held before the controlled stop, s (URDriver's ``settle``).
    deceleration : float
        Deceleration of the controlled stop (servoStop), m/s^2 of the tool.
    record : bool
        Keep every sample of the last run in :attr:`recording` (memory grows with the job: for tests and
        comparisons). Without it a run's memory is bounded: the report is reduced as the run goes
        (:class:`drivers.recording.Recording`).
    """

    def __init__(self, model: str = "ur5e", *, speed: float = math.inf, q0=None,
                 lookahead: float = DEFAULT_LOOKAHEAD, gain: float = DEFAULT_GAIN, compensate: bool = True,
                 settle: float = 0.3, deceleration: float = 10.0, record: bool = False,
                 path_tolerance: float | None = None, fail_on_deviation: bool = False) -> None:
        from planner.kinematics import get_model

        self.model = get_model(model).name
        self.speed = _positive(speed, "speed")
        self.q0 = None if q0 is None else np.asarray(q0, dtype=float).reshape(6)
        self.lookahead, self.gain = check_servo(lookahead, gain)
        self.compensate = bool(compensate)
        self.path_tolerance = check_tolerance(path_tolerance)
        if fail_on_deviation and self.path_tolerance is None:
            raise ValueError("fail_on_deviation needs a path_tolerance")
        self.fail_on_deviation = bool(fail_on_deviation)
        self.settle = float(settle)
        if not self.settle >= 0:
            raise ValueError(f"settle must be >= 0 s, got {settle!r}")
        self.deceleration = _positive(deceleration, "deceleration")
        self.core: Core | None = None
        self._paused = threading.Event()
        self._stop = threading.Event()
        self._mode: str | None = None
        self._wall0 = self._sim0 = 0.0
        self.record = bool(record)
        #: With ``record``: what the last :meth:`execute` recorded, dict of arrays t (n,) job time s, target_q
        #: (n, 6) commanded joints, actual_q (n, 6), tcp (n, 6), digital_out (n,).
        self.recording: dict | None = None

    # ---- connection ---------------------------------------------------------------------------------
    def connect(self) -> None:
        """Start the in-process controller (arm at ``q0``, powered, brakes released, no program)."""
        if self.core is None:
            core = self.core = Core(self.model, IOState())
            if self.q0 is not None:
                core.motion._check_q(self.q0, "q0")
                core.motion.q = self.q0.copy()
                core.motion.servo_target = self.q0.copy()
                core.motion.servo_filtered = self.q0.copy()

    def close(self) -> None:
        """Drop the in-process controller (the arm's state goes with it)."""
        self.core = None

    def __enter__(self) -> SimDriver:
        self.connect()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _need(self) -> Core:
        if self.core is None:
            raise NotReadyError("the simulated robot is not connected: call connect() first")
        return self.core

    # ---- state --------------------------------------------------------------------------------------
    def state(self) -> RobotState:
        core = self._need()
        with core.lock:
            return RobotState(
                joints=tuple(float(x) for x in core.motion.q), tcp_pose=tuple(float(x) for x in core.tcp_pose()),
                robot_mode=core.robot_mode, safety_mode=core.safety_mode, runtime_state=core.runtime_state,
                protective_stop=core.safety_mode == SAFETY_PROTECTIVE_STOP, emergency_stop=False,
                program_running=core.runtime_state == RUNTIME_PLAYING, digital_out=core.io.digital_out)

    def _fault(self) -> DriverError | None:
        core = self._need()
        if core.safety_mode == SAFETY_PROTECTIVE_STOP:
            text = next((m for _, src, m in reversed(core.log) if src == "Safety"), "protective stop")
            return ProtectiveStopError(text)
        if core.robot_mode != 7:
            return NotReadyError(f"the robot is not running (robot mode {core.robot_mode})")
        return None

    def _check_job(self, job) -> None:
        check_job(job, self.model, "the simulated robot is")
        ticks = 1.0 / (float(job.settings.rate) * DT)
        if abs(ticks - round(ticks)) > 1e-9:
            raise DriverError(f"the job's rate {job.settings.rate:g} Hz is not a whole division of the "
                              f"controller's {1 / DT:g} Hz")

    # ---- the clock ----------------------------------------------------------------------------------
    def _tick(self, n: int = 1) -> None:
        """``n`` control periods; paced to the wall clock when ``speed`` is finite."""
        core = self._need()
        with core.lock:
            for _ in range(n):
                core.tick()
        if math.isfinite(self.speed):
            ahead = (core.time - self._sim0) / self.speed - (time.perf_counter() - self._wall0)
            if ahead > 0.002:
                time.sleep(ahead)

    def _start_clock(self) -> None:
        self._wall0 = time.perf_counter()
        self._sim0 = self._need().time

    # ---- motions ------------------------------------------------------------------------------------
    def move_to_start(self, job, *, speed: float = 0.5, acceleration: float = 0.5) -> None:
        """A joint move (rad/s, rad/s^2) onto ``job.start_joints`` (the controller's movej)."""
        self._check_job(job)
        core = self._need()
        err = self._fault()
        if err is not None:
            raise err
        q0 = np.asarray(job.start_joints, dtype=float)
        self._start_clock()
        with core.lock:
            try:
                seg = Segment(q0, _positive(speed, "speed"), _positive(acceleration, "acceleration"))
                core.motion.plan_joint([seg])
            except MotionError as exc:
                core.protective_stop(str(exc))
        while core.motion.busy:
            self._tick()
        err = self._fault()
        if err is not None:
            raise type(err)(f"move to the start: {err.reason}", t=0.0, line=int(job.moves[0].line) if job.moves
                            else None)
        gap = float(np.abs(core.motion.q - q0).max())
        if gap > 1e-3:
            raise DriverError(f"the move to the start ended {gap:.4f} rad from the start joints", t=0.0)

    def pause(self) -> None:
        """Hold the arm on the path (stream: the target stops advancing; program: the program pauses)."""
        self._paused.set()
        core = self.core
        if self._mode == "program" and core is not None:
            with core.lock:
                core.pause()

    def resume(self) -> None:
        """Continue after :meth:`pause`."""
        self._paused.clear()
        core = self.core
        if self._mode == "program" and core is not None:
            with core.lock:
                core.resume()

    def stop(self) -> None:
        """End the run now with a controlled stop; its report says CancelledError (stopped by the caller)."""
        self._stop.set()

    def _stopped(self, cancel) -> DriverError | None:
        return stop_requested(cancel, self._stop)

    # ---- execution ----------------------------------------------------------------------------------
    def execute(self, job, *, mode: str = DEFAULT_MODE, progress=None,
                cancel: threading.Event | None = None) -> ExecutionReport:
        """Execute ``job`` on the simulated arm and return its report (``report.failure`` on failure).

        DriverError is raised only when the run cannot start (not connected, wrong job, robot not ready);
        once the arm moves, every failure ends the run with the arm stopped and is returned in the report.
        """
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        self._check_job(job)
        core = self._need()
        err = self._fault()
        if err is not None:
            raise err
        self._stop.clear()
        self._paused.clear()
        planned = PlannedPath(job)  # read once, kept in summary: bounded memory
        self.move_to_start(job)
        mask = planned.mask
        if mask:
            core.io.set_digital_out(mask, 0)
        self._mode = mode
        self._start_clock()
        try:
            run = self._stream if mode == "stream" else self._program
            rec, failure = run(job, planned, mask, progress, cancel)
        finally:
            self._mode = None
        if self.record:
            t, target, q, x, bits = (np.asarray(a, dtype=float) for a in rec.lists)
            self.recording = {"t": t, "target_q": target.reshape(-1, 6), "actual_q": q.reshape(-1, 6),
                              "tcp": x.reshape(-1, 6), "digital_out": bits.astype(np.int64)}
        if mode == "stream":
            cause = (f"servo lag (servoj lookahead {self.lookahead:g} s, gain {self.gain:g}, "
                     + ("targets shaped by the servo model)" if self.compensate else "planned joints unshaped)"))
        else:
            cause = "the controller's blending of the program's moves (movep)"
        return execution_report(job, rec.rec, mode=mode, failure=failure, planned=planned,
                                recording="every control period", lag_cause=cause,
                                fail_on_deviation=self.fail_on_deviation)

    @staticmethod
    def _locate(err: DriverError, k: int, planned: PlannedPath, rec=None) -> DriverError:
        """``err`` at planned sample ``k``: its job time, planned TCP pose p[x, y, z, rx, ry, rz] and source line."""
        if planned.n == 0:
            return err
        t, pose, line = planned.at(k, rec.rec.planned if rec is not None else None)
        return err.located(t, pose, line)

    def _halt(self, failure: DriverError, mask: int) -> None:
        """After a failure: a controlled stop of a moving arm (a faulted one is halted already), outputs off."""
        core = self._need()
        with core.lock:
            if self._mode == "program":
                core.stop_program()
            elif core.safety_mode != SAFETY_PROTECTIVE_STOP and np.abs(core.motion.qd).max() > 0:
                core.motion.plan_stop(self.deceleration, linear=True)
        while core.motion.busy:
            self._tick()
        if mask:
            core.io.set_digital_out(mask, 0)

    def _stream(self, job, planned, mask, progress, cancel):
        core = self._need()
        m = core.motion
        total = planned.n
        rate = float(job.settings.rate)
        ticks = round(1.0 / (rate * DT))
        dt = 1.0 / rate
        rec = _Recorder(new_recording(job, planned, tolerance=self.path_tolerance), self.record)
        failure = None
        prev_io = 0
        stations = Stations(core.io.set_digital_out)  # switches whose station the actual TCP has not reached yet
        k = 0
        report_every = max(1, int(rate // 10))
        t_last, q_last = 0.0, None
        tail = np.zeros((0, 3))  # the planned positions before the chunk (a station's direction of travel)
        shaper = ServoShaper(ServoModel(self.lookahead, self.gain, dt), job.start_joints, compensate=self.compensate)

        try:
            for chunk in job.trajectory(rate).chunks():
                qs, ios, times = shaper.shape(chunk.joints), chunk.io.tolist(), chunk.times.tolist()
                pos = np.vstack((tail, chunk.poses[:, :3]))
                h0 = tail.shape[0]
                tail = pos[-HISTORY:]
                i, n = 0, len(times)
                while i < n:
                    err = self._stopped(cancel)
                    if err is not None:
                        raise err
                    paused = self._paused.is_set()
                    with core.lock:
                        try:
                            m.servo(qs[i], dt, self.lookahead, self.gain)
                        except MotionError as exc:
                            core.protective_stop(str(exc))
                    if ios[i] != prev_io and not paused:
                        stations.add(Station.on_path(k, ios[i] ^ prev_io, ios[i], pos, h0 + i, rate=rate))
                        prev_io = ios[i]
                    self._tick(ticks)
                    t_last, q_last = times[i], qs[i]
                    rec.sample(core, t_last)
                    stations.reached(rec.last_x, k)
                    f = self._fault()
                    if f is not None:
                        raise f
                    if not paused:
                        i += 1
                        k += 1
                        if progress is not None and k % report_every == 0:
                            progress("execute", k, total)
            # hold the last target while the arm, lagging its targets, arrives; then the controlled stop
            n_settle = int(self.settle * rate)
            hold = shaper.hold(n_settle) if q_last is not None else np.zeros((0, 6))
            for j in range(n_settle + 10):
                with core.lock:
                    if j < len(hold):
                        m.servo(hold[j], dt, self.lookahead, self.gain)
                    elif j == n_settle:
                        stations.flush()
                        m.plan_stop(self.deceleration, linear=True)
                self._tick(ticks)
                rec.sample(core, t_last + (j + 1) * dt)
                stations.reached(rec.last_x, k)
            while m.busy:  # the rest of the controlled stop, if any
                self._tick()
            if progress is not None:
                progress("execute", total, total)
        except DriverError as exc:
            failure = self._locate(exc, k, planned, rec)
            self._halt(failure, mask)
        return rec, failure

    def _program(self, job, planned, mask, progress, cancel):
        from planner.export import job_program

        core = self._need()
        text = job_program(job)
        rec = _Recorder(new_recording(job, planned, tolerance=self.path_tolerance), self.record)
        failure = None
        k = 0
        try:
            with core.lock:
                started = core.load_program(text)
            if not started:
                reason = next((msg for _, src, msg in reversed(core.log) if src == "Program"), "program refused")
                raise ProgramError(f"the controller refused the job's program: {reason}")
            t0 = core.time
            every = max(1, int(0.1 / DT))
            n = 0
            while True:
                err = self._stopped(cancel)
                if err is not None:
                    raise err
                self._tick()
                n += 1
                rec.sample(core, core.time - t0)
                f = self._fault()
                if f is not None:
                    raise f
                if core.runtime_state == RUNTIME_STOPPED:
                    break
                if progress is not None and n % every == 0 and planned.n:
                    rec.rec.reduce_pending()  # the planned segment nearest the last sample: where the run is
                    k = max(k, rec.rec.last_segment)
                    progress("execute", k, planned.n)
            # the program ended: at the job's end, or halted by a runtime error
            halted = next((msg for _, src, msg in reversed(core.log) if src == "Program"), "")
            d = float(np.linalg.norm(rec.last_x[:3] - planned.last_pose[:3])) if planned.n else 0.0
            if halted.startswith("Runtime error") or d > 1e-3:
                if planned.n:
                    rec.rec.reduce_pending()
                    k = rec.rec.last_segment
                raise ProgramError((halted or "the program ended early") + f"; the tool is {1e3 * d:.1f} mm from "
                                   "the job's last pose")
            k = planned.n - 1
            if progress is not None:
                progress("execute", planned.n, planned.n)
        except DriverError as exc:
            if rec.n and planned.n and not isinstance(exc, ProgramError):
                rec.rec.reduce_pending()
                k = rec.rec.last_segment
            failure = self._locate(exc, k, planned, rec)
            self._halt(failure, mask)
        with core.lock:
            if core.runtime_state == RUNTIME_PAUSED:
                core.stop_program()
        return rec, failure
