"""UR's ``movej`` / ``movel`` / ``movep`` as the controller samples them, and the joint limits the samples are held to.

One definition for the simulated controller (:mod:`sim.motion`, which runs programs on it) and for the program
writer (:mod:`planner.export.job_script`, which checks every move it writes on it before a controller sees it):

- the time law: the time-optimal profile along the move's path under its speed ``v`` and acceleration ``a`` (a
  trapezoid for a single move, continuous speed through blends, slow enough through a blend that turning the
  path's direction there needs at most ``a`` too); ``movej`` parameterizes the joint-space path by its
  infinity-norm length, ``movel``/``movep`` by the tool's path length (rotation counted as the angle times
  :data:`ROTATION_RADIUS`); a move's ``t`` slows the whole profile down uniformly to last t;
- the samples: joint positions every control period :data:`DT`, blends as quadratic Bezier arcs (positions) and
  their analogue on rotations, the inverse kinematics along the tool path from the joints the move starts at;
- the limits: a sample's joint speed is its first difference over DT and its acceleration the second difference
  over DT^2, the move played from rest at the joints it starts from; beyond the model's speed limits
  (:attr:`URModel.speed_limits`) or :data:`JOINT_ACCEL_MAX` the controller stops the arm (a protective stop).

movej/movel/movep semantics: UR Script Manual (e-Series); shared/UR-PROTOCOLS.md does not cover them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from planner.kinematics.errors import UnreachableError
from planner.kinematics.forward import forward
from planner.kinematics.inverse import inverse_path
from planner.quaternion import conj
from planner.quaternion import mul as qmul
from planner.rotations import quaternion_to_rotvec, rotvec_to_quaternion

DT = 0.002  # control period (s), 500 Hz
#: Joint acceleration limit (rad/s^2) of every joint, beyond which the arm stops with a protective stop.
#: UR publishes no acceleration limits (the model tables hold none); this is the bound the controller accepts in a
#: move command, as ur_rtde 1.6.5 checks it (UR_JOINT_ACCELERATION_MAX, rtde_control_interface.h).
JOINT_ACCEL_MAX = 40.0
#: Relative tolerance on the joint acceleration limit before a protective stop (sampled trajectories).
ACCEL_TOLERANCE = 1e-3
#: Length (m) one radian of tool rotation counts for in a linear move's path length.
ROTATION_RADIUS = 0.1
#: Relative tolerance on the joint speed limits before a protective stop.
SPEED_TOLERANCE = 1e-6
#: Path grid spacing (m or rad) of the time law, and its sample bounds.
GRID_STEP = 5e-4
GRID_MIN, GRID_MAX = 16, 4000


class MotionError(Exception):
    """A motion command that cannot start (the message says why); the controller raises a protective stop."""


@dataclass
class Segment:
    """One move of a path: target (joints, or a tool pose for linear moves), speed, acceleration, blend."""

    target: np.ndarray
    v: float
    a: float
    r: float = 0.0


@dataclass
class MoveSamples:
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


def time_law(d: np.ndarray, vmax: np.ndarray, amax: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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


def corner_radii(radii: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Blend radius (m+1,) at every waypoint of a path of m segments, in the path parameter's units: the move's
    ``r`` into the waypoint clipped to half of either neighbouring segment; 0 at the ends and where the arm
    passes the waypoint unblended (``r`` 0, or a segment of length 0)."""
    r = np.zeros(len(lengths) + 1)
    if len(lengths) > 1:
        r[1:-1] = np.minimum(radii[:-1], 0.5 * np.minimum(lengths[:-1], lengths[1:]))
        r[1:-1][(lengths[:-1] <= 0) | (lengths[1:] <= 0)] = 0.0
    return np.maximum(r, 0.0)


def blend_points(W: np.ndarray, radii: np.ndarray, lengths: np.ndarray, d: np.ndarray):
    """Points of the polyline ``W`` (m+1, k) at polyline parameter ``d`` with corners blended.

    ``lengths`` (m,) are the segment lengths in the parameter's norm; returns (points (n, k),
    segment index (n,), fraction within the segment (n,)). Within ``r`` of waypoint j (:func:`corner_radii`) the
    point is on the quadratic Bezier arc from A = W_j - r u_j-1 over W_j to B = W_j + r u_j (u: the segments' unit
    directions) at w = (d - D_j + r) / 2r.
    """
    D = np.concatenate([[0.0], np.cumsum(lengths)])
    seg = np.clip(np.searchsorted(D, d, side="right") - 1, 0, len(lengths) - 1)
    frac = np.divide(d - D[seg], lengths[seg], out=np.ones_like(d), where=lengths[seg] > 0)
    frac = np.clip(frac, 0.0, 1.0)
    P = W[seg] + frac[:, None] * (W[seg + 1] - W[seg])
    zone, j, r, w = _blend_zone(D, corner_radii(radii, lengths), d)
    if len(zone):
        u0 = (W[j] - W[j - 1]) / lengths[j - 1][:, None]
        u1 = (W[j + 1] - W[j]) / lengths[j][:, None]
        A, B, w = W[j] - r[:, None] * u0, W[j] + r[:, None] * u1, w[:, None]
        P[zone] = (1 - w) ** 2 * A + 2 * w * (1 - w) * W[j] + w**2 * B
    return P, seg, frac


def _blend_zone(D: np.ndarray, corner_r: np.ndarray, d: np.ndarray):
    """(sample indices within a blend, their waypoint j, its radius r, the blend parameter w in [0, 1]) of path
    parameters ``d`` (n,), waypoints at ``D`` (m+1,) with blend radii ``corner_r`` (m+1,)."""
    if not (corner_r > 0.0).any():
        return np.zeros(0, int), np.zeros(0, int), np.zeros(0), np.zeros(0)
    j = np.clip(np.searchsorted(0.5 * (D[:-1] + D[1:]), d), 0, len(D) - 1)  # the nearest waypoint
    r = corner_r[j]
    zone = np.flatnonzero((r > 0.0) & (np.abs(d - D[j]) <= r))
    j, r = j[zone], r[zone]
    return zone, j, r, np.clip((d[zone] - D[j] + r) / (2.0 * r), 0.0, 1.0)


def _exp(r: np.ndarray) -> np.ndarray:
    """Unit quaternions (n, 4), scalar first, of rotation vectors (n, 3)."""
    return rotvec_to_quaternion(r)


def _log(q: np.ndarray) -> np.ndarray:
    """Rotation vectors (n, 3), angle in [0, pi], of unit quaternions (n, 4) (either sign)."""
    return quaternion_to_rotvec(np.where(q[:, :1] < 0.0, -q, q))


def blend_rotations(Q: np.ndarray, radii: np.ndarray, lengths: np.ndarray, d: np.ndarray, seg: np.ndarray,
                    frac: np.ndarray) -> np.ndarray:
    """Rotation vectors (n, 3) at path parameter ``d`` of a linear path through the orientations ``Q`` (m+1, 4)
    (unit quaternions, scalar first), with its corners blended as :func:`blend_points` blends the positions.

    On segment k the orientation is the slerp R_k exp(f e_k), e_k = log(R_k^-1 R_k+1), at the fraction f
    (``seg``, ``frac`` from :func:`blend_points`). Within ``r`` of waypoint j it is the quadratic Bezier curve
    on rotations from R_A (``r`` before the waypoint on segment j-1) over R_j to R_B (``r`` after it on segment
    j) by de Casteljau's construction with slerp, at w = (d - D_j + r) / 2r: with rho = r / length of each
    segment, R_j X(w), X = exp(a) exp(w log(exp(-a) exp(b))), a = (w - 1) rho_j-1 e_j-1, b = w rho_j e_j. It
    starts at R_A and ends at R_B with the segments' angular velocities (d/dw = 2 rho e), as the position arc
    starts and ends with the segments' velocities: the angular velocity is continuous through the blend.
    Quaternion products (:func:`planner.quaternion.mul`): scipy's Rotation composes ~10x slower per sample."""
    e = _log(qmul(conj(Q[:-1]), Q[1:]))  # (m, 3)
    out = _log(qmul(Q[seg], _exp(frac[:, None] * e[seg])))
    D = np.concatenate([[0.0], np.cumsum(lengths)])
    zone, j, r, w = _blend_zone(D, corner_radii(radii, lengths), d)
    if len(zone):
        a = _exp(((w - 1.0) * r / lengths[j - 1])[:, None] * e[j - 1])
        b = _exp((w * r / lengths[j])[:, None] * e[j])
        X = qmul(a, _exp(w[:, None] * _log(qmul(conj(a), b))))
        out[zone] = _log(qmul(Q[j], X))
    return out


def stretched(t: np.ndarray, v: np.ndarray, duration: float) -> tuple[np.ndarray, np.ndarray]:
    """The profile (times, speeds) of :func:`time_law` slowed down uniformly to last ``duration`` s (a move's
    ``t``; never faster than planned): times times c, speeds over c, accelerations over c^2, c = duration / T."""
    T = float(t[-1])
    if not (duration > T > 0.0):
        return t, v
    c = duration / T
    return t * c, v / c


def inf_norm(x: np.ndarray, axis: int) -> np.ndarray:
    return np.abs(x).max(axis=axis)


def corner_turns(parts: list[np.ndarray], lengths: np.ndarray, norm) -> np.ndarray:
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


def path_grid(lengths: np.ndarray, segs: list[Segment], turns: np.ndarray | None = None):
    """Parameter grid over the whole path, with per-sample speed and acceleration limits.

    The grid holds every waypoint; the speed limit is 0 at an interior waypoint without a blend (``r`` 0 on
    the move that ends there): the arm comes to rest there, as the controller stops at an unblended waypoint.
    Through a blend the speed is at most sqrt(2 a r / turn) (``turns`` from :func:`corner_turns`, r from
    :func:`corner_radii`): a blend turns the direction by ``turn`` over 2 r of the path parameter (the quadratic
    Bezier arc of :func:`blend_points`, whose second derivative is turn / 2r), so at speed v it accelerates the
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
        r = corner_radii(np.array([s.r for s in segs]), lengths)
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


def sample_times(t: np.ndarray, d: np.ndarray, v: np.ndarray, period: float = DT) -> np.ndarray:
    """Path parameter at every control period DT, 2 DT, ..., ending exactly at the path's end (``period``: another
    sample spacing, s, for a coarser look at the same profile).

    Exact for the profile of :func:`time_law` (constant acceleration between its grid points), so that the
    samples' second differences are the profile's acceleration (a linear interpolation in time would put the
    acceleration of a whole grid interval into single periods)."""
    T = float(t[-1])
    K = max(1, math.ceil(T / period - 1e-9))
    tk = np.minimum(np.arange(1, K + 1) * period, T)
    i = np.clip(np.searchsorted(t, tk, side="right") - 1, 0, len(t) - 2)
    h = t[i + 1] - t[i]
    tau = np.minimum(tk - t[i], h)
    acc = np.divide(v[i + 1] - v[i], h, out=np.zeros_like(h), where=h > 0)
    dk = d[i] + v[i] * tau + 0.5 * acc * tau * tau
    dk[-1] = d[-1]
    return np.minimum(dk, d[-1])


def segment_starts(dk: np.ndarray, lengths: np.ndarray) -> list[int]:
    D = np.concatenate([[0.0], np.cumsum(lengths)])
    return [int(np.searchsorted(dk, D[i], side="right")) for i in range(len(lengths))]


def _check_target(model, q: np.ndarray, what: str) -> None:
    if not np.isfinite(q).all():
        raise MotionError(f"{what}: joint target is not finite")
    lower, upper = model.lower, model.upper
    bad = np.flatnonzero((q < lower - 1e-9) | (q > upper + 1e-9))
    if len(bad):
        j = int(bad[0])
        raise MotionError(f"{what}: joint {j} target {q[j]:.4f} rad outside its limits [{lower[j]:.4f}, "
                          f"{upper[j]:.4f}]")


def joint_samples(model, q0: np.ndarray, segs: list[Segment], duration: float = 0.0,
                  period: float = DT) -> MoveSamples:
    """The samples of a (blended) joint-space move (``movej``) from joints ``q0`` through ``segs`` (targets are joints),
    lasting at least ``duration`` s (its ``t``). MotionError for a target outside the joint limits or a v or a <= 0."""
    W = np.vstack([q0] + [np.asarray(s.target, dtype=float) for s in segs])
    for i, s in enumerate(segs):
        _check_target(model, W[i + 1], f"movej target {i}")
        if not (s.v > 0 and s.a > 0):
            raise MotionError(f"movej target {i}: speed and acceleration must be > 0")
    lengths = np.abs(np.diff(W, axis=0)).max(axis=1)
    if lengths.sum() <= 0.0:
        return MoveSamples(np.array(q0, dtype=float)[None].copy(), [0] * len(segs))
    d, v, a = path_grid(lengths, segs, corner_turns([np.diff(W, axis=0)], lengths, inf_norm))
    t, vt = stretched(*time_law(d, v, a), duration)
    dk = sample_times(t, d, vt, period)
    q, _, _ = blend_points(W, np.array([s.r for s in segs]), lengths, dk)
    q[-1] = W[-1]
    return MoveSamples(q, segment_starts(dk, lengths))


def linear_path(P0: np.ndarray, segs: list[Segment], duration: float = 0.0,
                period: float = DT) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The tool poses of a (blended) linear move (``movel``/``movep``) from pose ``P0`` (6,) through ``segs`` (targets
    are poses) at every control period, lasting at least ``duration`` s (its ``t``): (poses (K, 6), path parameter
    (K,) of each, segment lengths (m,) in the path parameter, m). A move of length 0 has no samples (K = 0).
    MotionError for a target not finite or a v or a <= 0."""
    poses = np.vstack([P0] + [np.asarray(s.target, dtype=float) for s in segs])
    for i, s in enumerate(segs):
        if not np.isfinite(poses[i + 1]).all():
            raise MotionError(f"movel target {i}: pose is not finite")
        if not (s.v > 0 and s.a > 0):
            raise MotionError(f"movel target {i}: speed and acceleration must be > 0")
    Q = rotvec_to_quaternion(poses[:, 3:])
    turn = _log(qmul(conj(Q[:-1]), Q[1:]))  # each segment's rotation, in its start frame
    chord = np.diff(poses[:, :3], axis=0)
    lengths = np.maximum(np.linalg.norm(chord, axis=1), np.linalg.norm(turn, axis=1) * ROTATION_RADIUS)
    if lengths.sum() <= 0.0:
        return np.zeros((0, 6)), np.zeros(0), lengths
    # the angular velocity at a waypoint, before and after it, in the frame there: e_k-1 and e_k (the slerp
    # R_k-1 exp(f e_k-1) turns about e_k-1, which R_k-1 exp(e_k-1) = R_k leaves unchanged)
    d, v, a = path_grid(lengths, segs, corner_turns([chord, ROTATION_RADIUS * turn], lengths, np.linalg.norm))
    t, vt = stretched(*time_law(d, v, a), duration)
    dk = sample_times(t, d, vt, period)
    radii = np.array([s.r for s in segs])
    pos, seg, frac = blend_points(poses[:, :3], radii, lengths, dk)
    samples = np.hstack([pos, blend_rotations(Q, radii, lengths, dk, seg, frac)])
    samples[-1] = poses[-1]
    return samples, dk, lengths


def linear_samples(model, tcp, q0: np.ndarray, segs: list[Segment], duration: float = 0.0,
                   period: float = DT) -> MoveSamples:
    """The joint samples of a (blended) linear move from joints ``q0`` through ``segs`` (:func:`linear_path`), on the
    inverse-kinematics branch the arm is on; ``tcp`` the tool offset pose (6,) or None. Where the path leaves the
    workspace or the joint position limits the samples end and ``fault`` says so. MotionError for an unreachable
    target (before the arm moves)."""
    samples, dk, lengths = linear_path(forward(model, q0, tcp), segs, duration, period)
    poses_end = np.asarray(segs[-1].target, dtype=float)[None]
    try:  # the target itself must be reachable before the arm moves
        q_end = inverse_path(model, poses_end, q0, tcp=tcp)[0]
    except UnreachableError:
        raise MotionError("movel: target pose is not reachable (no inverse kinematics solution)") from None
    if not len(samples):
        return MoveSamples(np.array(q0, dtype=float)[None].copy(), [0] * len(segs))
    q = inverse_path(model, samples, q0, tcp=tcp, allow_unreachable=True)
    fault = None
    bad = np.flatnonzero(np.isnan(q).any(axis=1))
    if len(bad):
        q = q[: bad[0]]
        fault = "movel: the path leaves the workspace (no inverse kinematics solution)"
    if len(q) == 0:
        raise MotionError(fault or "movel: empty path")
    outside = np.flatnonzero(((q < model.lower) | (q > model.upper)).any(axis=1))
    if len(outside):
        q = q[: outside[0]]
        fault = "movel: the path leaves the joint position limits"
    if not fault:
        # the last sample is the target: take the branch nearest the tracked path (exact pose)
        q[-1] = q_end + 2 * np.pi * np.round((q[-1] - q_end) / (2 * np.pi))
    return MoveSamples(q if len(q) else np.array(q0, dtype=float)[None].copy(), segment_starts(dk, lengths), fault)


def joint_rates(q0: np.ndarray, q: np.ndarray, period: float = DT) -> tuple[np.ndarray, np.ndarray]:
    """Joint speeds (K, 6), rad/s, and accelerations (K, 6), rad/s^2, of the samples ``q`` (K, 6) of a move played
    every DT (``period``) from rest at ``q0`` (6,): row k is the speed reached at sample k (its first difference over
    DT) and the change of speed into it over DT (the second difference over DT^2)."""
    P = np.vstack([q0, q0, q])
    V = np.diff(P, axis=0) / period  # speed reached at each sample (0: at rest before the move)
    return V[1:], np.diff(V, axis=0) / period


def first_excess(model, q0: np.ndarray, q: np.ndarray, what: str, accel: bool = True) -> tuple[int, str | None]:
    """First sample of ``q`` (K, 6), played from rest at ``q0``, beyond the model's joint speed limits or (``accel``)
    :data:`JOINT_ACCEL_MAX` (each with its tolerance), and why (a message starting with ``what``); (-1, None) when
    none is."""
    qd_max = model.speed_limits
    V, A = joint_rates(q0, q)
    speed = np.abs(V) > qd_max * (1.0 + SPEED_TOLERANCE)
    over = speed | (np.abs(A) > JOINT_ACCEL_MAX * (1.0 + ACCEL_TOLERANCE)) if accel else speed
    bad = np.flatnonzero(over.any(axis=1))
    if not len(bad):
        return -1, None
    k = int(bad[0])
    if speed[k].any():
        j = int(np.argmax(np.abs(V[k]) / qd_max))
        return k, f"{what}: joint {j} speed {abs(V[k, j]):.3f} rad/s beyond its limit {qd_max[j]:.3f} rad/s"
    j = int(np.argmax(np.abs(A[k])))
    return k, f"{what}: joint {j} acceleration {abs(A[k, j]):.1f} rad/s^2 beyond the limit {JOINT_ACCEL_MAX:g} rad/s^2"
