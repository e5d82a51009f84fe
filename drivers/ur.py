"""Execute planned jobs on Universal Robots e-Series controllers through ur_rtde.

Two modes, one report (:func:`drivers.report.execution_report`):

- "stream": ``servoJ`` with the planner's own joints (the branch the planner chose and tracked, so the
  controller never picks another) at the job's rate, shaped by the assumed servo model so that the arm runs on them
  (:mod:`drivers.servo`; lookahead 0.03 s, gain 2000 by default), one target per control period on an absolute
  schedule (:class:`drivers.pacing.Schedule`, the loop SCHED_FIFO where the system allows it), after a joint move
  onto ``job.start_joints`` (the safe approach), and
  ending with ``servoStop`` (a controlled stop). The job's digital outputs switch at the samples where the
  trajectory's I/O bits change (RTDE I/O interface, or Modbus with ``io="modbus"``). Stream mode depends on this
  machine's scheduling: see "A stream that misses periods" below.
- "program": the job's URScript program (:func:`planner.export.job_program`) sent to the script port
  (30002); the driver watches it run (RTDE runtime state; progress by the planned sample nearest the actual TCP).
  A program larger than ``max_program_bytes`` (default :data:`planner.export.job_script.MAX_PROGRAM_BYTES`, what a
  controller is known to take) is sent as consecutive programs under it
  (:func:`planner.export.job_script.job_program_pieces`), each cut between two moves where the arm is at rest (never
  in a cut; where the outputs are off unless a run of passes joined at corners needs two programs, then at a
  corner, the output kept on), each sent once the one before has ended at its last pose; the report says how many
  and the waits at the seams.

In both modes the actual TCP, joints and digital outputs of every data package are recorded, whole, through a
recording connection of its own (:class:`drivers.package_log.PackageLog`: a polled reading mixes packages and
misses those between polls; in stream mode one reading per control period missed a package whenever the loop's
phase drifted against the controller's, some 20 in a minute); the streaming loop still reads
``RTDEReceiveInterface`` each period for its checks (faults, runtime state, the outputs' stations). Every
failure is a :class:`drivers.base.DriverError` subclass with the robot's reason and the job's time, planned
pose and source line; the driver never retries a motion by itself. The driver connects only to the host it is
given. Program mode is the default (:data:`drivers.base.DEFAULT_MODE`).

A stream that misses periods
----------------------------
When the streaming loop starts a period late (a loaded machine did not run it in time), the controller holds the
arm on the last target it was sent, a point of the planned path, for the periods missed; the loop then goes on with
the next target, so that the rest of the job runs that many periods later. No target is skipped: catching up (the
target due now instead of the next one) would be a jump along the path within one period, which the controller's
servo turns into more than the joint acceleration limit (a protective stop) after a stall of a few periods at a
usual feed, and a cut across a bend. The outputs stay as they are meanwhile. So any number of short stalls delays
the job (the report counts the missed periods, the longest period and where each was) and leaves the path only by
the servo's settling when the arm stops and starts again (the report's deviations name "missed control periods").

The run stops (``servoStop``: a controlled stop on the path, the outputs off) with :class:`PeriodOverrunError`, its
reason naming the stall, only when a single stall lasts longer than ``overrun_limit`` (default 1 s, 500 periods at
500 Hz: the machine cannot stream the job; program mode can run it), or, with ``path_tolerance`` and
``fail_on_deviation``, with :class:`drivers.report.PathDeviationError` as soon as the tracked TCP is further from the
path than the tolerance (checked every 0.2 s while the stream runs, not after the job has ended).
"""

from __future__ import annotations

import gc
import os
import socket
import sys
import threading
import time
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers.base import (
    DEFAULT_MODE,
    MODES,
    ConnectionLostError,
    DriverError,
    EmergencyStopError,
    NotReadyError,
    PeriodOverrunError,
    ProtectiveStopError,
    RobotState,
)
from drivers.feed import TargetFeed
from drivers.jobs import check_job, stop_requested
from drivers.pacing import Schedule
from drivers.package_log import PackageLog
from drivers.plan_window import PlannedPath, PlanWindow
from drivers.report import (
    ExecutionReport,
    Seam,
    check_tolerance,
    deviation_failure,
    execution_report,
    new_recording,
)
from drivers.servo import DEFAULT_GAIN, DEFAULT_LOOKAHEAD, ServoModel, ServoShaper, check_servo
from drivers.stations import Station, Stations
from planner.export.job_script import MAX_PROGRAM_BYTES
from planner.kinematics.ur_outputs import UR_OUTPUTS
from planner.wording import counted

if TYPE_CHECKING:  # pragma: no cover
    from drivers.modbus_io import ModbusToolIO

#: RTDE safety_status_bits: protective stop (bit 2), robot / system emergency stop (bits 7, 8), safeguard (3).
_BIT_PROTECTIVE = 1 << 2
_BITS_EMERGENCY = (1 << 7) | (1 << 8)
#: RTDE runtime_state: 2 PLAYING, 4 PAUSED (1 STOPPED).
_PLAYING, _PAUSED = 2, 4
_ROBOT_MODES = {-1: "NO_CONTROLLER", 0: "DISCONNECTED", 1: "CONFIRM_SAFETY", 2: "BOOTING", 3: "POWER_OFF",
                4: "POWER_ON", 5: "IDLE", 6: "BACKDRIVE", 7: "RUNNING", 8: "UPDATING_FIRMWARE"}
_SAFETY_MODES = {1: "NORMAL", 2: "REDUCED", 3: "PROTECTIVE_STOP", 4: "RECOVERY", 5: "SAFEGUARD_STOP",
                 6: "SYSTEM_EMERGENCY_STOP", 7: "ROBOT_EMERGENCY_STOP", 8: "VIOLATION", 9: "FAULT",
                 10: "VALIDATE_JOINT_ID", 11: "UNDEFINED_SAFETY_MODE", 12: "AUTOMATIC_MODE_SAFEGUARD_STOP",
                 13: "SYSTEM_THREE_POSITION_ENABLING_STOP"}
#: The streaming loop takes the recorded packages into its recording (reduced at once) after this many periods, in
#: a period with this much time left, s.
_RT_BLOCK, _RT_SPARE = 100, 1.2e-3
#: Program mode reads the packages recorded so far (and reports progress) this often, s of wall time.
_READ_EVERY = 0.05
#: SCHED_FIFO priority of the streaming loop (``realtime``): below a controller simulated on the same machine
#: (its control loop runs at 10, its RTDE server at 8).
LOOP_PRIORITY = 5
#: The longest stall of the streaming loop a stream rides out (the arm holding its last target meanwhile), s: a longer
#: one stops the run (PeriodOverrunError). A shared virtual machine under load stalls a thread for tens to a few
#: hundred ms now and then (214 ms failed a service's stream at 98.5 % under the former 0.2 s limit).
OVERRUN_LIMIT = 1.0
#: Missed periods of a stream remembered (the job time of each: the causes of path deviations and of late switches).
MAX_STALLS = 10_000
#: ur_rtde interfaces whose connection dropped: never disconnected or destroyed (see URDriver.close).
_ABANDONED: list = []


def _realtime_loop() -> tuple | None:
    """The calling thread SCHED_FIFO at LOOP_PRIORITY if the system allows it; its former (policy, priority), or
    None when refused."""
    try:
        before = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(LOOP_PRIORITY))
    except (OSError, AttributeError):
        return None
    return before


def _restore_scheduling(before: tuple) -> None:
    try:
        os.sched_setscheduler(0, before[0], os.sched_param(before[1]))
    except (OSError, AttributeError):
        pass


class ProgramStoppedError(DriverError):
    """The program on the robot stopped before the job ended (a stop from the dashboard or the pendant)."""

    kind = "program stopped"


class RTDEOutputs:
    """Digital outputs through ur_rtde's ``RTDEIOInterface``: ``set_bits(mask, value)`` on the 18-bit word
    (standard 0-7, configurable 8-15, tool 16-17), as :class:`drivers.modbus_io.ModbusToolIO` offers."""

    def __init__(self, host: str) -> None:
        import rtde_io

        self.io = rtde_io.RTDEIOInterface(host)

    def set_bits(self, mask: int, value: int) -> None:
        for kind in UR_OUTPUTS.values():  # in the order of their bits
            for pin in range(kind.pins):
                b = kind.bit(pin)
                if not (mask >> b) & 1:
                    continue
                ok = getattr(self.io, kind.rtde_io_method)(pin, bool((value >> b) & 1))
                if ok is False:
                    raise ConnectionLostError(f"the RTDE I/O interface refused to set output bit {b}")

    def close(self) -> None:
        try:
            self.io.disconnect()
        except RuntimeError:
            pass


class URDriver:
    """A UR e-Series robot at ``host`` through ur_rtde (see the module doc).

    Parameters
    ----------
    host : str
        The controller's address (the only host the driver talks to).
    model : str
        UR model the jobs are planned for (checked against ``job.settings.robot``).
    io : "rtde" or "modbus"
        How the job's digital outputs are switched.
    modbus_port : int
        Modbus TCP port of the controller (with ``io="modbus"``).
    lookahead, gain : float
        servoJ lookahead time (s, 0.03..0.2; default 0.03) and proportional gain (100..2000; default 2000): the
        shortest time constants UR allows (see :mod:`drivers.servo`).
    compensate : bool
        Send servo targets shaped by the assumed servo model so that the arm runs on the planned joints
        (:class:`drivers.servo.ServoShaper`; default); False: the planned joints as they are (the arm lags them and
        cuts bends by the servo's filtering).
    realtime : bool
        Run the streaming loop's thread SCHED_FIFO (priority :data:`LOOP_PRIORITY`) where the system allows it, as
        ur_rtde does on a real-time kernel (default): on a loaded machine an ordinary thread misses control periods
        (each one holds the arm on its last target; on a tight bend a stall of 20 ms or more puts the arm off the
        path). Its usual scheduling is restored after the run.
    path_tolerance : float, optional
        Path tolerance, m: the report lists every stretch where the tracked TCP was further than this from the
        planned path, with where (job time, source line) and why (servo lag, missed control periods, a stop).
    max_program_bytes : int or None
        Program mode: the largest program sent to the controller, bytes (default :data:`MAX_PROGRAM_BYTES`); a
        longer job is sent as consecutive programs under it. None: one program whatever its size.
    fail_on_deviation : bool
        A run beyond ``path_tolerance`` fails (``report.ok`` False, :class:`drivers.report.PathDeviationError` at
        its largest deviation); otherwise it is only reported.
    overrun_limit : float
        Stream: two targets this many seconds apart stop the run with PeriodOverrunError, s (default
        :data:`OVERRUN_LIMIT`). The arm holds its last (planned, on the path) target meanwhile, so a shorter stall
        delays the job without leaving the path (see the module doc).
    settle : float
        Seconds of recording after the last target (the arm's lag behind the servo targets).
    deceleration : float
        servoStop deceleration, rad/s^2.
    approach_speed, approach_acceleration : float
        The joint move onto the job's start joints before a run (:meth:`move_to_start`), rad/s, rad/s^2.
    frequency : float
        The controller's control rate, Hz (500 e-Series, 125 CB-Series): a job is streamed at its planned rate,
        which must be this.
    samples : callable or None
        Called with each batch of the run's recorded samples as they are taken (job time (n,) s, actual TCP poses
        (n, 6), actual joints (n, 6) rad, output bits (n,)): a live view's feed. It must return at once (the
        streaming loop calls it).
    """

    def __init__(self, host: str, model: str = "ur5e", *, io: str = "rtde", modbus_port: int = 502,
                 lookahead: float = DEFAULT_LOOKAHEAD, gain: float = DEFAULT_GAIN, compensate: bool = True,
                 realtime: bool = True, path_tolerance: float | None = None, fail_on_deviation: bool = False,
                 max_program_bytes: int | None = MAX_PROGRAM_BYTES, overrun_limit: float = OVERRUN_LIMIT,
                 settle: float = 0.3, deceleration: float = 10.0, frequency: float = 500.0, approach_speed: float = 0.5,
                 approach_acceleration: float = 0.5, samples=None) -> None:
        if not isinstance(host, str) or not host.strip():
            raise ValueError(f"host must be the controller's address, got {host!r}")
        if io not in ("rtde", "modbus"):
            raise ValueError(f"io must be 'rtde' or 'modbus', got {io!r}")
        lookahead, gain = check_servo(lookahead, gain)
        if not float(overrun_limit) > 0:
            raise ValueError(f"overrun_limit must be > 0 s, got {overrun_limit!r}")
        from planner.kinematics import get_model

        self.host = host.strip()
        self.model = get_model(model).name
        self.io_kind = io
        self.modbus_port = int(modbus_port)
        self.lookahead = float(lookahead)
        self.gain = float(gain)
        self.compensate = bool(compensate)
        self.realtime = bool(realtime)
        self.path_tolerance = check_tolerance(path_tolerance)
        if fail_on_deviation and self.path_tolerance is None:
            raise ValueError("fail_on_deviation needs a path_tolerance")
        self.fail_on_deviation = bool(fail_on_deviation)
        if max_program_bytes is not None and not (isinstance(max_program_bytes, int) and max_program_bytes >= 4096):
            raise ValueError(f"max_program_bytes must be at least 4096 bytes or None, got {max_program_bytes!r}")
        self.max_program_bytes = max_program_bytes
        self._seams: list[Seam] = []  # the last program run's seams between its programs
        self._pieces = 0
        self._stalls: list[float] = []  # job times at which the last stream's loop missed periods, one per period
        self.overrun_limit = float(overrun_limit)
        self.settle = float(settle)
        self.deceleration = float(deceleration)
        self.frequency = float(frequency)
        if not (0 < float(approach_speed) <= 3.14 and 0 < float(approach_acceleration) <= 40.0):
            raise ValueError("approach_speed must be within (0, 3.14] rad/s and approach_acceleration within "
                             f"(0, 40] rad/s^2, got {approach_speed!r}, {approach_acceleration!r}")
        self.approach_speed = float(approach_speed)
        self.approach_acceleration = float(approach_acceleration)
        #: Told of the run's recorded samples as they are taken (:attr:`drivers.recording.Recording.listener`)
        self.samples = samples
        # ur_rtde's interfaces (no type information: Any), None when not connected
        self._r: Any | None = None  # rtde_receive.RTDEReceiveInterface
        self._c: Any | None = None  # rtde_control.RTDEControlInterface
        self._dash: Any | None = None  # dashboard_client.DashboardClient
        self._io: RTDEOutputs | ModbusToolIO | None = None
        self._paused = threading.Event()
        self._stop = threading.Event()
        self._mode: str | None = None
        self._lost = False  # the connection dropped: the ur_rtde interfaces are abandoned on close
        #: The streaming loop's last reading of the receive interface (see _read): what state() returns while the
        #: loop runs, so that no other thread uses ur_rtde meanwhile.
        self._snap: tuple | None = None

    # ---- connection ---------------------------------------------------------------------------------
    def connect(self) -> None:
        """Connect the receive interface, check the robot is ready (powered, brakes released, no stop, in
        remote control), then the control and I/O interfaces. NotReadyError / ConnectionLostError / ..."""
        import dashboard_client
        import rtde_receive

        try:
            self._r = rtde_receive.RTDEReceiveInterface(self.host)
        except RuntimeError as exc:
            raise ConnectionLostError(f"cannot connect to the controller at {self.host} (RTDE): {exc}") from exc
        try:
            dash = self._dash = dashboard_client.DashboardClient(self.host)
            dash.connect()
            remote = dash.isInRemoteControl()
        except RuntimeError as exc:
            self.close()
            raise ConnectionLostError(f"cannot connect to the dashboard server at {self.host}: {exc}") from exc
        if not remote:
            self.close()
            raise NotReadyError("the robot is not in remote control (switch it to remote control on the pendant)")
        try:
            self._check_state()
        except DriverError:
            self.close()
            raise
        self._connect_control()
        try:
            if self.io_kind == "modbus":
                from drivers.modbus_io import ModbusToolIO

                mio = ModbusToolIO(self.host, self.modbus_port)
                self._io = mio
                mio.connect()
            else:
                self._io = RTDEOutputs(self.host)
        except (RuntimeError, OSError) as exc:
            self.close()
            if isinstance(exc, DriverError):
                raise
            raise ConnectionLostError(f"cannot connect the {self.io_kind} I/O at {self.host}: {exc}") from exc

    def _connect_control(self) -> None:
        import rtde_control

        try:
            self._c = rtde_control.RTDEControlInterface(self.host, self.frequency)
        except RuntimeError as exc:
            self.close()
            raise NotReadyError(f"the controller at {self.host} refused the control connection: {exc}") from exc

    def close(self) -> None:
        """Disconnect every interface (the arm is left as it is: stopped after a run)."""
        for name in ("_c", "_io", "_r"):
            obj = getattr(self, name)
            setattr(self, name, None)
            if obj is None:
                continue
            if self._lost or (name in ("_c", "_r") and not obj.isConnected()):
                # a dropped ur_rtde interface reconnects (and may abort the process on a broken pipe) when
                # disconnected or destroyed: it is kept, never touched again
                _ABANDONED.append(obj)
                continue
            try:
                if name == "_c":
                    obj.stopScript()
                if hasattr(obj, "disconnect"):
                    obj.disconnect()
                else:
                    obj.close()
            except (RuntimeError, OSError):
                pass
        self._lost = False
        if self._dash is not None:
            try:
                self._dash.disconnect()
            except RuntimeError:
                pass
            self._dash = None

    def __enter__(self) -> URDriver:
        self.connect()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _need(self) -> Any:
        """The receive interface (ConnectionLostError when not connected)."""
        if self._r is None:
            raise ConnectionLostError(f"not connected to {self.host}: call connect() first")
        return self._r

    def _control(self) -> Any:
        """The control interface (ConnectionLostError when not connected)."""
        if self._c is None:
            raise ConnectionLostError(f"no control connection to {self.host}: call connect() first")
        return self._c

    def _outputs(self) -> RTDEOutputs | ModbusToolIO:
        """The job's output interface (ConnectionLostError when not connected)."""
        if self._io is None:
            raise ConnectionLostError(f"no I/O connection to {self.host}: call connect() first")
        return self._io

    # ---- state ----------------------------------------------------------------------------------------
    def state(self) -> RobotState:
        """The robot's state. While a stream runs, the loop's own reading of this control period (at most one
        period old): another thread never calls into ur_rtde beside the real-time loop."""
        snap = self._snap
        if snap is not None and self._mode == "stream":
            _, x, q, bits, sbits, smode, rmode, runtime = snap
            return RobotState(joints=tuple(q), tcp_pose=tuple(x), robot_mode=int(rmode), safety_mode=int(smode),
                              runtime_state=int(runtime), protective_stop=bool(int(sbits) & _BIT_PROTECTIVE),
                              emergency_stop=bool(int(sbits) & _BITS_EMERGENCY),
                              program_running=int(runtime) == _PLAYING, digital_out=int(bits))
        r = self._need()
        try:
            bits = int(r.getSafetyStatusBits())
            runtime = int(r.getRuntimeState())
            return RobotState(
                joints=tuple(r.getActualQ()), tcp_pose=tuple(r.getActualTCPPose()), robot_mode=int(r.getRobotMode()),
                safety_mode=int(r.getSafetyMode()), runtime_state=runtime,
                protective_stop=bool(bits & _BIT_PROTECTIVE), emergency_stop=bool(bits & _BITS_EMERGENCY),
                program_running=runtime == _PLAYING, digital_out=int(r.getActualDigitalOutputBits()))
        except RuntimeError as exc:
            raise ConnectionLostError(f"lost the RTDE connection to {self.host}: {exc}") from exc

    def _fault(self) -> DriverError | None:
        """The robot's fault now, as an error without the job's place (None: none)."""
        r = self._r
        if r is None or not r.isConnected() or (self._c is not None and not self._c.isConnected()):
            return ConnectionLostError(f"the RTDE connection to {self.host} dropped")
        return self._fault_of(r.getSafetyStatusBits(), r.getSafetyMode(), r.getRobotMode())

    def _fault_of(self, bits: int, safety: int, mode: int) -> DriverError | None:
        """The fault that safety status bits, safety mode and robot mode (RTDE) mean (None: none)."""
        bits, safety, mode = int(bits), int(safety), int(mode)
        if mode == 7 and safety == 1 and not bits & (_BIT_PROTECTIVE | _BITS_EMERGENCY):
            return None  # the usual case, decided at once
        name = _SAFETY_MODES.get(safety, str(safety))
        if bits & _BITS_EMERGENCY or safety in (6, 7):
            return EmergencyStopError(f"emergency stop (safety mode {name})")
        if bits & _BIT_PROTECTIVE or safety == 3:
            return ProtectiveStopError(f"protective stop (safety mode {name}, safety status bits {bits:#x})"
                                       f"{self._safety_text()}")
        if mode == 3:
            return NotReadyError("the robot is powered off (robot mode POWER_OFF)")
        if mode in (4, 5):
            return NotReadyError(f"the robot's brakes are locked (robot mode {_ROBOT_MODES[mode]})")
        if mode != 7:
            return NotReadyError(f"the robot is not running (robot mode {_ROBOT_MODES.get(mode, mode)})")
        if safety not in (1, 2):
            return NotReadyError(f"the robot is stopped by its safety system (safety mode {name})")
        return None

    def _safety_text(self) -> str:
        try:
            return f"; dashboard: {self._dash.safetystatus()}" if self._dash is not None else ""
        except RuntimeError:
            return ""

    def _check_state(self) -> None:
        err = self._fault()
        if err is not None:
            raise err

    # ---- motions ------------------------------------------------------------------------------------
    def move_to_start(self, job, *, speed: float = 0.5, acceleration: float = 0.5,
                      cancel: threading.Event | None = None) -> None:
        """A joint move (rad/s, rad/s^2) onto ``job.start_joints``: the arm configuration the planner chose.

        The move runs asynchronously on the controller and is watched every 4 ms: ``cancel`` set, or
        :meth:`stop` called, stops it (``stopJ`` at ``acceleration`` x 4) and raises CancelledError."""
        self._check_job(job)
        r = self._need()
        self._check_state()
        if self._c is None or not self._c.isProgramRunning():
            if self._c is not None:
                self._c.reuploadScript()
            else:
                self._connect_control()
        q0 = [float(x) for x in job.start_joints]
        c = self._control()
        try:
            ok = c.moveJ(q0, float(speed), float(acceleration), True)  # asynchronous: watched below
            while ok and c.getAsyncOperationProgress() >= 0:
                stopped = stop_requested(cancel, self._stop)
                if stopped is not None:
                    c.stopJ(4.0 * float(acceleration))
                    end = time.monotonic() + 2.0  # the arm at rest before the caller hears of it
                    while time.monotonic() < end and np.abs(r.getActualQd()).max() > 1e-4:
                        time.sleep(0.004)
                    raise type(stopped)(f"move to the start: {stopped.reason}", t=0.0)
                if self._fault() is not None:
                    break
                time.sleep(0.004)
        except DriverError:
            raise
        except RuntimeError as exc:  # ur_rtde's own errors: the connection
            raise ConnectionLostError(f"the move to the start failed: {exc}") from exc
        err = self._fault()
        if not ok or err is not None:
            err = err or DriverError("the controller did not complete the move to the start joints")
            raise type(err)(f"move to the start: {err.reason}", t=0.0, pose=self._first_pose(job),
                            line=self._first_line(job))
        # the control interface's "done" and the receive interface's data come over two connections: the joints
        # read may be a package or two older than the end of the move (more so in fast-forward)
        end = time.monotonic() + 0.5
        q = np.asarray(r.getActualQ())
        while np.abs(q - q0).max() > 1e-3 and time.monotonic() < end:
            time.sleep(0.004)
            q = np.asarray(r.getActualQ())
        if np.abs(q - q0).max() > 1e-3:
            raise DriverError(f"the move to the start ended {np.abs(q - q0).max():.4f} rad from the start joints",
                              t=0.0, pose=self._first_pose(job))

    @staticmethod
    def _first_pose(job):
        for c in job.trajectory().chunks(joints=False):
            if len(c):
                return c.poses[0]
        return None

    @staticmethod
    def _first_line(job):
        return int(job.moves[0].line) if job.moves else None

    def _check_job(self, job) -> None:
        check_job(job, self.model)
        if abs(float(job.settings.rate) - self.frequency) > 1e-9:
            raise DriverError(f"the job was planned at {job.settings.rate:g} Hz, the controller runs at "
                              f"{self.frequency:g} Hz: plan it with rate={self.frequency:g}")

    def pause(self) -> None:
        """Hold the arm on the path (stream: the target stops advancing; program: dashboard pause)."""
        self._paused.set()
        if self._mode == "program" and self._dash is not None:
            self._dash.pause()

    def resume(self) -> None:
        """Continue after :meth:`pause`."""
        self._paused.clear()
        if self._mode == "program" and self._dash is not None:
            self._dash.play()

    def stop(self) -> None:
        """End the run now with a controlled stop; its report says CancelledError (stopped by the caller)."""
        self._stop.set()

    # ---- execution --------------------------------------------------------------------------------------
    def execute(self, job, *, mode: str = DEFAULT_MODE, progress=None,
                cancel: threading.Event | None = None) -> ExecutionReport:
        """Execute ``job`` (see the module doc) and return its report (``report.failure`` on failure).

        DriverError is raised when the run cannot start (not connected, wrong job, robot not ready) or the
        approach onto the start joints fails (the arm is stopped then); from the job's first target on, every
        failure ends the run with the arm stopped and the job's outputs off, and is returned in the report."""
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        self._check_job(job)
        self._need()
        self._check_state()
        self._stop.clear()
        self._paused.clear()
        self._seams, self._pieces = [], 0
        cancel = cancel if cancel is not None else threading.Event()
        planned = PlannedPath(job)  # read once, kept in summary (bounded memory); the run reads it again in windows
        # stream: the targets are produced ahead by a thread of their own while the arm approaches the start
        feed = None
        pieces = self.program_pieces(job) if mode == "program" else ()
        if mode == "stream":
            shaper = ServoShaper(ServoModel(self.lookahead, self.gain, 1.0 / float(job.settings.rate)),
                                 job.start_joints, compensate=self.compensate)
            feed = TargetFeed(job.trajectory(job.settings.rate), shaper=shaper)
        try:
            self.move_to_start(job, speed=self.approach_speed, acceleration=self.approach_acceleration, cancel=cancel)
            mask = planned.mask
            if mask:
                self._outputs().set_bits(mask, 0)
            self._mode = mode
            try:
                if mode == "stream":
                    rec, failure, loop = self._stream(job, planned, mask, progress, cancel, feed)
                else:
                    (rec, failure), loop = self._program(job, planned, mask, progress, cancel, pieces), None
            finally:
                self._mode = None
                self._snap = None
        finally:
            if feed is not None:
                feed.close()
        cause = self._lag_cause(mode)
        program = mode == "program"
        return execution_report(job, rec, mode=mode, failure=failure, planned=planned, loop=loop,
                                recording="every data package", stalls=self._stalls if mode == "stream" else (),
                                lag_cause=cause, fail_on_deviation=self.fail_on_deviation,
                                programs=self._pieces if program else 0,
                                program_bytes=(self.max_program_bytes or 0) if program else 0,
                                seams=self._seams if program else ())

    def _stopped(self, cancel) -> DriverError | None:
        return stop_requested(cancel, self._stop)

    def _lag_cause(self, mode: str) -> str:
        """What puts the arm behind the plan in ``mode`` (the cause of a deviation without a stall or a stop)."""
        if mode == "stream":
            return (f"servo lag (servoJ lookahead {self.lookahead:g} s, gain {self.gain:g}, "
                    + ("targets shaped by the servo model)" if self.compensate else "planned joints unshaped)"))
        return "the controller's blending of the program's moves (movep)"

    def _safe_off(self, mask: int) -> None:
        """Switch the job's outputs off after a failure (best effort: the connection may be gone), and wait until
        the controller reports them off."""
        if mask and self._io is not None and not (self._lost and isinstance(self._io, RTDEOutputs)):
            try:
                self._io.set_bits(mask, 0)
            except (RuntimeError, OSError):
                return
            self._confirm_outputs(mask, 0)

    def _confirm_outputs(self, mask: int, value: int, timeout: float = 1.0) -> bool:
        """Wait (at most ``timeout`` s) until the controller's actual output bits under ``mask`` read ``value``:
        an output command is a message, applied and reported back a control period or two later. True if so."""
        r = self._r
        if not mask or r is None or self._lost:
            return True
        end = time.monotonic() + timeout
        try:
            while (int(r.getActualDigitalOutputBits()) & mask) != (value & mask):
                if time.monotonic() > end or not r.isConnected():
                    return False
                time.sleep(0.002)
        except RuntimeError:
            return False
        return True

    def _read(self) -> tuple:
        """One period's reading of the receive interface: (timestamp, tcp pose, joints, output bits, safety status
        bits, safety mode, robot mode, runtime state), all of one data package (read again when the timestamp
        changed meanwhile: a package arrived between the calls). Kept as the run's snapshot for :meth:`state`."""
        r = self._need()
        for _ in range(3):
            ts = r.getTimestamp()
            snap = (ts, r.getActualTCPPose(), r.getActualQ(), r.getActualDigitalOutputBits(),
                    r.getSafetyStatusBits(), r.getSafetyMode(), r.getRobotMode(), r.getRuntimeState())
            if r.getTimestamp() == ts:
                break
        self._snap = snap
        return snap

    def _stream(self, job, planned, mask, progress, cancel, feed):
        c, r = self._control(), self._need()
        total = planned.n
        rate = float(job.settings.rate)
        dt = 1.0 / rate
        la, gain = self.lookahead, self.gain
        # every data package, from the recording connection, reduced as it goes (bounded memory), in periods with time
        # to spare, ~100 packages at a time (~0.5 ms; 2500 at a time took 10-15 ms, several missed periods every 5 s);
        # the plan's pieces it is compared with are made ahead by a thread
        rec = new_recording(job, planned, prefetch=True, tolerance=self.path_tolerance)
        rec.listener = self.samples
        stalls = self._stalls = []
        missed_seen = 0
        t_cmd = 0.0
        log = None
        untaken = 0  # periods since the packages were last taken into the recording
        if isinstance(rec.planned, PlanWindow):
            rec.planned.prime()  # its first pieces made before the first period
        failure = None
        prev_io = 0
        stations = Stations(self._outputs().set_bits)  # switches whose station the actual TCP has not reached yet
        k = 0  # sample being commanded (job-wide)
        ts0 = None
        q_last = None
        report_every = max(1, int(rate // 10))
        host = self.host
        overrun = self.overrun_limit
        sched = Schedule(dt)
        switch = sys.getswitchinterval()
        # the target feed's thread computes ahead: a short switch interval hands the GIL back to this loop within
        # 0.2 ms of its deadline (the default 5 ms would be two and a half control periods)
        sys.setswitchinterval(2e-4)
        # no cyclic garbage collection during the stream: a full collection walks every object of the process (tens
        # of ms, more on a loaded machine) and the loop's objects are freed by reference counting anyway
        gc_enabled = gc.isenabled()
        gc.disable()
        gc.freeze()
        policy = _realtime_loop() if self.realtime else None
        try:
            # outputs that switch at the job's first sample: switched (and confirmed) before the first target, the
            # arm at rest on their station (the I/O path's latency, 2-12 ms on a loaded machine, would otherwise
            # make them late)
            for b, v, i in planned.switches:
                if i == 0:
                    prev_io = (prev_io & ~(1 << b)) | (int(v) << b)
            if prev_io:
                self._outputs().set_bits(prev_io, prev_io)
                self._confirm_outputs(prev_io, prev_io)
            log = PackageLog(self.host, self.frequency)
            last = sched.start()
            for sl in feed:
                qs, ios, times, pos, h0 = sl.q, sl.io, sl.t, sl.positions, sl.history
                i = 0
                n = len(times)
                while i < n:
                    err = self._stopped(cancel)
                    if err is not None:
                        raise err
                    paused = self._paused.is_set()
                    q = qs[i]
                    if not (r.isConnected() and c.isConnected()):  # before servoJ: ur_rtde would reconnect by itself
                        raise ConnectionLostError(f"the connection to the controller at {host} dropped")
                    if not c.servoJ(q, 0.0, 0.0, dt, la, gain):
                        raise self._fault() or ProgramStoppedError(self._not_running_reason())
                    t_cmd = times[i]
                    if ios[i] != prev_io and not paused:
                        stations.add(Station.on_path(k, ios[i] ^ prev_io, ios[i], pos, h0 + i, rate=rate))
                        prev_io = ios[i]
                    ts, x, _, _, sbits, smode, rmode, runtime = self._read()
                    if ts0 is None:
                        ts0 = ts - times[i]  # the controller's clock, 0 at the job's start
                    if stations:
                        stations.reached(x, k)
                    f = self._fault_of(sbits, smode, rmode)
                    if f is not None:
                        raise f
                    if runtime != _PLAYING:
                        raise ProgramStoppedError(self._not_running_reason())
                    if not paused:
                        q_last = q
                        i += 1
                        k += 1
                        if progress is not None and k % report_every == 0:
                            progress("execute", k, total)
                    untaken += 1
                    if untaken >= _RT_BLOCK and sched.time_left() > _RT_SPARE:
                        self._take(log, rec, ts0)
                        untaken = 0
                        off = deviation_failure(rec, planned, stalls, self._lag_cause("stream")) if (
                            self.fail_on_deviation and rec.excursion_count) else None
                        if off is not None:  # off the path now: stopped here, not after the job
                            raise off
                    now = sched.wait()
                    if sched.missed != missed_seen:  # one entry per period missed (each delays the rest by one)
                        stalls.extend([t_cmd] * min(sched.missed - missed_seen, MAX_STALLS - len(stalls)))
                        missed_seen = sched.missed
                    if now - last > overrun:  # the arm held its last target meanwhile: stopped there
                        missed_all = counted(sched.missed, "period")
                        raise PeriodOverrunError(
                            f"the control loop stalled for {1e3 * (now - last):.0f} ms between two targets (the arm "
                            f"held the last one; the limit is {1e3 * overrun:.0f} ms, {missed_all} missed so far): "
                            "this machine is too loaded to stream the job; run it in program mode")
                    last = now
            # hold the last target until the arm, lagging its targets, has arrived; then a controlled stop
            n_settle = int(self.settle * rate)
            hold = feed.hold(n_settle) if q_last is not None else []
            for j in range(n_settle + 10):
                if j < len(hold):
                    c.servoJ(hold[j], 0.0, 0.0, dt, la, gain)
                elif j == n_settle:
                    stations.flush()
                    c.servoStop(self.deceleration)
                x = self._read()[1]
                if stations:
                    stations.reached(x, k)
                sched.wait()
            if progress is not None:
                progress("execute", total, total)
        except DriverError as exc:
            failure = self._locate(exc, k, planned, rec)
        except RuntimeError as exc:  # ur_rtde: the socket closed
            failure = self._locate(ConnectionLostError(f"the connection to {host} dropped: {exc}"), k, planned, rec)
        finally:
            if policy is not None:
                _restore_scheduling(policy)
            sys.setswitchinterval(switch)
            gc.unfreeze()
            if gc_enabled:
                gc.enable()
        if log is not None:  # the packages up to the end (or the failure) into the recording
            try:
                if ts0 is not None:
                    self._take(log, rec, ts0)
            except (RuntimeError, OSError, DriverError):
                pass
            log.close()
        if isinstance(failure, ConnectionLostError):
            self._lost = True
        if failure is not None:
            self._halt(failure)
            self._safe_off(mask)
        else:
            self._confirm_outputs(mask, prev_io)
        return rec, failure, sched.stats()

    def _program_start(self, log: PackageLog, t_sent: float) -> float:
        """The controller's time at which the program sent at controller time ``t_sent`` started: the timestamp of
        the first data package after ``t_sent`` that shows the program playing (the job's time 0; the packages read
        here are given back to the log). Seeing the program start through ur_rtde's receive interface took this
        machine's poll 28-56 ms after the controller started it, and the recording began there: an output switched
        at the program's start was reported 0.2-0.8 mm from its station, where the arm had already accelerated to;
        the package's own runtime state has no such delay. Falls back to the receive interface's time if no package
        shows the program playing within 0.5 s (one that ended between two packages)."""
        rows = []
        end = time.monotonic() + 0.5
        while True:
            rows.append(log.read())
            got = np.concatenate(rows)
            playing = np.flatnonzero((got[:, 0] >= t_sent) & (got[:, 14] == _PLAYING))
            if playing.size or time.monotonic() > end:
                log.unread(got)
                return float(got[playing[0], 0]) if playing.size else self._need().getTimestamp()
            time.sleep(0.002)

    @staticmethod
    def _take(log: PackageLog, rec, ts0: float) -> int:
        """The packages recorded since the last call into ``rec`` (those of the run: from ``ts0`` on, job time
        0 there), reduced at once; the planned sample nearest the last one (where the run is)."""
        rows = log.read()
        rows = rows[rows[:, 0] >= ts0 - 1e-9]
        if rows.shape[0]:
            rec.extend(rows[:, 0] - ts0, rows[:, 1:7], rows[:, 7:13], rows[:, 13].astype(np.int64))
        return rec.last_segment

    def _last_place(self, log: PackageLog | None, rec, k: int, ts0: float | None) -> int:
        """Where a failed program run was: the planned sample nearest the last package recorded (``k`` when none)."""
        if log is None or ts0 is None:
            return k
        try:
            self._take(log, rec, ts0)
        except (RuntimeError, OSError, DriverError):
            return k
        return max(k, rec.last_segment) if rec.samples else k

    def _not_running_reason(self) -> str:
        state = self._need().getRuntimeState()
        return ("the program on the robot stopped (runtime state "
                f"{'STOPPED' if state == 1 else state}): "
                "a stop from the dashboard or the pendant")

    @staticmethod
    def _locate(err: DriverError, k: int, planned: PlannedPath, rec=None) -> DriverError:
        """``err`` at planned sample ``k``: its job time, planned pose and source line (from the recording's window
        of the plan when it holds the sample)."""
        if planned.n == 0 or err.t is not None:  # (an error placed already: a path deviation at its worst point)
            return err
        t, pose, line = planned.at(k, rec.planned if rec is not None else None)
        return err.located(t, pose, line)

    def _halt(self, failure: DriverError) -> None:
        """Bring the arm to rest after a failure (nothing to do when the connection or the program is gone)."""
        c, r = self._c, self._r
        if isinstance(failure, ConnectionLostError) or c is None or r is None:
            return
        try:
            if self._mode == "stream":
                c.servoStop(self.deceleration)
            elif r.getRuntimeState() in (_PLAYING, _PAUSED) and self._dash is not None:
                self._dash.stop()
        except RuntimeError:
            pass
        try:
            end = time.monotonic() + 2.0
            while time.monotonic() < end and np.abs(r.getActualQd()).max() > 1e-4:
                time.sleep(0.01)
        except RuntimeError:
            pass

    def _send_program(self, text: str) -> None:
        """One program to the secondary interface (30002), whole."""
        try:
            with socket.create_connection((self.host, 30002), timeout=2.0) as s:
                s.sendall(text.encode() if text.endswith("\n") else (text + "\n").encode())
        except OSError as exc:
            raise ConnectionLostError(f"cannot send the program to {self.host}:30002: {exc}") from exc

    def _started(self, piece, t_sent: float) -> None:
        """Wait (at most 5 s of wall time) until the controller runs the program just sent: PLAYING, or (a piece so
        short that it ended between two readings) stopped again, at the piece's end, with a newer data package."""
        r = self._need()
        end = time.monotonic() + 5.0
        while True:
            state = r.getRuntimeState()
            if state == _PLAYING:
                return
            f = self._fault()
            if f is not None:
                raise f
            if r.getTimestamp() > t_sent and state not in (_PLAYING, _PAUSED):
                x = np.asarray(r.getActualTCPPose(), dtype=float)
                if (np.linalg.norm(x[:3] - piece.end[:3]) < 1e-5 and
                        np.linalg.norm(piece.end[:3] - piece.start[:3]) > 1e-4):
                    return
            if time.monotonic() > end:
                raise ProgramStoppedError(f"the controller did not start the program ({piece.size} bytes) within "
                                          "5 s (refused)")
            time.sleep(0.002)

    def program_pieces(self, job) -> tuple:
        """The programs program mode sends for ``job`` (:func:`planner.export.job_script.job_program_pieces` under
        ``max_program_bytes``); DriverError when a pass alone needs a larger program (before the arm moves)."""
        from planner.export import job_program_pieces

        limit = self.max_program_bytes
        try:
            return job_program_pieces(job, max_bytes=limit if limit is not None else 2**62)
        except ValueError as exc:
            raise DriverError(f"program mode: {exc}") from None

    def _program(self, job, planned, mask, progress, cancel, pieces):
        r, c = self._need(), self._control()
        c.stopScript()  # hand the arm from ur_rtde's control script to the job's program
        end = time.monotonic() + 1.0  # and see it stopped: a PLAYING read after sending must be the job's program
        while r.getRuntimeState() == _PLAYING and time.monotonic() < end:
            time.sleep(0.002)
        rec = new_recording(job, planned, tolerance=self.path_tolerance)
        rec.listener = self.samples
        failure = None
        k = 0
        log = None
        ts0 = None
        seams = self._seams = []
        t_ended = 0.0  # controller time at which the last program ended
        try:
            # every data package from here on, through a connection of its own (a stalled loop misses none)
            log = PackageLog(self.host, self.frequency)
            for n, piece in enumerate(pieces):
                t_sent = r.getTimestamp()
                self._send_program(piece.text)
                self._started(piece, t_sent)
                if ts0 is None:
                    ts0 = self._program_start(log, t_sent)
                else:  # the seam: the arm at rest at the end of the piece before, from its end to this start
                    seams.append(Seam(n + 1, t_ended - ts0, max(0.0, r.getTimestamp() - t_ended), piece.line))
                last_read = time.monotonic()
                while True:
                    err = self._stopped(cancel)
                    if err is not None:
                        raise err
                    f = self._fault()
                    if f is not None:
                        raise f
                    state = r.getRuntimeState()
                    if time.monotonic() - last_read > _READ_EVERY:
                        last_read = time.monotonic()
                        k = max(k, self._take(log, rec, ts0))
                        if progress is not None:
                            progress("execute", k, planned.n)
                    if state not in (_PLAYING, _PAUSED):
                        break
                    time.sleep(0.002)
                # the program ended: at the piece's end, or stopped from outside
                t_ended = r.getTimestamp()
                x = np.asarray(r.getActualTCPPose(), dtype=float)
                d = float(np.linalg.norm(x[:3] - piece.end[:3]))
                if d > 1e-3:
                    time.sleep(0.01)
                    self._take(log, rec, float(ts0))
                    k = max(k, rec.last_segment)
                    where = ("the job's last pose" if n == len(pieces) - 1 else
                             f"the last pose of program {n + 1} of {len(pieces)}")
                    raise ProgramStoppedError(self._not_running_reason() + f"; the tool is {1e3 * d:.1f} mm "
                                              f"from {where}")
            time.sleep(0.01)
            if ts0 is not None:
                self._take(log, rec, ts0)
            k = planned.n - 1
            if progress is not None:
                progress("execute", planned.n, planned.n)
        except DriverError as exc:
            failure = self._locate(exc, self._last_place(log, rec, k, ts0), planned, rec)
        except RuntimeError as exc:
            failure = self._locate(ConnectionLostError(f"the connection to {self.host} dropped: {exc}"),
                                   self._last_place(log, rec, k, ts0), planned, rec)
        finally:
            if log is not None:
                log.close()
        self._pieces = len(pieces)
        if isinstance(failure, ConnectionLostError):
            self._lost = True
        if failure is not None:
            self._halt(failure)
            self._safe_off(mask)
        if not isinstance(failure, ConnectionLostError):
            try:
                c.reuploadScript()  # ur_rtde's control script back, for the next move
                end = time.monotonic() + 1.0  # and playing before the caller reads the state
                while r.getRuntimeState() != _PLAYING and time.monotonic() < end:
                    time.sleep(0.004)
            except RuntimeError:
                pass
        return rec, failure
