"""ur_rtde's control script (``def rtde_control():``) executed natively: its register protocol.

The script (ur_rtde 1.6.5, scripts/rtde_control.script) loops once per control period: it reads the
command id from ``input_int_register_0``, runs the command, and answers through
``output_int_register_0`` (1 = ready for a command, 2 = done with it), ``output_int_register_1``
(bool / int results), ``output_double_register_0..5`` (vector results) and ``output_int_register_2``
(async progress: bits 24-30 operation id, 16-22 write count, bit 15 running, bits 0-14 progress).
:class:`ControlScript` reproduces that loop step by step (``process_cmd``, the real-time command set,
the ``executing_cmd`` latch, the move/stop threads, ``write_async_progress_register``) on the
simulator's motion model. Force mode, servoC, jogging, contact detection and freedrive are accepted
and ignored (no force or contact model); their result registers read 0.
"""

from __future__ import annotations

import numpy as np

from planner.kinematics import UnreachableError, forward, inverse, inverse_nearest, matrix_to_pose, pose_to_matrix
from sim.motion import MotionError, Segment
from sim.programs import Program

# commands the main loop handles "real-time": processed, then ready signalled at once
REALTIME = frozenset({24, 11, 9, 10, 6, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71})
NO_OP = frozenset({6, 8, 12, 18, 19, 20, 21, 41, 51, 52, 53, 56, 57, 59, 62, 66, 67, 68, 69, 70, 71})
STOP_SCRIPT = 255


class ScriptRuntimeError(Exception):
    """A runtime error of the script (e.g. get_inverse_kin without a solution): the program halts."""


class ControlScript:
    """One running instance of ur_rtde's control script, stepped by the controller every period.

    Parameters
    ----------
    core : sim.core.Core
        The controller (registers, motion model, safety, TCP offset, payload).
    program : Program
        The framed script (register offsets, injected path).
    """

    def __init__(self, core, program: Program) -> None:
        self.core = core
        self.motion = core.motion
        self.regs = core.registers
        self.oi = program.int_offset
        self.of = program.float_offset
        self.path = program.path
        self.keep_running = True
        self.executing = False
        self.blocked: str | None = None  # the blocking call in progress ("move", "path", "stop")
        self.move_thread = False  # async move thread alive
        self.move_is_path = False
        self.stop_thread = False
        self.stop_type = 0  # global of the script: 0 = stopj, 1 = stopl
        self.speed_type = 0
        self.path_progress = -1
        self.async_wr_count = 0
        self.async_op_id = 0
        self.contact_step_back = 0
        self.core.message("RTDE Control Script Loaded", source="rtde_control", level=3)
        self.reset_async_progress()
        self.signal_ready()

    # ---- registers -------------------------------------------------------------------------
    def rd_i(self, i: int) -> int:
        return self.regs.in_int[i + self.oi]

    def rd_f(self, i: int) -> float:
        return self.regs.in_double[i + self.of]

    def rd_vec(self, i: int) -> np.ndarray:
        j = i + self.of
        return np.array(self.regs.in_double[j : j + 6], dtype=float)

    def wr_i(self, i: int, v: int) -> None:
        self.regs.out_int[i + self.oi] = int(v)

    def wr_f(self, i: int, v: float) -> None:
        self.regs.out_double[i + self.of] = float(v)

    def wr_vec(self, i: int, v) -> None:
        for k in range(6):
            self.wr_f(i + k, float(v[k]))

    def signal_ready(self) -> None:
        self.wr_i(0, 1)

    def signal_done(self) -> None:
        self.wr_i(0, 2)

    def write_async_progress(self, value: int) -> None:
        """``write_async_progress_register`` of the script."""
        self.async_wr_count = 0 if self.async_wr_count + 1 > 127 else self.async_wr_count + 1
        if value == 0:
            self.async_op_id = 0 if self.async_op_id + 1 > 127 else self.async_op_id + 1
        reg = self.async_wr_count * 65536 + self.async_op_id * 16777216
        if value >= 0:
            reg += min(value, 32767) + 32768
        self.wr_i(2, reg)

    def reset_async_progress(self) -> None:
        self.write_async_progress(-1)

    # ---- the main loop, one control period ---------------------------------------------------
    def step(self) -> None:
        """One iteration of the script's main loop (plus its threads) for this control period."""
        if not self.keep_running:
            return
        self._threads()
        if self.rd_i(0) == STOP_SCRIPT and (self.blocked is not None or self.executing):
            # stopScript while a blocking command runs or before the previous command's NO_CMD: the script on a
            # controller reads it only once that client clears the register, which a killed client never does
            # (ur_rtde's next client then waits up to 300 s); here it stops the script at once, and the arm
            self.blocked = None
            self.motion.halt()
            self.keep_running = self.process(STOP_SCRIPT)
            return
        if self.blocked is not None:
            if self.blocked == "path":
                self._path_progress()
            if self.motion.busy:
                return
            self.blocked = None
            self.signal_done()
            self.executing = True
            return
        cmd = self.rd_i(0)
        if cmd in REALTIME:
            self.keep_running = self.process(cmd)
            self.signal_ready()
        elif cmd == 0:
            self.executing = False
            self.signal_ready()
        else:
            if not self.executing:
                self.keep_running = self.process(cmd)
            self.executing = True

    def _threads(self) -> None:
        """The async move / stop threads: progress, and their end when the motion ends."""
        if self.move_thread:
            if self.move_is_path:
                self._path_progress()
            if not self.motion.busy:
                self.move_thread = False
                self.write_async_progress(-1)
        if self.stop_thread and not self.motion.busy:
            self.stop_thread = False
            self.write_async_progress(-1)

    def _path_progress(self) -> None:
        k = self.motion.progress()
        while self.path_progress < k:
            self.path_progress += 1
            self.write_async_progress(self.path_progress)

    # ---- helpers -----------------------------------------------------------------------------
    def stop_async_move(self) -> None:
        if self.move_thread:
            self.move_thread = False
            self.motion.abandon()
            self.write_async_progress(-1)

    def _start_move(self, kind: str, target: np.ndarray, v: float, a: float, asynchronous: bool) -> None:
        self.stop_async_move()
        if asynchronous:
            self.write_async_progress(0)  # signal_async_operation_started
        try:
            if kind == "movej":
                self.motion.plan_joint([Segment(target, v, a)])
            else:
                self.motion.plan_linear([Segment(target, v, a)])
        except MotionError as exc:
            self.core.protective_stop(str(exc))
            return
        if asynchronous:
            self.move_thread, self.move_is_path = True, False
        else:
            self.blocked = "move"

    def _exec_path(self, asynchronous: bool) -> None:
        self.stop_async_move()
        if asynchronous:
            self.write_async_progress(0)
        self.core.message("exec_move_path", source="rtde_control", level=3)
        self.path_progress = -1
        if not self.path:
            if asynchronous:
                self.write_async_progress(-1)
            return
        try:
            self.core.run_path(self.path)
        except MotionError as exc:
            self.core.protective_stop(str(exc))
            return
        if asynchronous:
            self.move_thread, self.move_is_path = True, True
        else:
            self.blocked = "path"

    def _stop(self, decel: float, linear: bool) -> None:
        try:
            self.motion.plan_stop(decel, linear)
        except MotionError as exc:
            raise ScriptRuntimeError(str(exc)) from None
        self.blocked = "stop"

    def get_inverse_kin(self, pose, qnear=None) -> np.ndarray:
        """The IK solution nearest ``qnear`` (default: the current joints), as the controller picks it."""
        near = self.motion.q if qnear is None else np.asarray(qnear, dtype=float)
        try:
            return inverse_nearest(self.motion.model, pose, near, tcp=self.motion.tcp)
        except (UnreachableError, ValueError) as exc:
            raise ScriptRuntimeError(f"get_inverse_kin(p{np.round(pose, 6).tolist()}): {exc}") from None

    def _within_limits_pose(self, pose) -> bool:
        sols = inverse(self.motion.model, pose, tcp=self.motion.tcp)
        return len(sols) > 0

    # ---- process_cmd -------------------------------------------------------------------------
    def process(self, cmd: int) -> bool:
        """``process_cmd(cmd)``: returns False for stop-script (255)."""
        try:
            self._process(cmd)
        except ScriptRuntimeError as exc:
            self.core.runtime_error(str(exc))
            return False
        if cmd == STOP_SCRIPT or self.core.program is not self:
            return False  # stop script, or halted by a runtime error
        if self.core.safety_mode != 1:
            return True  # a protective stop: no "done"; the controller ends the program shortly
        if self.blocked is None and cmd not in REALTIME:
            self.signal_done()
        return True

    def _process(self, cmd: int) -> None:  # noqa: C901 - one branch per command, as in the script
        m = self.motion
        if cmd in (1, 2, 3, 4):
            target, v, a, asyn = self.rd_vec(0), self.rd_f(6), self.rd_f(7), self.rd_i(1) == 1
            if cmd == 1:
                self._start_move("movej", target, v, a, asyn)
            elif cmd == 2:
                self._start_move("movej", self.get_inverse_kin(target), v, a, asyn)
            elif cmd == 3:
                self._start_move("movel", target, v, a, asyn)
            else:
                self._start_move("movel", forward(m.model, target, m.tcp), v, a, asyn)
        elif cmd == 7:
            self._stop(10.0, True)
        elif cmd in (9, 10):
            self.speed_type = 1 if cmd == 9 else 0
            try:
                m.speed(self.rd_vec(0), self.rd_f(6), linear=cmd == 10)
            except MotionError as exc:
                self.core.protective_stop(str(exc))
        elif cmd in (11, 24):
            target = self.rd_vec(0)
            if cmd == 24:
                target = self.get_inverse_kin(target)
            try:
                m.servo(target, self.rd_f(8), self.rd_f(9), self.rd_f(10))
            except MotionError as exc:
                self.core.protective_stop(str(exc))
        elif cmd == 15:
            self._stop(self.rd_f(0), self.speed_type == 0)
        elif cmd == 16:
            self._stop(self.rd_f(0), True)
        elif cmd in (17, 65):
            mass, cog = self.rd_f(0), [self.rd_f(1), self.rd_f(2), self.rd_f(3)]
            self.core.payload_mass = mass
            if any(cog):
                self.core.payload_cog = np.array(cog)
            if cmd == 65:
                self.core.payload_inertia = np.array([self.rd_f(4 + k) for k in range(6)])
        elif cmd == 25:
            self.wr_i(1, 0)
        elif cmd == 26:
            self.wr_f(0, 0.002)
        elif cmd == 27:
            self.wr_vec(0, self.core.q_history(self.rd_i(1)))
        elif cmd == 28:
            traj = m.traj
            target = traj.q[-1] if traj is not None and m.busy else m.q
            self.wr_vec(0, forward(m.model, target, m.tcp))
        elif cmd == 29:
            m.tcp = self.rd_vec(0)
            self.core.tcp_changed()
        elif cmd in (30, 46):
            qnear = self.rd_vec(6) if cmd == 30 else None
            self.wr_vec(0, self.get_inverse_kin(self.rd_vec(0), qnear))
        elif cmd == 31:
            self.core.protective_stop("protective_stop() called by the program")
        elif cmd in (33, 34):
            self._exec_stopl_stopj()
        elif cmd == 35:
            self.core.set_watchdog(f"input_int_register_{self.oi}", self.rd_f(0))
        elif cmd == 36:
            self.wr_i(1, 1 if self._within_limits_pose(self.rd_vec(0)) else 0)
        elif cmd == 37:
            q = self.rd_vec(0)
            self.wr_i(1, 1 if bool(np.all((q >= m.lower) & (q <= m.upper))) else 0)
        elif cmd == 38:
            self.wr_vec(0, np.zeros(6))
        elif cmd == 39:
            T = pose_to_matrix(self.rd_vec(0)) @ pose_to_matrix(self.rd_vec(6))
            self.wr_vec(0, matrix_to_pose(T))
        elif cmd == 40:
            self.wr_vec(0, m.tcp)
        elif cmd == 42:
            self._stop(1.2, True)
        elif cmd == 43:
            self.wr_vec(0, forward(m.model, m.q, m.tcp))
        elif cmd == 44:
            self.wr_vec(0, forward(m.model, self.rd_vec(0), self.rd_vec(6)))
        elif cmd == 45:
            self._exec_path(self.rd_i(1) == 1)
        elif cmd == 47:
            self.wr_i(1, 1 if (not m.busy and not np.any(m.qd)) else 0)
        elif cmd == 54:
            self.wr_i(1, 0)
        elif cmd == 58:
            self.wr_vec(0, forward(m.model, m.q))
        elif cmd in (60, 61):
            try:
                self.get_inverse_kin(self.rd_vec(0), self.rd_vec(6) if cmd == 61 else None)
                self.wr_i(1, 1)
            except ScriptRuntimeError:
                self.wr_i(1, 0)
        elif cmd in (63, 64):
            self.wr_i(1, self.contact_step_back)
        elif cmd == STOP_SCRIPT:
            self.core.message("Received stop script!", source="rtde_control", level=3)
        # every other id (0 excluded) falls through the script's if-chain unchanged

    def _exec_stopl_stopj(self) -> None:
        decel, asyn = self.rd_f(0), self.rd_i(1)
        stop_move = True
        if self.stop_thread:
            stop_move = False
            self.stop_thread = False
            self.write_async_progress(-1)
        if stop_move:
            self.stop_async_move()
        if asyn == 1:
            self.stop_type = 1
            self.write_async_progress(0)
            try:
                self.motion.plan_stop(decel, True)
            except MotionError as exc:
                raise ScriptRuntimeError(str(exc)) from None
            self.stop_thread = True
        else:
            self._stop(decel, self.stop_type == 1)

