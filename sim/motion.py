"""The simulated arm's one motion model: joint state integrated every control period (2 ms).

Every entry point (ur_rtde's control script, URScript programs) drives the arm through
:class:`MotionModel`; kinematics come only from :mod:`planner.kinematics`.

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
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from planner.kinematics import (
    UnreachableError,
    forward,
    forward_matrix,
    get_model,
    inverse_nearest,
    inverse_path,
    wrap_angle,
)

DT = 0.002  # control period (s), 500 Hz
#: Gravity (m/s^2) in the base frame of a floor-mounted arm.
GRAVITY = np.array([0.0, 0.0, -9.81])
#: Joint acceleration limit (rad/s^2) of every joint, beyond which the arm stops with a protective stop.
#: UR publishes no acceleration limits (``planner.kinematics`` models none); this is the bound the controller
#: accepts in a move command, as ur_rtde 1.6.5 checks it (UR_JOINT_ACCELERATION_MAX, rtde_control_interface.h).
JOINT_ACCEL_MAX = 40.0
#: Relative tolerance on the joint acceleration limit before a protective stop (sampled trajectories).
ACCEL_TOLERANCE = 1e-3
#: Tracking time constant scale of servoj: tau = SERVO_GAIN_TIME / gain (gain 300 -> 33 ms).
SERVO_GAIN_TIME = 10.0
#: Length (m) one radian of tool rotation counts for in a linear move's path length.
ROTATION_RADIUS = 0.1
#: Relative tolerance on the joint speed limits before a protective stop.
SPEED_TOLERANCE = 1e-6
#: Path grid spacing (m or rad) of the time law, and its sample bounds.
GRID_STEP = 5e-4
GRID_MIN, GRID_MAX = 16, 4000

HOME = np.array([0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0])


class MotionError(Exception):
    """A motion command that cannot start (the message says why); the caller raises a protective stop."""


def servo_following_error(speed: float, lookahead_time: float, gain: float) -> float:
    """Bound on |actual - commanded| (rad) of servoj for a target moving at most ``speed`` rad/s."""
    return speed * (0.5 * lookahead_time + SERVO_GAIN_TIME / gain)


@dataclass
class Segment:
    """One move of a path: target (joints, or a tool pose for linear moves), speed, acceleration, blend."""

    target: np.ndarray
    v: float
    a: float
    r: float = 0.0


@dataclass
class Trajectory:
    """A planned joint trajectory sampled every ``DT``.

    Attributes
    ----------
    q : ndarray, shape (K, 6)
        Joint positions (rad) at t = DT, 2 DT, ..., the last one the end of the move.
    starts : list of int
        Sample index at which each path entry starts (for async progress).
    fault : str or None
        If set, the arm stops with a protective stop after the last sample (a limit is exceeded or
        the path leaves the workspace there).
    """

    q: np.ndarray
    starts: list[int] = field(default_factory=list)
    fault: str | None = None


def _time_law(d: np.ndarray, vmax: np.ndarray, amax: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Times (s) and speeds at the path grid ``d`` of the fastest rest-to-rest profile under vmax(d), amax(d).

    Between grid points the speed squared is linear in the path parameter: constant acceleration."""
    n = len(d)
    ds = np.diff(d)
    v = vmax.astype(float).copy()
    v[0] = 0.0
    v[-1] = 0.0
    two_a_ds = 2.0 * np.minimum(amax[:-1], amax[1:]) * ds
    for i in range(n - 1):  # forward pass (acceleration)
        lim = math.sqrt(v[i] * v[i] + two_a_ds[i])
        if v[i + 1] > lim:
            v[i + 1] = lim
    for i in range(n - 2, -1, -1):  # backward pass (deceleration)
        lim = math.sqrt(v[i + 1] * v[i + 1] + two_a_ds[i])
        if v[i] > lim:
            v[i] = lim
    vs = v[:-1] + v[1:]
    dt = np.divide(2.0 * ds, vs, out=np.zeros_like(ds), where=vs > 0)
    return np.concatenate([[0.0], np.cumsum(dt)]), v


def _corner_radii(radii: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Blend radius (m+1,) at every waypoint of a path of m segments, in the path parameter's units: the move's
    ``r`` into the waypoint clipped to half of either neighbouring segment; 0 at the ends and where the arm
    passes the waypoint unblended (``r`` 0, or a segment of length 0)."""
    r = np.zeros(len(lengths) + 1)
    if len(lengths) > 1:
        r[1:-1] = np.minimum(radii[:-1], 0.5 * np.minimum(lengths[:-1], lengths[1:]))
        r[1:-1][(lengths[:-1] <= 0) | (lengths[1:] <= 0)] = 0.0
    return np.maximum(r, 0.0)


def _blend_points(W: np.ndarray, radii: np.ndarray, lengths: np.ndarray, d: np.ndarray):
    """Points of the polyline ``W`` (m+1, k) at polyline parameter ``d`` with corners blended.

    ``lengths`` (m,) are the segment lengths in the parameter's norm; returns (points (n, k),
    segment index (n,), fraction within the segment (n,)).
    """
    D = np.concatenate([[0.0], np.cumsum(lengths)])
    seg = np.clip(np.searchsorted(D, d, side="right") - 1, 0, len(lengths) - 1)
    frac = np.divide(d - D[seg], lengths[seg], out=np.ones_like(d), where=lengths[seg] > 0)
    frac = np.clip(frac, 0.0, 1.0)
    P = W[seg] + frac[:, None] * (W[seg + 1] - W[seg])
    corner_r = _corner_radii(radii, lengths)
    for i in np.flatnonzero(corner_r > 0.0):  # interior corners with a blend
        r = corner_r[i]
        zone = (d >= D[i] - r) & (d <= D[i] + r)
        if not zone.any():
            continue
        u0 = (W[i] - W[i - 1]) / lengths[i - 1]
        u1 = (W[i + 1] - W[i]) / lengths[i]
        A, B = W[i] - r * u0, W[i] + r * u1
        w = ((d[zone] - (D[i] - r)) / (2.0 * r))[:, None]
        P[zone] = (1 - w) ** 2 * A + 2 * w * (1 - w) * W[i] + w**2 * B
    return P, seg, frac


def _blend_rotations(rots: Rotation, radii: np.ndarray, lengths: np.ndarray, d: np.ndarray, seg: np.ndarray,
                     frac: np.ndarray) -> np.ndarray:
    """Rotation vectors (n, 3) at path parameter ``d`` of a linear path through the orientations ``rots`` (m+1),
    with its corners blended as :func:`_blend_points` blends the positions.

    On segment k the orientation is the slerp R_k exp(f e_k), e_k = log(R_k^-1 R_k+1), at the fraction f
    (``seg``, ``frac`` from :func:`_blend_points`). Within ``r`` of waypoint j it is the quadratic Bezier curve
    on rotations from R_A (``r`` before the waypoint on segment j-1) over R_j to R_B (``r`` after it on segment
    j) by de Casteljau's construction with slerp, at w = (d - D_j + r) / 2r: with rho = r / length of each
    segment, R_j X(w), X = exp(a) exp(w log(exp(-a) exp(b))), a = (w - 1) rho_j-1 e_j-1, b = w rho_j e_j. It
    starts at R_A and ends at R_B with the segments' angular velocities (d/dw = 2 rho e), as the position arc
    starts and ends with the segments' velocities: the angular velocity is continuous through the blend."""
    e = (rots[:-1].inv() * rots[1:]).as_rotvec()  # (m, 3)
    out = (rots[seg] * Rotation.from_rotvec(frac[:, None] * e[seg])).as_rotvec()
    corner_r = _corner_radii(radii, lengths)
    if not (corner_r > 0.0).any():
        return out
    D = np.concatenate([[0.0], np.cumsum(lengths)])
    j = np.clip(np.searchsorted(0.5 * (D[:-1] + D[1:]), d), 0, len(D) - 1)  # the nearest waypoint
    r = corner_r[j]
    zone = np.flatnonzero((r > 0.0) & (np.abs(d - D[j]) <= r))
    if not len(zone):
        return out
    j, r = j[zone], r[zone]
    w = np.clip((d[zone] - D[j] + r) / (2.0 * r), 0.0, 1.0)
    a = Rotation.from_rotvec(((w - 1.0) * r / lengths[j - 1])[:, None] * e[j - 1])
    b = Rotation.from_rotvec((w * r / lengths[j])[:, None] * e[j])
    X = a * Rotation.from_rotvec(w[:, None] * (a.inv() * b).as_rotvec())
    out[zone] = (rots[j] * X).as_rotvec()
    return out


def _stretched(t: np.ndarray, v: np.ndarray, duration: float) -> tuple[np.ndarray, np.ndarray]:
    """The profile (times, speeds) of :func:`_time_law` slowed down uniformly to last ``duration`` s (a move's
    ``t``; never faster than planned): times times c, speeds over c, accelerations over c^2, c = duration / T."""
    T = float(t[-1])
    if not (duration > T > 0.0):
        return t, v
    c = duration / T
    return t * c, v / c


def _inf_norm(x: np.ndarray, axis: int) -> np.ndarray:
    return np.abs(x).max(axis=axis)


def _corner_turns(parts: list[np.ndarray], lengths: np.ndarray, norm) -> np.ndarray:
    """How sharply the path turns at each waypoint (m+1,): the change of its direction there, the direction of a
    segment being its displacement per unit of the path parameter (``parts``: arrays (m, k) of displacements, e.g.
    position and scaled rotation, each measured by ``norm`` over its last axis; the largest part counts, as the
    path parameter is the largest part's length). 0 at the ends and next to a segment of length 0."""
    turn = np.zeros(len(lengths) + 1)
    if len(lengths) < 2:
        return turn
    ok = lengths > 0
    inv = np.divide(1.0, lengths, out=np.zeros_like(lengths), where=ok)
    for x in parts:
        u = x * inv[:, None]
        turn[1:-1] = np.maximum(turn[1:-1], norm(u[1:] - u[:-1], axis=1))
    turn[1:-1][~(ok[:-1] & ok[1:])] = 0.0
    return turn


def _path_grid(lengths: np.ndarray, segs: list[Segment], turns: np.ndarray | None = None):
    """Parameter grid over the whole path, with per-sample speed and acceleration limits.

    The grid holds every waypoint; the speed limit is 0 at an interior waypoint without a blend (``r`` 0 on
    the move that ends there): the arm comes to rest there, as the controller stops at an unblended waypoint.
    Through a blend the speed is at most sqrt(2 a r / turn) (``turns`` from :func:`_corner_turns`, r from
    :func:`_corner_radii`): a blend turns the direction by ``turn`` over 2 r of the path parameter (the quadratic
    Bezier arc of :func:`_blend_points`, whose second derivative is turn / 2r), so at speed v it accelerates the
    arm by v^2 turn / 2r, which ``a`` bounds as it bounds the speeding up and slowing down along the path (UR's
    movel/movep ``a`` is the tool's acceleration). A blend too small for the speed is thus passed slowly, never
    within one control period at full speed."""
    total = float(lengths.sum())
    n = int(min(GRID_MAX, max(GRID_MIN, math.ceil(total / GRID_STEP)))) + 1
    D = np.concatenate([[0.0], np.cumsum(lengths)])
    d = np.union1d(np.linspace(0.0, total, n), D)
    vs = np.array([s.v for s in segs])
    As = np.array([s.a for s in segs])
    cap = r = None
    if turns is not None and len(segs) > 1:
        r = _corner_radii(np.array([s.r for s in segs]), lengths)
        cap = np.full(len(D), np.inf)
        sharp = np.flatnonzero((r > 0.0) & (turns > 0.0))
        cap[sharp] = np.sqrt(2.0 * np.minimum(As[sharp - 1], As[sharp]) * r[sharp] / turns[sharp])
        slow = np.flatnonzero(cap < np.maximum(vs[np.maximum(np.arange(len(D)) - 1, 0)],
                                               vs[np.minimum(np.arange(len(D)), len(segs) - 1)]))
        if len(slow):  # the blend's ends on the grid, so that the speed is capped over the whole blend
            d = np.union1d(d, np.clip(np.concatenate([D[slow] - r[slow], D[slow] + r[slow]]), 0.0, total))
        else:
            cap = None
    seg = np.clip(np.searchsorted(D, d, side="right") - 1, 0, len(segs) - 1)
    v = vs[seg]
    a = As[seg]
    if cap is not None and r is not None:
        j = np.clip(np.searchsorted(0.5 * (D[:-1] + D[1:]), d), 0, len(D) - 1)  # the nearest waypoint
        zone = np.abs(d - D[j]) <= r[j] * (1.0 + 1e-12)
        v[zone] = np.minimum(v[zone], cap[j[zone]])
    stops = [D[i + 1] for i, s in enumerate(segs[:-1]) if s.r <= 0.0]
    if stops:
        v[np.searchsorted(d, stops)] = 0.0
    return d, v, a


def _sample_times(t: np.ndarray, d: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Path parameter at every control period DT, 2 DT, ..., ending exactly at the path's end.

    Exact for the profile of :func:`_time_law` (constant acceleration between its grid points), so that the
    samples' second differences are the profile's acceleration (a linear interpolation in time would put the
    acceleration of a whole grid interval into single periods)."""
    T = float(t[-1])
    K = max(1, math.ceil(T / DT - 1e-9))
    tk = np.minimum(np.arange(1, K + 1) * DT, T)
    i = np.clip(np.searchsorted(t, tk, side="right") - 1, 0, len(t) - 2)
    h = t[i + 1] - t[i]
    tau = np.minimum(tk - t[i], h)
    acc = np.divide(v[i + 1] - v[i], h, out=np.zeros_like(h), where=h > 0)
    dk = d[i] + v[i] * tau + 0.5 * acc * tau * tau
    dk[-1] = d[-1]
    return np.minimum(dk, d[-1])


def _starts(dk: np.ndarray, lengths: np.ndarray) -> list[int]:
    D = np.concatenate([[0.0], np.cumsum(lengths)])
    return [int(np.searchsorted(dk, D[i], side="right")) for i in range(len(lengths))]


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
        self.traj: Trajectory | None = None
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
        or (``accel``) the acceleration limit, and why; (-1, None) when none is."""
        P = np.vstack([self.q, self.q, q])
        V = np.diff(P, axis=0) / DT  # speed reached at each sample (0: at rest before the move)
        speed = np.abs(V[1:]) > self.qd_max * (1.0 + SPEED_TOLERANCE)
        if accel:
            acc = np.abs(np.diff(V, axis=0)) / DT > JOINT_ACCEL_MAX * (1.0 + ACCEL_TOLERANCE)
            over = speed | acc
        else:
            over = speed
        bad = np.flatnonzero(over.any(axis=1))
        if not len(bad):
            return -1, None
        k = int(bad[0])
        v = V[k + 1]
        if speed[k].any():
            j = int(np.argmax(np.abs(v) / self.qd_max))
            return k, (f"{what}: joint {j} speed {abs(v[j]):.3f} rad/s beyond its limit {self.qd_max[j]:.3f} rad/s")
        a = np.abs(V[k + 1] - V[k]) / DT
        j = int(np.argmax(a))
        return k, f"{what}: joint {j} acceleration {a[j]:.1f} rad/s^2 beyond the limit {JOINT_ACCEL_MAX:g} rad/s^2"

    def _start(self, traj: Trajectory, what: str = "move", accel: bool = True) -> Trajectory:
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

    def plan_joint(self, segs: list[Segment], duration: float = 0.0) -> Trajectory:
        """Plan and start a (blended) joint-space move through ``segs`` (targets are joints); ``duration`` > 0 (a
        move's ``t``, s) slows its profile down uniformly to last that long, before the limits are checked."""
        return self._start(self._joint_samples(self.q, segs, duration), "movej")

    def plan_linear(self, segs: list[Segment], duration: float = 0.0) -> Trajectory:
        """Plan and start a (blended) linear tool move through ``segs`` (targets are TCP poses); ``duration`` as
        for :meth:`plan_joint`."""
        return self._start(self._linear_samples(self.q, segs, duration), "movel")

    def plan_path(self, moves: list[tuple[str, Segment, bool]]) -> Trajectory:
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
        return self._start(Trajectory(np.vstack(parts), starts, fault), "path")

    def _joint_samples(self, q0: np.ndarray, segs: list[Segment], duration: float = 0.0) -> Trajectory:
        """The samples of a (blended) joint-space move from ``q0`` through ``segs`` (not started), lasting at least
        ``duration`` s."""
        W = np.vstack([q0] + [np.asarray(s.target, dtype=float) for s in segs])
        for i, s in enumerate(segs):
            self._check_q(W[i + 1], f"movej target {i}")
            if not (s.v > 0 and s.a > 0):
                raise MotionError(f"movej target {i}: speed and acceleration must be > 0")
        lengths = np.abs(np.diff(W, axis=0)).max(axis=1)
        if lengths.sum() <= 0.0:
            return Trajectory(np.array(q0, dtype=float)[None].copy(), [0] * len(segs))
        d, v, a = _path_grid(lengths, segs, _corner_turns([np.diff(W, axis=0)], lengths, _inf_norm))
        t, vt = _stretched(*_time_law(d, v, a), duration)
        dk = _sample_times(t, d, vt)
        q, _, _ = _blend_points(W, np.array([s.r for s in segs]), lengths, dk)
        q[-1] = W[-1]
        return Trajectory(q, _starts(dk, lengths))

    def _linear_samples(self, q0: np.ndarray, segs: list[Segment], duration: float = 0.0) -> Trajectory:
        """The samples of a (blended) linear tool move from joints ``q0`` through ``segs`` (not started), lasting at
        least ``duration`` s."""
        P0 = forward(self.model, q0, self.tcp)
        poses = np.vstack([P0] + [np.asarray(s.target, dtype=float) for s in segs])
        for i, s in enumerate(segs):
            if not np.isfinite(poses[i + 1]).all():
                raise MotionError(f"movel target {i}: pose is not finite")
            if not (s.v > 0 and s.a > 0):
                raise MotionError(f"movel target {i}: speed and acceleration must be > 0")
        rots = Rotation.from_rotvec(poses[:, 3:])
        turn = (rots[:-1].inv() * rots[1:]).as_rotvec()  # each segment's rotation, in its start frame
        chord = np.diff(poses[:, :3], axis=0)
        lengths = np.maximum(np.linalg.norm(chord, axis=1), np.linalg.norm(turn, axis=1) * ROTATION_RADIUS)
        # the target itself must be reachable before the arm moves
        try:
            q_end = inverse_path(self.model, poses[-1:], q0, tcp=self.tcp)[0]
        except UnreachableError:
            raise MotionError("movel: target pose is not reachable (no inverse kinematics solution)") from None
        if lengths.sum() <= 0.0:
            return Trajectory(np.array(q0, dtype=float)[None].copy(), [0] * len(segs))
        # the angular velocity at a waypoint, before and after it, in the frame there: e_k-1 and e_k (the slerp
        # R_k-1 exp(f e_k-1) turns about e_k-1, which R_k-1 exp(e_k-1) = R_k leaves unchanged)
        d, v, a = _path_grid(lengths, segs, _corner_turns([chord, ROTATION_RADIUS * turn], lengths, np.linalg.norm))
        t, vt = _stretched(*_time_law(d, v, a), duration)
        dk = _sample_times(t, d, vt)
        radii = np.array([s.r for s in segs])
        pos, seg, frac = _blend_points(poses[:, :3], radii, lengths, dk)
        samples = np.hstack([pos, _blend_rotations(rots, radii, lengths, dk, seg, frac)])
        samples[-1] = poses[-1]
        q = inverse_path(self.model, samples, q0, tcp=self.tcp, allow_unreachable=True)
        fault = None
        bad = np.flatnonzero(np.isnan(q).any(axis=1))
        if len(bad):
            q = q[: bad[0]]
            fault = "movel: the path leaves the workspace (no inverse kinematics solution)"
        if len(q) == 0:
            raise MotionError(fault or "movel: empty path")
        outside = np.flatnonzero(((q < self.lower) | (q > self.upper)).any(axis=1))
        if len(outside):
            q = q[: outside[0]]
            fault = "movel: the path leaves the joint position limits"
        if not fault:
            # the last sample is the target: take the branch nearest the tracked path (exact pose)
            q[-1] = q_end + 2 * np.pi * np.round((q[-1] - q_end) / (2 * np.pi))
        return Trajectory(q if len(q) else np.array(q0, dtype=float)[None].copy(), _starts(dk, lengths), fault)

    def plan_stop(self, decel: float, linear: bool = False) -> Trajectory:
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
            return self._start(Trajectory(self.q[None].copy(), [0]))
        T = speed / decel
        K = max(1, math.ceil(T / DT - 1e-9))
        tk = np.minimum(np.arange(1, K + 1) * DT, T)[:, None]
        q = self.q + qd * tk - 0.5 * (qd / T) * tk**2
        return self._start(Trajectory(q, [0]), "stop", accel=False)

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
