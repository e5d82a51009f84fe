"""The simulated arm's one motion model: joint state integrated every control period (2 ms).

Every entry point (ur_rtde's control script, URScript programs) drives the arm through
:class:`MotionModel`; kinematics come only from :mod:`planner.kinematics`, and so do the samples of movej, movel
and movep and the joint limits they are held to (:mod:`planner.kinematics.ur_moves`, which the program writer checks
its programs on).

Modes
-----
trajectory
    ``movej`` / ``movel`` / ``movep`` (single targets or blended paths) and ``stopj`` / ``stopl``:
    a joint trajectory sampled at the control period, planned when the move starts. The time law is
    the time-optimal profile along the path under the move's speed ``v`` and acceleration ``a``
    (a trapezoid for a single move, continuous speed through blends, slow enough through a blend that
    turning the path's direction there needs at most ``a`` too: a blend too small for the speed is passed
    slowly, never within one control period at full speed). ``movej`` parameterizes the
    joint-space path by its infinity-norm length, so ``v`` and ``a`` bound every joint (the leading
    joint reaches them, as on the controller); ``movel`` by the tool's path length (rotation-only
    moves by the rotation angle times `ROTATION_RADIUS`), so ``v`` is the tool speed.
    Blends replace each corner by a quadratic Bezier arc from ``r`` before to ``r`` after the
    waypoint (``r`` clipped to half the neighbouring segments). A linear blend blends the whole pose, as
    UR's Cartesian blends are a smooth transition: the position along that arc, the orientation along
    its analogue on rotations (de Casteljau's construction with slerp), so the tool's angular velocity
    turns from the one segment's to the next's through the blend instead of jumping at the waypoint
    (a jump within one period is a joint acceleration of the jump / ``DT``: 0.08 rad/s is 40 rad/s^2).
    For ``movej`` the blend radius is applied in joint space (rad), an approximation of the
    controller's tool-space radius.
servo
    ``servoj``: the commanded target passes a first-order lookahead filter (time constant
    ``lookahead_time / 2``) and the joints follow the filtered target with a first-order tracking
    loop of time constant ``SERVO_GAIN_TIME / gain``. For a target moving at most ``v`` rad/s the
    following error is therefore at most ``v * (lookahead_time / 2 + SERVO_GAIN_TIME / gain)``
    (:func:`servo_following_error`). When following the targets would take a joint beyond its speed
    limit or beyond `JOINT_ACCEL_MAX` (a target that jumps away from the arm, or a stream faster than
    the joints can go) the arm stops with a protective stop, as the controller's safety system stops it;
    so does a target outside the joint position limits.
speed
    ``speedj`` / ``speedl``: joint (or tool) speeds ramped to the target at the given acceleration.

Protective stop: the model sets :attr:`MotionModel.fault` (a message) and halts when a target is out
of the joint position limits or unreachable, when a trajectory would exceed the joint speed limits
(``URModel.speed_limits``) or the joint acceleration limit `JOINT_ACCEL_MAX` (a move's ``v`` or ``a``
too high, a linear move through a singularity), or when a servo / speed command asks for more. A
trajectory runs up to its first sample beyond a limit and stops there; a command that exceeds a limit
from its first period does not move the arm. The controller core turns the fault into the
protective-stop safety state.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

from planner.kinematics import UnreachableError, forward, forward_matrix, get_model, inverse_nearest, wrap_angle
from planner.kinematics.ur_moves import (  # noqa: F401 - DT, ROTATION_RADIUS: the simulator's names for them
    ACCEL_TOLERANCE,
    DT,
    JOINT_ACCEL_MAX,
    ROTATION_RADIUS,
    SPEED_TOLERANCE,
    MotionError,
    MoveSamples,
    Segment,
    first_excess,
    joint_samples,
    linear_samples,
)

#: Gravity (m/s^2) in the base frame of a floor-mounted arm.
GRAVITY = np.array([0.0, 0.0, -9.81])
#: Tracking time constant scale of servoj: tau = SERVO_GAIN_TIME / gain (gain 300 -> 33 ms).
SERVO_GAIN_TIME = 10.0

HOME = np.array([0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0])


def servo_following_error(speed: float, lookahead_time: float, gain: float) -> float:
    """Bound on |actual - commanded| (rad) of servoj for a target moving at most ``speed`` rad/s."""
    return speed * (0.5 * lookahead_time + SERVO_GAIN_TIME / gain)


class MotionModel:
    """Joint state of one simulated arm, advanced by :meth:`step` every ``DT`` of simulated time.

    Parameters
    ----------
    model : str
        UR model name (``"ur5e"``, ...), see :func:`planner.kinematics.get_model`.
    q0 : array_like (6,), optional
        Initial joint positions (rad); default `HOME`.
    """

    def __init__(self, model: str, q0=None) -> None:
        self.model = get_model(model)
        self.lower = self.model.lower
        self.upper = self.model.upper
        self.qd_max = self.model.speed_limits
        self.q = np.array(HOME if q0 is None else q0, dtype=float)
        self.qd = np.zeros(6)
        self.qdd = np.zeros(6)
        self.mode = "idle"
        self.fault: str | None = None
        self.traj: MoveSamples | None = None
        self.index = 0.0  # playback position in traj.q (float, speed-slider scaled)
        # servo state
        self.servo_target = self.q.copy()
        self.servo_filtered = self.q.copy()
        self.servo_lookahead = 0.1
        self.servo_gain = 300.0
        self._servo_age = 1  # control periods since the last servo target
        # speed state
        self.speed_target = np.zeros(6)
        self.speed_accel = 0.5
        self.speed_linear = False
        self.tcp = np.zeros(6)

    # ---- state the controller reports ------------------------------------------------------
    @property
    def target_q(self) -> np.ndarray:
        return self.q

    @property
    def target_qd(self) -> np.ndarray:
        return self.qd

    @property
    def target_qdd(self) -> np.ndarray:
        return self.qdd

    @property
    def commanded(self) -> np.ndarray:
        """What the program commands now: the servo target in servo mode, else the planned joints."""
        return self.servo_target if self.mode == "servo" else self.q

    @property
    def busy(self) -> bool:
        """A trajectory (move or stop) is being executed."""
        return self.mode == "trajectory"

    def progress(self) -> int:
        """Index of the path entry being executed (for async progress), -1 when idle."""
        if self.traj is None or self.mode != "trajectory":
            return -1
        return max(0, bisect.bisect_right(self.traj.starts, int(self.index)) - 1)

    # ---- commands ----------------------------------------------------------------------------
    def halt(self) -> None:
        """Stop immediately (program stopped, protective stop): zero speed, no pending motion."""
        self.mode = "idle"
        self.traj = None
        self.qd[:] = 0.0
        self.qdd[:] = 0.0

    def abandon(self) -> None:
        """Drop the current trajectory (a killed move thread) keeping the joint speeds for a stop."""
        self.mode = "idle"
        self.traj = None

    def _check_q(self, q: np.ndarray, what: str) -> None:
        if not np.isfinite(q).all():
            raise MotionError(f"{what}: joint target is not finite")
        bad = np.flatnonzero((q < self.lower - 1e-9) | (q > self.upper + 1e-9))
        if len(bad):
            j = int(bad[0])
            raise MotionError(
                f"{what}: joint {j} target {q[j]:.4f} rad outside its limits "
                f"[{self.lower[j]:.4f}, {self.upper[j]:.4f}]"
            )

    def _check_limits(self, q: np.ndarray, what: str, accel: bool = True) -> tuple[int, str | None]:
        """First sample of ``q`` (K, 6), played from rest at the current joints, beyond the joint speed limits
        or (``accel``) the acceleration limit, and why; (-1, None) when none is
        (:func:`planner.kinematics.ur_moves.first_excess`)."""
        return first_excess(self.model, self.q, q, what, accel)

    def _start(self, traj: MoveSamples, what: str = "move", accel: bool = True) -> MoveSamples:
        k, why = self._check_limits(traj.q, what, accel)
        out = np.flatnonzero(((traj.q < self.lower) | (traj.q > self.upper)).any(axis=1))
        if len(out) and (k < 0 or out[0] < k):
            k = int(out[0])
            j = int(np.flatnonzero((traj.q[k] < self.lower) | (traj.q[k] > self.upper))[0])
            why = f"{what}: joint {j} position limit reached"
        if k >= 0:
            traj.q = traj.q[:k]
            traj.fault = traj.fault or why
        if len(traj.q) == 0:
            traj.q = self.q[None].copy()
        self.traj = traj
        self._origin = self.q.copy()
        self.index = 0.0
        self.mode = "trajectory"
        return traj

    def plan_joint(self, segs: list[Segment], duration: float = 0.0) -> MoveSamples:
        """Plan and start a (blended) joint-space move through ``segs`` (targets are joints); ``duration`` > 0 (a
        move's ``t``, s) slows its profile down uniformly to last that long, before the limits are checked."""
        return self._start(self._joint_samples(self.q, segs, duration), "movej")

    def plan_linear(self, segs: list[Segment], duration: float = 0.0) -> MoveSamples:
        """Plan and start a (blended) linear tool move through ``segs`` (targets are TCP poses); ``duration`` as
        for :meth:`plan_joint`."""
        return self._start(self._linear_samples(self.q, segs, duration), "movel")

    def plan_path(self, moves: list[tuple[str, Segment, bool]]) -> MoveSamples:
        """Plan and start a path of ``(kind, segment, target_is_pose)`` moves, kind ``movej``/``movel``/``movep``.

        Consecutive moves of one family (joint, or linear/process) are blended into one run; where the family
        changes the arm comes to rest on the waypoint (the controller blends across families; the simulator
        does not). A ``movej`` to a pose goes to the inverse kinematics solution nearest the joints it starts
        from, a ``movel`` to joints to their tool pose. ``starts`` counts the path's entries across runs."""
        runs: list[tuple[bool, list[tuple[Segment, bool]]]] = []
        for kind, seg, is_pose in moves:
            linear = kind != "movej"
            if runs and runs[-1][0] == linear:
                runs[-1][1].append((seg, is_pose))
            else:
                runs.append((linear, [(seg, is_pose)]))
        q0 = self.q
        parts: list[np.ndarray] = []
        starts: list[int] = []
        fault = None
        for linear, entries in runs:
            segs: list[Segment] = []
            near = q0
            for seg, is_pose in entries:
                target = np.asarray(seg.target, dtype=float)
                if linear and not is_pose:
                    target = forward(self.model, target, self.tcp)
                elif not linear and is_pose:
                    try:
                        target = inverse_nearest(self.model, target, near, tcp=self.tcp if np.any(self.tcp) else None)
                    except (UnreachableError, ValueError):
                        raise MotionError(f"movej target {len(starts) + len(segs)}: pose is not reachable "
                                          "(no inverse kinematics solution)") from None
                if not linear:
                    near = target
                segs.append(Segment(target, seg.v, seg.a, seg.r))
            tr = self._linear_samples(q0, segs) if linear else self._joint_samples(q0, segs)
            offset = sum(len(p) for p in parts)
            starts += [offset + k for k in tr.starts]
            parts.append(tr.q)
            if tr.fault:
                fault = tr.fault
                break
            q0 = tr.q[-1]
        return self._start(MoveSamples(np.vstack(parts), starts, fault), "path")

    def _joint_samples(self, q0: np.ndarray, segs: list[Segment], duration: float = 0.0) -> MoveSamples:
        """The samples of a (blended) joint-space move from ``q0`` through ``segs`` (not started), lasting at least
        ``duration`` s (:func:`planner.kinematics.ur_moves.joint_samples`)."""
        return joint_samples(self.model, q0, segs, duration)

    def _linear_samples(self, q0: np.ndarray, segs: list[Segment], duration: float = 0.0) -> MoveSamples:
        """The samples of a (blended) linear tool move from joints ``q0`` through ``segs`` (not started), lasting at
        least ``duration`` s (:func:`planner.kinematics.ur_moves.linear_samples`)."""
        return linear_samples(self.model, self.tcp, q0, segs, duration)

    def plan_stop(self, decel: float, linear: bool = False) -> MoveSamples:
        """Decelerate to rest (stopj / stopl): joint speeds scaled down together at ``decel``.

        ``decel`` is rad/s^2 for the leading joint (stopj) or m/s^2 of the tool (stopl).
        """
        if decel <= 0 or not math.isfinite(decel):
            raise MotionError(f"stop: deceleration must be > 0, got {decel}")
        qd = self.qd.copy()
        if linear:
            J = self.jacobian()
            speed = float(np.linalg.norm((J @ qd)[:3]))
        else:
            speed = float(np.abs(qd).max())
        self.mode = "idle"
        if speed <= 0.0:
            return self._start(MoveSamples(self.q[None].copy(), [0]))
        T = speed / decel
        K = max(1, math.ceil(T / DT - 1e-9))
        tk = np.minimum(np.arange(1, K + 1) * DT, T)[:, None]
        q = self.q + qd * tk - 0.5 * (qd / T) * tk**2
        return self._start(MoveSamples(q, [0]), "stop", accel=False)

    def servo(self, q_target, t: float, lookahead: float, gain: float) -> None:
        """servoj: track ``q_target``; ``t`` is the client's command period (s)."""
        q_target = np.asarray(q_target, dtype=float)
        self._check_q(q_target, "servoj")
        if self.mode != "servo":
            self.servo_target = self.q.copy()
            self.servo_filtered = self.q.copy()
            self.mode = "servo"
            self.traj = None
        self.servo_target = q_target
        self._servo_age = 0
        self.servo_lookahead = min(max(lookahead, 0.03), 0.2)
        self.servo_gain = min(max(gain, 100.0), 2000.0)

    def speed(self, target, accel: float, linear: bool) -> None:
        """speedj (joint speeds, rad/s) or speedl (tool speed [v, omega] in the base frame)."""
        target = np.asarray(target, dtype=float)
        if not np.isfinite(target).all() or accel <= 0:
            raise MotionError("speed command: target not finite or acceleration <= 0")
        if not linear:
            over = np.flatnonzero(np.abs(target) > self.qd_max * (1.0 + SPEED_TOLERANCE))
            if len(over):
                j = int(over[0])
                raise MotionError(f"speedj: joint {j} speed {target[j]:.3f} rad/s over its limit")
        if self.mode != "speed":
            self.traj = None
            self.mode = "speed"
            self._tool_speed = np.zeros(6)
        self.speed_target = target
        self.speed_accel = accel
        self.speed_linear = linear

    # ---- kinematics helpers ------------------------------------------------------------------
    def jacobian(self, q=None) -> np.ndarray:
        """Geometric Jacobian (6, 6) of the TCP (linear; angular velocity in the base frame)."""
        q = self.q if q is None else np.asarray(q, dtype=float)
        h = 1e-7
        Q = np.vstack([q, q + h * np.eye(6)])
        T = forward_matrix(self.model, Q, self.tcp)
        dp = (T[1:, :3, 3] - T[0, :3, 3]) / h
        dR = (T[1:, :3, :3] - T[0, :3, :3]) / h
        W = dR @ T[0, :3, :3].T  # skew(omega) per joint
        w = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
        return np.vstack([dp.T, w.T])

    # ---- integration -------------------------------------------------------------------------
    def step(self, fraction: float = 1.0) -> None:
        """Advance one control period (``fraction`` < 1: the speed slider slows trajectories)."""
        q_old, qd_old = self.q, self.qd
        tr = self.traj
        if self.mode == "trajectory" and tr is not None:
            n = len(tr.q)
            self.index = min(self.index + fraction, n)
            k = self.index - 1.0  # sample 0 is at t = DT
            if k < 0:
                q_new = self._origin + self.index * (tr.q[0] - self._origin)
            else:
                i = int(k)
                w = k - i
                if i >= n - 1:
                    q_new = tr.q[-1]
                elif w == 0.0:
                    q_new = tr.q[i]  # a row of the planned samples: never changed in place
                else:
                    q_new = tr.q[i] + w * (tr.q[i + 1] - tr.q[i])
            self._set(q_new, q_old, qd_old)
            if self.index >= n:
                self.mode = "idle"
                self.qd = np.zeros(6)
                if tr.fault:
                    self.fault = tr.fault
                    self.halt()
            # planned samples lie within the joint position limits (checked, or convex combinations of
            # targets that are): no per-period check
            return
        elif self.mode == "servo":
            self._servo_age += 1
            a_f = 1.0 - math.exp(-DT / (0.5 * self.servo_lookahead))
            self.servo_filtered = self.servo_filtered + a_f * (self.servo_target - self.servo_filtered)
            a_t = 1.0 - math.exp(-DT * self.servo_gain / SERVO_GAIN_TIME)
            qd = a_t * (self.servo_filtered - q_old) / DT
            why = self._servo_excess(qd, qd_old)
            if why is not None:
                self.fault = why
                self.halt()
                return
            self._set(q_old + qd * DT, q_old, qd_old)
        elif self.mode == "speed":
            if self.speed_linear:
                J = self.jacobian()
                cur = self._tool_speed
                dv = self.speed_target - cur
                dv_norm = float(np.linalg.norm(dv[:3]))
                lim = self.speed_accel * DT
                cur = cur + (dv if dv_norm <= lim else dv * (lim / dv_norm))
                self._tool_speed = cur
                qd = np.linalg.lstsq(J, cur, rcond=None)[0]
                over = np.flatnonzero(np.abs(qd) > self.qd_max * (1.0 + SPEED_TOLERANCE))
                if len(over):
                    self.fault = f"speedl: joint {int(over[0])} speed limit exceeded"
                    self.halt()
                    return
            else:
                lim = self.speed_accel * DT
                qd = qd_old + np.clip(self.speed_target - qd_old, -lim, lim)
            self._set(q_old + qd * DT, q_old, qd_old)
        else:
            self.qd = np.zeros(6)
            self.qdd = np.zeros(6)
            return
        out = np.flatnonzero((self.q < self.lower) | (self.q > self.upper))
        if len(out):
            self.q = np.clip(self.q, self.lower, self.upper)
            self.fault = f"joint {int(out[0])} position limit reached"
            self.halt()

    def _servo_excess(self, qd: np.ndarray, qd_old: np.ndarray) -> str | None:
        """Why following the servo target this period takes a joint beyond its limits (None: it does not)."""
        over_v = np.abs(qd) > self.qd_max * (1.0 + SPEED_TOLERANCE)
        acc = np.abs(qd - qd_old) / DT
        over_a = acc > JOINT_ACCEL_MAX * (1.0 + ACCEL_TOLERANCE)
        if not (over_v.any() or over_a.any()):
            return None
        gap = self.servo_target - self.q
        if over_v.any():
            j = int(np.argmax(np.abs(qd) / self.qd_max))
            what = f"speed {abs(qd[j]):.3f} rad/s beyond its limit {self.qd_max[j]:.3f} rad/s"
        else:
            j = int(np.argmax(acc))
            what = f"acceleration {acc[j]:.1f} rad/s^2 beyond the limit {JOINT_ACCEL_MAX:g} rad/s^2"
        return f"servoj: joint {j} {what} to follow its target ({gap[j]:+.4f} rad from the actual position)"

    def _set(self, q_new: np.ndarray, q_old: np.ndarray, qd_old: np.ndarray) -> None:
        self.q = q_new
        self.qd = (q_new - q_old) / DT
        self.qdd = (self.qd - qd_old) / DT

    def tool_pose(self) -> np.ndarray:
        """TCP pose p[x, y, z, rx, ry, rz] of the current joints."""
        return forward(self.model, self.q, self.tcp)

    def wrap_near(self, q: np.ndarray, near: np.ndarray) -> np.ndarray:
        """``q`` shifted by whole turns per joint to lie nearest ``near``, within the joint limits."""
        out = near + wrap_angle(q - near)
        out = np.where(out > self.upper, out - 2 * np.pi, out)
        return np.where(out < self.lower, out + 2 * np.pi, out)
