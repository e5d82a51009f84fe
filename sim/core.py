"""The simulated controller's state and its control period: modes, safety, programs, motion, registers.

One :class:`Core` per simulated controller. Its :meth:`Core.tick` advances simulated time by one
control period (2 ms): the running program's step, the motion model's integration, the watchdog, the
recorder. Every server thread (RTDE, dashboard, primary and script ports, Modbus) changes the core only while
holding :attr:`Core.lock`; the tick thread holds it for the whole tick, so a program always sees a
data package's inputs together.

Modes and bits follow the RTDE guide and ur_rtde 1.6.5 (include/ur_rtde/rtde_control_interface.h):
robot_mode 3 POWER_OFF, 5 IDLE, 7 RUNNING; safety_mode 1 NORMAL, 3 PROTECTIVE_STOP, 6
SYSTEM_EMERGENCY_STOP, 7 ROBOT_EMERGENCY_STOP; runtime_state 1 STOPPED, 2 PLAYING, 4 PAUSED;
robot_status_bits bit 0 power on, bit 1 program running; safety_status_bits bit 0 normal mode, bit 2
protective stopped, bit 5 system emergency stopped, bit 6 robot emergency stopped, bit 7 emergency
stopped, bit 10 stopped due to safety.

Faults: a protective stop (a motion beyond the limits, an unreachable target, ``protective_stop()``)
halts the arm, stops the program 0.1 s later and is cleared with the dashboard's ``unlock protective
stop`` no sooner than 5 s after it; an emergency stop (:meth:`Core.press_emergency_stop`) halts the arm,
stops the program and cuts the arm's power (robot mode POWER_OFF) until it is released and the arm
powered on and its brakes released again. In local control mode (:attr:`Core.remote_control` False, the
pendant's choice) the script ports refuse programs and the dashboard refuses what would start motion.
"""

from __future__ import annotations

import collections
import math
import re
import threading

import numpy as np

from planner.kinematics import forward_matrix
from planner.rotations import matrix_to_rotvec_1
from sim.control_script import ControlScript
from sim.motion import DT, GRAVITY, MotionModel, Segment
from sim.primary_packages import READ_ONLY_INTERFACE
from sim.programs import PathMove, ProgramError, head_of, parse_program
from sim.rtde_fields import Registers
from sim.urscript import URScriptProgram, compile_line, compile_program
from sim.versions import DEFAULT, REMOTE_CONTROL_SINCE, SoftwareVersion

ROBOT_POWER_OFF, ROBOT_IDLE, ROBOT_RUNNING = 3, 5, 7
SAFETY_NORMAL, SAFETY_PROTECTIVE_STOP = 1, 3
SAFETY_SYSTEM_EMERGENCY_STOP, SAFETY_ROBOT_EMERGENCY_STOP = 6, 7
EMERGENCY_STOPS = (SAFETY_SYSTEM_EMERGENCY_STOP, SAFETY_ROBOT_EMERGENCY_STOP)
RUNTIME_STOPPED, RUNTIME_PLAYING, RUNTIME_PAUSED = 1, 2, 4
JOINT_POWER_OFF, JOINT_RUNNING, JOINT_IDLE = 239, 253, 255
#: Seconds (simulated) after a protective stop before it may be unlocked, as on the controller.
UNLOCK_DELAY = 5.0
#: Simulated seconds between a protective stop (safety bits set, arm halted) and the program's end.
PROGRAM_STOP_DELAY = 0.1
MODE_NAMES = {3: "POWER_OFF", 5: "IDLE", 7: "RUNNING"}
SAFETY_NAMES = {1: "NORMAL", 3: "PROTECTIVE_STOP", 6: "SYSTEM_EMERGENCY_STOP", 7: "ROBOT_EMERGENCY_STOP"}
RUNTIME_NAMES = {1: "STOPPED", 2: "PLAYING", 4: "PAUSED"}


def _link3_origin(model, q: np.ndarray) -> np.ndarray:
    """``link_frames(model, q)[3][:3, 3]`` in closed form (UR's DH: alpha 90, 0, 0 degrees, d2 = d3 = a1 = 0)."""
    q1, q2, q3 = float(q[0]), float(q[1]), float(q[2])
    x = model.a2 * math.cos(q2) + model.a3 * math.cos(q2 + q3)  # in link 1's frame
    y = model.a2 * math.sin(q2) + model.a3 * math.sin(q2 + q3)
    return np.array([x * math.cos(q1), x * math.sin(q1), model.d1 + y])


def _line_of(text: str) -> int:
    """The program line a compile or runtime error names ("line N: ..."), 0 when it names none."""
    m = re.search(r"\bline (\d+)", text)
    return int(m.group(1)) if m else 0


class Core:
    """State of one simulated UR controller.

    Parameters
    ----------
    model : str
        UR model (``"ur5e"``, ...).
    io : sim.io_state.IOState
        The controller's I/O, shared with the Modbus server.
    recorder : sim.recording.Recorder, optional
        Receives every period's state and every safety / program event.
    version : sim.versions.SoftwareVersion
        The PolyScope release the controller reports and behaves as (its RTDE fields, dashboard commands).
    """

    def __init__(self, model: str, io, recorder=None, version: SoftwareVersion = DEFAULT) -> None:
        self.lock = threading.RLock()
        self.model_name = model
        self.version = version
        self.motion = MotionModel(model)
        self.registers = Registers()
        self.io = io
        self.recorder = recorder
        self.time = 0.0
        self.steps = 0
        self.robot_mode = ROBOT_RUNNING
        self.safety_mode = SAFETY_NORMAL
        self.remote_control = True  # the pendant's local / remote control switch
        self.runtime_state = RUNTIME_STOPPED
        self.program: ControlScript | URScriptProgram | None = None
        self.program_name = "<unnamed>"
        self.protective_stop_time = -1.0
        self.payload_mass = 0.0
        self.payload_cog = np.zeros(3)
        self.payload_inertia = np.zeros(6)
        self.execution_time_ms = 0.0
        self.late_ticks = 0  # control-loop ticks that ran late (the loop fell behind the wall clock), caught up
        self.packages_sent = 0  # RTDE data packages sent
        self.max_late_ms = 0.0  # largest wake-up delay of the control loop, ms
        self.log: collections.deque = collections.deque(maxlen=200)
        self.outbox: list[tuple[str, str, int]] = []  # text messages for RTDE clients
        # robot messages for the primary interface's clients: (sequence number, time, kind, fields), see event()
        self.events: collections.deque[tuple[int, float, str, dict]] = collections.deque(maxlen=500)
        self.event_seq = 0
        self.input_time: dict[str, float] = {}
        self.watchdog: tuple[str, float] | None = None
        self._history: collections.deque[np.ndarray] = collections.deque(maxlen=1000)
        # what was computed of the last joint vectors asked about, by identity (a joint vector is never changed in
        # place): [q, TCP transform, TCP pose, gravity in the tool frame] (:meth:`_frame`)
        self._frames: collections.deque[list] = collections.deque(maxlen=4)
        self._rates_of: tuple = ()  # the transforms the TCP speed and acceleration were computed from
        self._tcp_cache: tuple[int, np.ndarray, np.ndarray] | None = None
        self._elbow_cache: tuple[np.ndarray, np.ndarray] | None = None
        self._gravity_cache: tuple[int, np.ndarray] | None = None
        self._speed = np.zeros(6)
        self._accel = np.zeros(6)
        self._speed_step = -1
        self._program_stop_at: float | None = None

    # ---- reported state ----------------------------------------------------------------------
    @property
    def joint_mode(self) -> int:
        return JOINT_POWER_OFF if self.robot_mode == ROBOT_POWER_OFF else (
            JOINT_RUNNING if self.robot_mode == ROBOT_RUNNING else JOINT_IDLE)

    @property
    def robot_status_bits(self) -> int:
        return (1 if self.robot_mode != ROBOT_POWER_OFF else 0) | (2 if self.runtime_state == RUNTIME_PLAYING else 0)

    @property
    def safety_status_bits(self) -> int:
        if self.safety_mode == SAFETY_PROTECTIVE_STOP:
            return (1 << 2) | (1 << 10)
        if self.safety_mode == SAFETY_ROBOT_EMERGENCY_STOP:
            return (1 << 6) | (1 << 7) | (1 << 10)
        if self.safety_mode == SAFETY_SYSTEM_EMERGENCY_STOP:
            return (1 << 5) | (1 << 7) | (1 << 10)
        return 1

    @property
    def speed_scaling(self) -> float:
        return self.io.speed_slider if self.runtime_state == RUNTIME_PLAYING else 1.0

    def _tcp_offset(self) -> np.ndarray | None:
        tcp = self.motion.tcp
        return tcp if np.any(tcp) else None

    def _frame(self, q: np.ndarray) -> list:
        """[q, TCP transform (4, 4), TCP pose (6,) or None, tool-frame gravity (3,) or None] of joint vector ``q``
        (6,), remembered for the last few joint vectors: each period's transform is computed once for its pose and
        the speed over the last periods, and an arm at rest (the same joint vector period after period) computes
        nothing again."""
        for entry in self._frames:
            if entry[0] is q:
                return entry
        # one joint vector on Python floats: entry for entry the row of a batch (planner.kinematics.forward_matrix)
        entry = [q, forward_matrix(self.motion.model, q, self._tcp_offset()), None, None]
        self._frames.append(entry)
        return entry

    def _tcp(self) -> tuple[int, np.ndarray, np.ndarray]:
        """(period, TCP transform (4, 4), TCP pose (6,)) of the current joints, cached per period."""
        cache = self._tcp_cache
        if cache is None or cache[0] != self.steps:
            entry = self._frame(self.motion.q)
            T = entry[1]
            if entry[2] is None:
                # the pose from the transform's entries: what planner.kinematics.forward computes from them
                entry[2] = np.array([*T[:3, 3].tolist(), *matrix_to_rotvec_1(*T[:3, :3].ravel().tolist())])
            cache = (self.steps, T, entry[2])
            self._tcp_cache = cache
        return cache

    def tcp_pose(self) -> np.ndarray:
        """TCP pose p[x, y, z, rx, ry, rz] of the current joints (computed on demand, cached per period)."""
        return self._tcp()[2]

    def tcp_speed(self) -> np.ndarray:
        """TCP speed [v, omega] (base frame, m/s and rad/s) over the last period (computed on demand, cached
        per period)."""
        self._tcp_rates()
        return self._speed

    def tcp_acceleration(self) -> np.ndarray:
        """TCP acceleration [dv/dt, domega/dt] (base frame, m/s^2 and rad/s^2): the change of :meth:`tcp_speed`
        over the last period."""
        self._tcp_rates()
        return self._accel

    def _tcp_rates(self) -> None:
        if self._speed_step == self.steps:
            return
        self._speed_step = self.steps
        n = min(len(self._history), 3)
        if n < 2:
            self._speed, self._accel = np.zeros(6), np.zeros(6)
            return
        frames = tuple(self._frame(self._history[k])[1] for k in range(-n, 0))
        if len(frames) == len(self._rates_of) and all(a is b for a, b in zip(frames, self._rates_of, strict=True)):
            return  # the same transforms as last time (an arm at rest): the same speed and acceleration
        self._rates_of = frames
        # the transforms of the last n periods' joints, as one batch (n, 4, 4) would give them
        T = np.stack(frames)
        v = (T[1:, :3, 3] - T[:-1, :3, 3]) / DT
        W = (T[1:, :3, :3] - T[:-1, :3, :3]) @ T[1:, :3, :3].transpose(0, 2, 1) / DT  # skew(omega) per period
        speeds = np.column_stack([v, W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]])
        self._speed = speeds[-1]
        self._accel = (speeds[-1] - speeds[-2]) / DT if n == 3 else np.zeros(6)

    def tool_gravity(self) -> np.ndarray:
        """Gravity (m/s^2) in the tool frame, what a tool accelerometer at rest reads."""
        cache = self._gravity_cache
        if cache is None or cache[0] != self.steps:
            entry = self._frame(self.motion.q)
            if entry[3] is None:
                entry[3] = entry[1][:3, :3].T @ GRAVITY
            cache = (self.steps, entry[3])
            self._gravity_cache = cache
        return cache[1]

    def elbow_position(self) -> np.ndarray:
        """The elbow's position (m, base frame) of the current joints (computed on demand, cached per period: the
        real-time interface sends it every period)."""
        cache = self._elbow_cache
        if cache is None or cache[0] is not self.motion.q:
            cache = (self.motion.q, _link3_origin(self.motion.model, self.motion.q))
            self._elbow_cache = cache
        return cache[1]

    def tcp_changed(self) -> None:
        self._frames.clear()
        self._tcp_cache = None
        self._gravity_cache = None
        self._speed_step = -1
        self._rates_of = ()

    def q_history(self, steps: int) -> np.ndarray:
        """Actual joints ``steps`` periods ago (0 = now)."""
        steps = max(0, min(int(steps), len(self._history) - 1))
        return self._history[-1 - steps] if self._history else self.motion.q

    # ---- messages and events -----------------------------------------------------------------
    def message(self, text: str, source: str = "Controller", level: int = 3) -> None:
        """A text message: into the log and to every started RTDE client ('M' package); an information (level 3)
        is a text message on the primary interface too."""
        self.log.append((self.time, source, text))
        self.outbox.append((text, source, level))
        if level >= 3:
            self.event("text", text=text)
        if self.recorder is not None:
            self.recorder.event(self.time, source, text)

    def event(self, kind: str, **fields) -> None:
        """A robot message for the primary interface's clients (:mod:`sim.primary_server` formats it): ``text``
        (text), ``key`` (title, text), ``error`` (code, level, text), ``runtime`` (text, line), ``safety``
        (mode)."""
        self.event_seq += 1
        self.events.append((self.event_seq, self.time, kind, fields))

    # ---- safety ------------------------------------------------------------------------------
    def protective_stop(self, reason: str) -> None:
        """Enter the protective stop: the arm halts, the program stops, the safety bits say why."""
        self.motion.halt()
        self.motion.fault = None
        if self.safety_mode in EMERGENCY_STOPS:
            return  # the emergency stop has stopped everything already
        if self.safety_mode != SAFETY_PROTECTIVE_STOP:
            self.safety_mode = SAFETY_PROTECTIVE_STOP
            self.protective_stop_time = self.time
            self.message(f"Protective stop: {reason}", source="Safety", level=0)
            self.event("safety", mode=SAFETY_PROTECTIVE_STOP)
            self.event("error", code=0, level=3, text=f"Protective stop: {reason}")
        # the safety system stops the arm at once; the program is stopped a few periods later
        self._program_stop_at = self.time + PROGRAM_STOP_DELAY

    def unlock_protective_stop(self) -> str | None:
        """Leave the protective stop; None on success, else the controller's refusal text."""
        if self.safety_mode != SAFETY_PROTECTIVE_STOP:
            return None
        if self.time - self.protective_stop_time < UNLOCK_DELAY:
            return ("Cannot unlock protective stop until 5s after occurrence. "
                    "Always inspect cause of protective stop before unlocking")
        self.safety_mode = SAFETY_NORMAL
        self.message("Protective stop released", source="Safety", level=3)
        self.event("safety", mode=SAFETY_NORMAL)
        return None

    def press_emergency_stop(self, kind: str = "robot") -> None:
        """The emergency stop button: ``"robot"`` (the teach pendant's) or ``"system"`` (the cell's safety
        input). The arm stops at once, the program stops and the arm's power is cut (robot mode POWER_OFF)."""
        if kind not in ("robot", "system"):
            raise ValueError(f"emergency stop kind must be 'robot' or 'system', got {kind!r}")
        mode = SAFETY_ROBOT_EMERGENCY_STOP if kind == "robot" else SAFETY_SYSTEM_EMERGENCY_STOP
        if self.safety_mode == mode:
            return
        self.motion.halt()
        self.motion.fault = None
        self._program_stop_at = None
        self.safety_mode = mode
        what = "teach pendant emergency stop button" if kind == "robot" else "system emergency stop input"
        self.message(f"Emergency stop: the {what} is pressed; the arm is stopped and powered off",
                     source="Safety", level=0)
        self.event("safety", mode=mode)
        self.event("error", code=0, level=3, text=f"Emergency stop: the {what} is pressed")
        self._end_program("program stopped by the emergency stop")
        self.robot_mode = ROBOT_POWER_OFF

    def release_emergency_stop(self) -> bool:
        """Release the emergency stop button: the safety mode returns to NORMAL; the arm stays powered off
        (power on and brake release restart it). False when no emergency stop is pressed."""
        if self.safety_mode not in EMERGENCY_STOPS:
            return False
        self.safety_mode = SAFETY_NORMAL
        self.message("Emergency stop released: power the arm on and release its brakes to continue",
                     source="Safety", level=1)
        self.event("safety", mode=SAFETY_NORMAL)
        return True

    def set_remote_control(self, on: bool) -> None:
        """The pendant's switch between local and remote control (a running program keeps running); ValueError on a
        controller older than PolyScope 5.6, which has no such switch (always remote)."""
        on = bool(on)
        if not on and not self.version.at_least(REMOTE_CONTROL_SINCE):
            raise ValueError(f"local control: PolyScope {self.version.text} has no local / remote control switch "
                             "(from 5.6.0)")
        if on != self.remote_control:
            self.remote_control = on
            self.message(f"Control mode: {'remote' if on else 'local'}", source="Controller", level=3)

    def runtime_error(self, text: str) -> None:
        """A program's runtime error: the program halts (the arm stops), with an exception message."""
        self.motion.halt()
        self.message(f"Runtime error: {text}", source="Program", level=0)
        self.event("runtime", text=text, line=_line_of(text))
        self._end_program("program halted by a runtime error")

    def set_watchdog(self, field: str, min_frequency: float) -> None:
        self.watchdog = (field, min_frequency) if min_frequency > 0 else None
        self.input_time[field] = self.time

    # ---- programs ----------------------------------------------------------------------------
    def _end_program(self, why: str) -> None:
        self._program_stop_at = None
        if self.program is not None or self.runtime_state != RUNTIME_STOPPED:
            self.program = None
            self.runtime_state = RUNTIME_STOPPED
            self.watchdog = None
            self.event("key", title="PROGRAM_XXX_STOPPED", text=self.program_name)
            if self.recorder is not None:
                self.recorder.event(self.time, "Program", why)

    def stop_program(self) -> None:
        """Stop the running program (dashboard ``stop``, a new program): the arm halts."""
        if self.program is not None:
            self.motion.halt()
        self._end_program("program stopped")

    def load_program(self, text: str, port: int | None = None) -> bool:
        """A program arrives on a script port: it replaces the running one, or is refused whole.

        In local control mode the script ports take no program: it is refused and the running one is left
        alone."""
        if not self.remote_control:
            head = text.split("\n", 1)[0].strip()[:60]
            where = f" on port {port}" if port is not None else ""
            self.message(f"Script refused{where}: the robot is in local control mode ({head!r})",
                         source="Program", level=1)
            self.event("error", code=READ_ONLY_INTERFACE, level=3,
                       text="The primary interface is read-only in local control mode")
            return False
        self.stop_program()
        try:
            prog = parse_program(text)
        except ProgramError as exc:
            self.message(f"Compile error: {exc}", source="Program", level=0)
            self.event("runtime", text=f"compile error: {exc}", line=_line_of(str(exc)))
            return False
        if self.robot_mode != ROBOT_RUNNING:
            self.message(f"Program {prog.name} not started: robot is {MODE_NAMES.get(self.robot_mode)}",
                         source="Program", level=1)
            return False
        if self.safety_mode != SAFETY_NORMAL:
            self.message(f"Program {prog.name} not started: robot is in {SAFETY_NAMES.get(self.safety_mode)}",
                         source="Program", level=1)
            return False
        if prog.is_control_script:
            self.program = ControlScript(self, prog)
        else:
            try:
                body = compile_program(text) if head_of(text) else compile_line(text)
            except ProgramError as exc:
                self.message(f"Compile error in {prog.name}: {exc}", source="Program", level=0)
                self.event("runtime", text=f"compile error in {prog.name}: {exc}", line=_line_of(str(exc)))
                return False
            self.program = URScriptProgram(self, prog.name, body)
        self.program_name = prog.name
        self.runtime_state = RUNTIME_PLAYING
        self.event("key", title="PROGRAM_XXX_STARTED", text=prog.name)
        if self.recorder is not None:
            self.recorder.event(self.time, "Program", f"program {prog.name} started")
        return True

    def run_path(self, path: list[PathMove]) -> None:
        """Start an injected path: consecutive moves of one family are blended into one run (see
        :meth:`sim.motion.MotionModel.plan_path`)."""
        self.motion.plan_path([(mv.kind, Segment(np.array(mv.target), mv.v, mv.a, mv.r), mv.pose) for mv in path])

    # ---- the control period ------------------------------------------------------------------
    def tick(self) -> None:
        """Advance one control period of simulated time (caller holds :attr:`lock`)."""
        if self._program_stop_at is not None and self.time >= self._program_stop_at - 1e-9:
            self._program_stop_at = None
            self._end_program("program stopped by the protective stop")
        if self.safety_mode == SAFETY_NORMAL and self.runtime_state == RUNTIME_PLAYING and self.program is not None:
            self.program.step()
            if self.program is not None and not self.program.keep_running:
                if isinstance(self.program, ControlScript):
                    self.message("RTDE Control Script Terminated", source="rtde_control", level=3)
                self._end_program("program finished")
        if self.runtime_state != RUNTIME_PAUSED:
            self.motion.step(self.io.speed_slider)
        if self.motion.fault:
            self.protective_stop(self.motion.fault)
        if self.watchdog is not None:
            field, f = self.watchdog
            if self.time - self.input_time.get(field, self.time) > 1.0 / f:
                self.message(f"RTDE watchdog: no input on {field} for more than {1.0 / f:.3f} s", "RTDE", 0)
                self.motion.halt()
                self._end_program("program stopped by the RTDE watchdog")
        self.time = round(self.time + DT, 9)
        self.steps += 1
        # the motion model replaces its joint vector every period (never changes it in place): no copy;
        # the TCP pose and speed are computed when asked (RTDE packages, recorder), not every period
        self._history.append(self.motion.q)
        if self.recorder is not None:
            self.recorder.sample(self)

    # ---- dashboard actions -------------------------------------------------------------------
    def power_off(self) -> None:
        self.stop_program()
        self.motion.halt()
        self.robot_mode = ROBOT_POWER_OFF

    def power_on(self) -> None:
        if self.robot_mode == ROBOT_POWER_OFF and self.safety_mode not in EMERGENCY_STOPS:
            self.robot_mode = ROBOT_IDLE

    def brake_release(self) -> None:
        if self.robot_mode == ROBOT_IDLE:
            self.robot_mode = ROBOT_RUNNING

    def pause(self) -> bool:
        if self.runtime_state == RUNTIME_PLAYING:
            self.runtime_state = RUNTIME_PAUSED
            return True
        return False

    def resume(self) -> bool:
        if self.runtime_state == RUNTIME_PAUSED:
            self.runtime_state = RUNTIME_PLAYING
            return True
        return False

    def state(self) -> dict:
        """A JSON-able summary (for the parent process and people)."""
        return {
            "time": self.time,
            "q": self.motion.q.tolist(),
            "tcp_pose": self.tcp_pose().tolist(),
            "robot_mode": MODE_NAMES.get(self.robot_mode),
            "safety_mode": SAFETY_NAMES.get(self.safety_mode),
            "remote_control": self.remote_control,
            "runtime_state": RUNTIME_NAMES.get(self.runtime_state),
            "program": self.program_name if self.program is not None else None,
            "digital_out": self.io.digital_out,
            "digital_in": self.io.digital_in,
            "analog_out": list(self.io.analog_out),
            "log": [list(x) for x in list(self.log)[-20:]],
            "out_int": list(self.registers.out_int),
            "out_double": list(self.registers.out_double),
            "in_int": list(self.registers.in_int),
            "in_double": list(self.registers.in_double),
            "motion": self.motion.mode,
            "late_ticks": self.late_ticks,
            "max_late_ms": self.max_late_ms,
            "packages_sent": self.packages_sent,
        }
