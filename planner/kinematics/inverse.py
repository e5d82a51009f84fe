"""Closed-form inverse kinematics of UR arms (all 8 branches), vectorized, and branch tracking on paths.

Derivation (standard DH, T_i = Rz(q_i) Tz(d_i) Tx(a_i) Rx(alpha_i), alpha = (pi/2, 0, 0, pi/2, -pi/2, 0);
the steps follow K. P. Hawkins, "Analytic inverse kinematics for the Universal Robots UR-5/UR-10
arms" (2013) and R. S. Andersen, "Kinematics of a UR5" (Aalborg University, 2018), re-derived here so
that every quantity is computed from well-conditioned inputs):

- The wrist centre p5 = p6 - d6 z6 satisfies p5 . z1 = d4 with z1 = (sin q1, -cos q1, 0), so
  q1 = psi + asin(d4 / r) or psi + pi - asin(d4 / r), (r, psi) the polar coordinates of p5 in xy.
- The base-frame vector z1 expressed in the flange frame is (cos q6 sin q5, -sin q6 sin q5, cos q5),
  so with u = x6 . z1, v = y6 . z1, w = z6 . z1: q5 = atan2(+-hypot(u, v), w) and
  q6 = atan2(-v, u) (signs flipped on the q5 < 0 branch). At the wrist singularity (sin q5 = 0)
  only q234 + cos(q5) q6 is determined: q6 is set to a reference value (default 0) and q4 takes the
  rest, unless that leaves the wrist out of the elbow's reach; then (and also for |sin q5| < 1e-6,
  where atan2 for q6 is ill-conditioned) q234 and q6 are turned together to the nearest reachable
  angle (see ``_reachable_self_motion``).
- T14 = T01^-1 T06 T56^-1 T45^-1 = Rz(q2 + q3 + q4) Rx(pi/2) with origin
  (a2 cos q2 + a3 cos(q2 + q3), a2 sin q2 + a3 sin(q2 + q3), d4): q234 = q2 + q3 + q4 follows from the
  flange x and y axes (well defined also at the wrist singularity), and a planar 2R arm gives
  q3 = +-acos((x^2 + y^2 - a2^2 - a3^2) / (2 a2 a3)), q2 = atan2(y, x) - atan2(a3 sin q3, a2 + a3 cos q3),
  q4 = q234 - q2 - q3.

The sines and cosines of the angles found by atan2 / asin / acos are never evaluated by sin and cos:
they are the normalized arguments (cos atan2(y, x) = x / hypot(x, y), cos asin(s) = sqrt(1 - s^2),
sin acos(c) = sqrt((1 - c)(1 + c))), equal to round-off and several times cheaper. The solver works on
blocks of samples with the sample axis last (contiguous, cache-sized), so a path of 10^5 poses costs
a few microseconds per pose.

Candidates computed from clipped round-off (workspace boundary) or turned next to the wrist
singularity are checked by forward kinematics and discarded unless they reproduce the pose to 1e-9
(m and rad); elsewhere the formulas are exact and FK(IK(p)) = p holds to round-off (~1e-15).

One pose at a time (:func:`inverse`, :func:`inverse_nearest`: a controller loop), numpy's per-call
overhead dominates; those run the same derivation on Python floats in ``inverse_one`` (the one
documented exception to a single implementation, proven equal to the block solver by property tests)
and hand it back to the block solver for the few candidates that turn next to the wrist singularity.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from planner.errors import PlannerError
from planner.kinematics._checks import rows_of_six, six_floats
from planner.kinematics.errors import UnreachableError
from planner.kinematics.forward import compose, compose_1, flange_rp, invert_1
from planner.kinematics.inverse_one import solve_one
from planner.kinematics.poses import frame_matrix, pose_frame_1, pose_matrices_n, tcp_frame
from planner.kinematics.ur_models import URModel, get_model
from planner.validation import as_floats

__all__ = ["IKSolutions", "inverse", "inverse_batch", "inverse_frames", "inverse_nearest", "inverse_path",
           "wrap_angle"]

from planner.kinematics._tolerances import BOUNDARY_TOL as _BOUNDARY_TOL
from planner.kinematics._tolerances import INV_TWO_PI as _INV_TWO_PI
from planner.kinematics._tolerances import POS_TOL as _POS_TOL
from planner.kinematics._tolerances import ROT_TOL as _ROT_TOL
from planner.kinematics._tolerances import SAME_SOLUTION as _SAME_SOLUTION
from planner.kinematics._tolerances import TWO_PI as _TWO_PI
from planner.kinematics._tolerances import WRIST_NEAR as _WRIST_NEAR
from planner.kinematics._tolerances import WRIST_SINGULAR as _WRIST_SINGULAR
from planner.kinematics._tolerances import wrap_1

# Samples per block: the solver's arrays and the branch comparisons of a block stay in cache.
_BLOCK = 4096
# Margin (rad) of the test that a branch's nearest successor is the same branch (see _next_branch).
_SAME_BRANCH_MARGIN = 1e-12
_SIGNS = np.array([1.0, -1.0])


def wrap_angle(x) -> np.ndarray:
    """Angles wrapped into (-pi, pi] (a new array; NaN stays NaN: a joint without a solution)."""
    x = as_floats(x, "x")
    if np.isinf(x).any():
        raise PlannerError(f"x: angles must be finite (NaN passes), got {x[np.isinf(x)][0]}")
    return _wrap(x)


def _wrap(x: np.ndarray) -> np.ndarray:
    """:func:`wrap_angle` of a float array the solver made (finite or NaN: not checked)."""
    w = np.subtract(x, _TWO_PI * np.round(x * _INV_TWO_PI), out=np.empty_like(x))
    # round(x / 2 pi) may leave w a rounding error outside (-pi, pi]: one step back covers it
    np.add(w, _TWO_PI, out=w, where=w <= -np.pi)
    np.subtract(w, _TWO_PI, out=w, where=w > np.pi)
    return w


@dataclass(frozen=True)
class IKSolutions:
    """All eight closed-form branches for n poses.

    Branch ``b = 4 * i1 + 2 * i5 + i3`` takes the ``i1``-th shoulder solution (0: psi + asin(d4/r),
    1: psi + pi - asin(d4/r)), the ``i5``-th wrist solution (0: q5 >= 0, 1: q5 <= 0) and the
    ``i3``-th elbow solution (0: q3 >= 0, 1: q3 <= 0).

    Attributes
    ----------
    q : ndarray, shape (n, 8, 6)
        Joint positions in rad, wrapped to (-pi, pi]; NaN where ``valid`` is False.
    valid : ndarray of bool, shape (n, 8)
        The branch exists and reproduces the pose.
    within_limits : ndarray of bool, shape (n, 8)
        Valid and inside the model's joint position limits (as wrapped values).
    singular : ndarray of bool, shape (n, 8)
        Wrist singularity (|sin q5| < 1e-12): q6 was set to its reference value, or as near to it
        as the elbow's reach allows.
    """

    q: np.ndarray
    valid: np.ndarray
    within_limits: np.ndarray
    singular: np.ndarray


def _flange_targets(m: URModel, poses: np.ndarray, tcp) -> np.ndarray:
    """Flange transforms (n, 4, 4) of validated tool poses (n, 6): T_tool T_tcp^-1."""
    T = pose_matrices_n(poses)
    frame = tcp_frame(tcp)
    if frame is not None:
        T[:, :3, :3], T[:, :3, 3] = compose(T[:, :3, :3], T[:, :3, 3], *invert_1(*frame))
    return T


def _flange_target_1(pose: list[float], tcp):
    """:func:`_flange_targets` of one validated pose (6 floats): rotation entries row by row, origin."""
    R, p = pose_frame_1(pose)
    frame = tcp_frame(tcp)
    return (R, p) if frame is None else compose_1(R, p, *invert_1(*frame))


@dataclass(frozen=True)
class _Branches:
    """The solver's own layout of all 8 branches for n poses (sample axis last, contiguous rows).

    ``q`` (6, 8, n): joint, branch, sample (rad, wrapped; NaN where not valid); ``valid`` and
    ``singular`` (8, n): as in :class:`IKSolutions`, branch by sample.
    """

    q: np.ndarray
    valid: np.ndarray
    singular: np.ndarray

    def public(self, m: URModel) -> IKSolutions:
        """The same solutions as :class:`IKSolutions` (sample-major arrays)."""
        q = np.ascontiguousarray(self.q.transpose(2, 1, 0))
        valid = np.ascontiguousarray(self.valid.T)
        if (m.lower <= -np.pi).all() and (m.upper >= np.pi).all():
            within = valid.copy()  # wrapped angles lie in (-pi, pi]: inside such limits
        else:
            within = valid & ((q >= m.lower) & (q <= m.upper)).all(axis=-1)
        return IKSolutions(q=q, valid=valid, within_limits=within, singular=np.ascontiguousarray(self.singular.T))


def _solve(m: URModel, T: np.ndarray, q6_ref: np.ndarray) -> _Branches:
    """All branches for flange transforms T (n, 4, 4); q6_ref (n,) used at wrist singularities."""
    n = len(T)
    # declared as plain arrays: reshaped to (6, 8, n) and (8, n) below
    q: np.ndarray = np.empty((6, 2, 2, 2, n))
    valid: np.ndarray = np.empty((2, 2, 2, n), dtype=bool)
    singular: np.ndarray = np.empty((2, 2, 2, n), dtype=bool)
    clipped: np.ndarray = np.empty((2, 2, 2, n), dtype=bool)
    for a in range(0, n, _BLOCK):
        b = min(a + _BLOCK, n)
        _solve_block(m, T[a:b], q6_ref[a:b], q[..., a:b], valid[..., a:b], singular[..., a:b], clipped[..., a:b])
    q, valid, singular, clipped = q.reshape(6, 8, n), valid.reshape(8, n), singular.reshape(8, n), clipped.reshape(8, n)

    # Where round-off was clipped at the workspace boundary, or q4, q6 were turned next to the wrist
    # singularity, keep only candidates that reproduce the pose (elsewhere the formulas are exact
    # identities; tests check FK(IK(p)) = p).
    check = np.flatnonzero(valid & clipped)  # branch * n + sample
    if len(check):
        br, rows = np.divmod(check, n)
        R_chk, p_chk = flange_rp(m, q[:, br, rows].T)
        pos_err = np.linalg.norm(p_chk - T[rows, :3, 3], axis=-1)
        rot_err = np.linalg.norm(R_chk - T[rows, :3, :3], axis=(-1, -2)) / np.sqrt(2.0)  # ~ angle (rad)
        valid.reshape(-1)[check] = (pos_err <= _POS_TOL) & (rot_err <= _ROT_TOL)
    np.copyto(q, np.nan, where=~valid)
    return _Branches(q=q, valid=valid, singular=singular & valid)


def _solve_block(m: URModel, T, q6_ref, q_out, valid_out, singular_out, clipped_out) -> None:
    """The branches of one block of flange transforms T (k, 4, 4), written into the ``*_out`` arrays
    ((6, 2, 2, 2, k) wrapped joints by shoulder, wrist and elbow solution; (2, 2, 2, k) masks; clipped:
    candidates to verify by forward kinematics).

    Arrays here put the sample axis last: (k,), shoulder (2, k), shoulder x wrist (2, 2, k) and
    shoulder x wrist x elbow (2, 2, 2, k), so every operation runs over contiguous memory."""
    C = np.ascontiguousarray(T[:, :3, :].transpose(1, 2, 0))  # (3, 4, k): C[i, j] = T[:, i, j]
    x6, y6, z6, p = C[:, 0], C[:, 1], C[:, 2], C[:, 3]  # (3, k) each: columns of R and the origin
    sg2 = _SIGNS[:, None]  # (2, 1): + / - branch on the next axis

    # Shoulder: wrist centre p5 . z1 = d4 (Hawkins 2013, eq. for theta1).
    p5x, p5y = p[0] - m.d6 * z6[0], p[1] - m.d6 * z6[1]
    r = np.hypot(p5x, p5y)  # (the one-pose solver calls numpy's hypot too: math.hypot rounds differently)
    psi = np.arctan2(p5y, p5x)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = m.d4 / r
        r_safe = np.where(r > 0.0, r, 1.0)  # r = 0: psi = 0 as atan2 gives (the branch is invalid)
    cpsi, spsi = np.where(r > 0.0, p5x / r_safe, 1.0), p5y / r_safe
    ok1 = ratio <= 1.0 + _BOUNDARY_TOL  # False also for r = 0 (ratio inf)
    sb = np.clip(ratio, -1.0, 1.0)  # sin beta
    beta = np.arcsin(sb)
    cb = np.sqrt((1.0 - sb) * (1.0 + sb))  # cos beta >= 0
    q1 = np.stack([psi + beta, psi + np.pi - beta])  # (2, k)
    # cos, sin of psi + beta and psi + pi - beta by the angle-sum formulas
    c1 = np.stack([cpsi * cb - spsi * sb, -(cpsi * cb + spsi * sb)])
    s1 = np.stack([spsi * cb + cpsi * sb, cpsi * sb - spsi * cb])

    # Wrist: z1 in the flange frame is (cos q6 sin q5, -sin q6 sin q5, cos q5).
    u = x6[0] * s1 - x6[1] * c1  # (2, k)
    v = y6[0] * s1 - y6[1] * c1
    w = z6[0] * s1 - z6[1] * c1
    h = np.sqrt(u * u + v * v)  # |sin q5|, exact from the rotation (no sqrt(1 - cos^2) cancellation)
    q5 = np.arctan2(sg2 * h[:, None], w[:, None])  # (2, 2, k)
    s5 = sg2 * (h / np.sqrt(h * h + w * w))[:, None]  # sin q5
    sing = h < _WRIST_SINGULAR  # (2, k)
    with np.errstate(divide="ignore", invalid="ignore"):
        q6 = np.arctan2(-sg2 * v[:, None], sg2 * u[:, None])  # (2, 2, k)
        c6 = sg2 * (u / h)[:, None]  # cos and sin of that atan2
        s6 = -sg2 * (v / h)[:, None]
    if sing.any():
        sing3 = np.broadcast_to(sing[:, None], q6.shape)
        ref = np.broadcast_to(q6_ref, q6.shape)
        q6 = np.where(sing3, ref, q6)
        c6 = np.where(sing3, np.cos(ref), c6)
        s6 = np.where(sing3, np.sin(ref), s6)

    # Planar 2R arm in frame 1 (T14 = T01^-1 T06 T56^-1 T45^-1, written out): with x1 = (c1, s1, 0),
    # y1 = (0, 0, 1), the flange x/y axes give (-s234, c234) = s6 x6_1 + c6 y6_1 (first two entries),
    # and the frame-4 origin is p6_1 - (-d6 s5 c234 + d5 s234, -d6 s5 s234 - d5 c234).
    x6x = (x6[0] * c1 + x6[1] * s1)[:, None]  # (2, 1, k): x1 components; the y1 components are x6[2]
    y6x = (y6[0] * c1 + y6[1] * s1)[:, None]
    Y = -(s6 * x6x + c6 * y6x)  # sin q234
    X = s6 * x6[2] + c6 * y6[2]  # cos q234
    q234 = np.arctan2(Y, X)  # (2, 2, k)
    nrm = np.sqrt(X * X + Y * Y)
    c234, s234 = X / nrm, Y / nrm
    px = (p[0] * c1 + p[1] * s1)[:, None]  # (2, 1, k)
    pz = p[2] - m.d1  # (k,)
    adjusted = np.zeros(q5.shape, dtype=bool)
    near = h < _WRIST_NEAR
    turned = sing.any()
    if near.any():
        near3 = np.broadcast_to(near[:, None], q5.shape)
        c5 = np.sign(w)[:, None]
        q234, q6, adjusted = _reachable_self_motion(m, q234, q6, s5, c5, near3, px, pz)
        if adjusted.any():
            turned = True
            c6, s6 = np.where(adjusted, np.cos(q6), c6), np.where(adjusted, np.sin(q6), s6)
            c234, s234 = np.where(adjusted, np.cos(q234), c234), np.where(adjusted, np.sin(q234), s234)
    x = px + m.d6 * s5 * c234 - m.d5 * s234  # (2, 2, k)
    y = pz + m.d6 * s5 * s234 + m.d5 * c234
    cos3 = (x * x + y * y - m.a2**2 - m.a3**2) / (2.0 * m.a2 * m.a3)
    ok3 = np.abs(cos3) <= 1.0 + _BOUNDARY_TOL
    c3 = np.clip(cos3, -1.0, 1.0)
    t3 = np.arccos(c3)  # q3 = +-t3
    s3 = np.sqrt((1.0 - c3) * (1.0 + c3))  # sin t3 >= 0
    phi = np.arctan2(y, x)
    gam = np.arctan2(m.a3 * s3, m.a2 + m.a3 * c3)  # atan2(a3 sin q3, a2 + a3 cos q3) = +-gam (odd in y)

    # Joints wrapped to (-pi, pi] as they are written: atan2, acos and asin give [-pi, pi] or (-3 pi, 3 pi)
    # (q1: psi +- asin, q2: a difference of atan2, q4 = q234 - q2 - q3), q6 any value where it was set.
    q_out[0] = _wrap(q1)[:, None, None]
    q2 = np.stack([phi - gam, phi + gam], axis=2)  # (2, 2, 2, k): shoulder, wrist, elbow
    q_out[1] = _wrap(q2)
    q3 = q_out[2]
    q3[:, :, 0], q3[:, :, 1] = t3, -t3
    _pi_not_minus_pi(q3)
    q_out[3] = _wrap(q234[:, :, None] - q2 - q3)
    q_out[4] = _pi_not_minus_pi(q5)[:, :, None]
    q_out[5] = (_wrap(q6) if turned else _pi_not_minus_pi(q6))[:, :, None]
    valid_out[...] = (ok1 & ok3)[:, :, None]
    singular_out[...] = sing[:, None, None]
    clipped_out[...] = ((np.abs(ratio) > 1.0) | (np.abs(cos3) > 1.0) | adjusted)[:, :, None]


def _pi_not_minus_pi(x: np.ndarray) -> np.ndarray:
    """Angles in [-pi, pi] moved into (-pi, pi] in place (-pi becomes pi exactly); returns x."""
    np.add(x, _TWO_PI, out=x, where=x <= -np.pi)
    return x


def _reachable_self_motion(m: URModel, q234, q6, s5, c5, near, cx, cy):
    """At (or next to) the wrist singularity, turn q234 and q6 together so the elbow reaches.

    With sin q5 = 0 only q234 + cos(q5) q6 is fixed (next to it, nearly so), and the frame-4
    origin c + Rz(q234) (d6 sin q5, d5) circles the wrist centre c = (cx, cy) (frame 1, relative to
    the shoulder) at radius rho = hypot(d5, d6 sin q5). Its distance from the shoulder must lie in
    [| |a2| - |a3| |, |a2| + |a3|]; if q6 (the reference value, or an ill-conditioned atan2 when
    sin q5 is tiny) puts it outside, q234 moves to the nearest angle inside and q6 by -cos(q5)
    times as much. Returns (q234, q6, adjusted mask); callers verify adjusted candidates by FK.
    """
    cx, cy = np.broadcast_to(cx, q234.shape), np.broadcast_to(cy, q234.shape)
    rc = np.hypot(cx, cy)
    rho = np.hypot(m.d5, m.d6 * s5)
    alpha = np.arctan2(cy, cx) - np.arctan2(m.d5, m.d6 * s5)  # q234 pointing the offset outwards
    reach_in, reach_out = abs(abs(m.a2) - abs(m.a3)), abs(m.a2) + abs(m.a3)
    with np.errstate(divide="ignore", invalid="ignore"):
        lo = (reach_in**2 - rc**2 - rho**2) / (2.0 * rho * rc)  # bounds on cos(q234 - alpha)
        hi = (reach_out**2 - rc**2 - rho**2) / (2.0 * rho * rc)
        tol = _BOUNDARY_TOL
        feasible = (lo <= hi + tol) & (hi >= -1.0 - tol) & (lo <= 1.0 + tol)  # False on NaN (rc = 0)
    lo = np.clip(lo, -1.0, 1.0)
    hi = np.maximum(np.clip(hi, -1.0, 1.0), lo)
    delta = wrap_angle(q234 - alpha)
    k = np.cos(delta)
    adjust = near & feasible & ((k < lo) | (k > hi))
    if not adjust.any():
        return q234, q6, adjust
    k = np.where(adjust, np.clip(k, lo, hi), k)
    new = alpha + np.where(delta >= 0, 1.0, -1.0) * np.arccos(k)
    return np.where(adjust, new, q234), np.where(adjust, q6 + c5 * (q234 - new), q6), adjust


def _q6_reference(q6_ref, n: int) -> np.ndarray:
    ref = np.broadcast_to(np.asarray(q6_ref, dtype=float), (n,)) if np.ndim(q6_ref) == 0 else None
    if ref is None:
        ref = np.asarray(q6_ref, dtype=float)
        if ref.shape != (n,):
            raise PlannerError(f"q6_ref: expected a number or shape ({n},), got shape {ref.shape}")
    if not np.isfinite(ref).all():
        raise PlannerError(f"q6_ref[{int(np.argmin(np.isfinite(ref)))}] is not finite")
    return ref


def inverse_batch(model: str | URModel, poses, tcp=None, q6_ref=0.0) -> IKSolutions:
    """All eight inverse kinematics branches for many poses at once.

    Parameters
    ----------
    model : str or URModel
    poses : array_like, shape (6,) or (n, 6), or (n, 4, 4)
        Tool poses ``[x, y, z, rx, ry, rz]`` (m, rotation vector) in the base frame, or their homogeneous
        transforms (rotation orthonormal to 1e-9; a planner that holds frames as matrices skips the rotation
        vectors both ways).
    tcp : array_like, shape (6,), optional
        Tool-centre-point offset in the flange frame (the poses are TCP poses).
    q6_ref : float or array_like (n,), optional
        Value of q6 (rad) used where the wrist is singular (sin q5 = 0), where only q4 + q6 is
        determined.

    Returns
    -------
    IKSolutions
        Arrays of shape (n, 8, 6) and (n, 8) (n = 1 for a single pose). Invalid branches are
        flagged in ``valid`` and filled with NaN; joint limits are flagged in ``within_limits``.
    """
    m = get_model(model)
    if np.ndim(poses) == 3:
        T = _transforms(poses, tcp)
        return _solve(m, T, _q6_reference(q6_ref, len(T))).public(m)
    P, _ = rows_of_six(poses, "pose")
    return _solve(m, _flange_targets(m, P, tcp), _q6_reference(q6_ref, len(P))).public(m)


def inverse_frames(model: str | URModel, p: np.ndarray, R: np.ndarray, tcp=None) -> tuple[np.ndarray, np.ndarray]:
    """All eight branches of tool frames the planner made itself, joint-major: for a search over many poses.

    The same solutions as :func:`inverse_batch` of the transforms (p, R) (q6 = 0 at a wrist singularity),
    without its checks of the input (the frames are orthonormal by construction: rotation-minimizing frames
    turned about their own axis) and without its re-arrangement to sample-major arrays.

    Parameters
    ----------
    model : str or URModel
    p : ndarray, shape (n, 3)
        Tool positions in the base frame, m.
    R : ndarray, shape (n, 3, 3)
        Tool rotations in the base frame (columns: the tool's x, y, z axes).
    tcp : array_like, shape (6,), optional
        Tool-centre-point offset in the flange frame.

    Returns
    -------
    q : ndarray, shape (6, 8, n)
        Joints (rad, wrapped to (-pi, pi]) by joint, branch (as :class:`IKSolutions`) and pose; NaN where not
        valid. ``q[:, b, i]`` is ``inverse_batch(...).q[i, b]`` bit for bit.
    valid : ndarray of bool, shape (8, n)
    """
    m = get_model(model)
    n = len(p)
    T = np.zeros((n, 4, 4))
    T[:, 3, 3] = 1.0
    frame = tcp_frame(tcp)
    if frame is None:
        T[:, :3, :3], T[:, :3, 3] = R, p
    else:
        T[:, :3, :3], T[:, :3, 3] = compose(np.ascontiguousarray(R, dtype=float), np.asarray(p, dtype=float),
                                            *invert_1(*frame))
    sol = _solve(m, T, np.zeros(n))
    return sol.q, sol.valid


_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def _transforms(poses, tcp) -> np.ndarray:
    """Flange transforms (n, 4, 4) of tool transforms (n, 4, 4), checked: finite, the rotations orthonormal."""
    T = as_floats(poses, "pose")
    if T.shape[1:] != (4, 4):
        raise PlannerError(f"pose: expected transforms of shape (n, 4, 4), got {T.shape}")
    bad = ~np.isfinite(T).all(axis=(1, 2))
    if bad.any():
        raise PlannerError(f"pose[{int(np.argmax(bad))}]: every entry of a transform must be finite")
    R = T[:, :3, :3]
    c = [R[:, :, i] for i in range(3)]  # the columns: orthonormal, and c0 x c1 = c2 (proper)
    err = np.abs(np.stack([np.einsum("ij,ij->i", c[i], c[j]) - (i == j) for i, j in _PAIRS])).max(axis=0)
    bad = (err > 1e-9) | (np.einsum("ij,ij->i", np.cross(c[0], c[1]), c[2]) <= 0.0)
    if bad.any():
        i = int(np.argmax(bad))
        raise PlannerError(f"pose[{i}]: the rotation of a transform must be orthonormal and proper "
                           f"(error {err[i]:.3g})")
    out = np.zeros_like(T)
    out[:, 3, 3] = 1.0
    frame = tcp_frame(tcp)
    if frame is None:
        out[:, :3, :] = T[:, :3, :]
    else:
        out[:, :3, :3], out[:, :3, 3] = compose(np.ascontiguousarray(R), T[:, :3, 3], *invert_1(*frame))
    return out


class _Limits:
    """A model's joint limits as Python floats, for the one-pose functions (built once per model)."""

    _cache: dict[int, tuple[URModel, _Limits]] = {}

    def __init__(self, m: URModel):
        self.lower, self.upper = list(m.q_min), list(m.q_max)
        self.multiturn = [bool(t) for t in m.multiturn]
        # wrapped angles lie in (-pi, pi]: inside such limits (as in _Branches.public)
        self.wide = all(lo <= -np.pi for lo in self.lower) and all(hi >= np.pi for hi in self.upper)

    @classmethod
    def of(cls, m: URModel) -> _Limits:
        hit = cls._cache.get(id(m))
        if hit is None or hit[0] is not m:
            if len(cls._cache) > 64:
                cls._cache.clear()
            hit = cls._cache[id(m)] = (m, cls(m))
        return hit[1]

    def within(self, q) -> bool:
        """Wrapped joints q inside the limits."""
        return self.wide or all(lo <= v <= hi for lo, v, hi in zip(self.lower, q, self.upper, strict=True))

    def nearest(self, sols, q_near: list[float]) -> list[float] | None:
        """Of the branches ``sols`` (wrapped joints or None), the one nearest to ``q_near`` in joint space,
        each placed by whole turns on the multiturn joints as near to ``q_near`` as the limits allow
        (one turn back towards the range where the nearest lies beyond a limit); None if no branch
        fits the limits. The first in branch order wins a tie.

        A branch is dropped as soon as its partial distance reaches the best one; the joints that tell
        branches apart (q1, q5, q3) are summed first and the shoulder solution nearer in q1 is tried
        first, so most branches are dropped after a joint or two."""
        joints = [
            (j, q_near[j], wrap_1(q_near[j]), self.lower[j], self.upper[j], self.multiturn[j]) for j in _JOINT_ORDER
        ]
        first = sols[0] if sols[0] is not None else next((q for q in sols[:4] if q is not None), None)
        order: Sequence[int] = range(8)
        if first is not None and any(q is not None for q in sols[4:]):
            other = next(q for q in sols[4:] if q is not None)
            n1 = joints[0][2]
            if abs(wrap_1(other[0] - n1)) < abs(wrap_1(first[0] - n1)):
                order = (4, 5, 6, 7, 0, 1, 2, 3)
        best: tuple[int, list[float]] | None = None
        best_d = math.inf
        for b in order:
            q = sols[b]
            if q is None:
                continue
            d2 = 0.0
            cand = [0.0] * 6
            for j, n, w, lo, hi, mt in joints:
                v = q[j]
                if mt:
                    dv = v - w  # in (-2 pi, 2 pi): wrapped by one turn at most
                    if dv > math.pi:
                        dv -= _TWO_PI
                    elif dv <= -math.pi:
                        dv += _TWO_PI
                    v = n + dv
                    if v > hi:
                        v -= _TWO_PI
                    elif v < lo:
                        v += _TWO_PI
                if not lo <= v <= hi:
                    break
                dv = v - n
                d2 += dv * dv
                if d2 > best_d or (best is not None and d2 == best_d and b > best[0]):
                    break
                cand[j] = v
            else:
                best, best_d = (b, cand), d2
        return None if best is None else best[1]


# Joints in the order that tells branches apart soonest: shoulder (q1), wrist (q5), elbow (q3) solution.
_JOINT_ORDER = (0, 4, 2, 1, 3, 5)


def _same_solution(a, b) -> bool:
    """Whether two wrapped solutions coincide (every |wrap(a_j - b_j)| <= _SAME_SOLUTION), testing first
    the joints that tell branches apart (q1, q5, q3). For a difference d of wrapped angles, |wrap(d)|
    is |d| or 2 pi - |d|."""
    lo, hi = _SAME_SOLUTION, _TWO_PI - _SAME_SOLUTION
    return not (
        lo < abs(a[0] - b[0]) < hi
        or lo < abs(a[4] - b[4]) < hi
        or lo < abs(a[2] - b[2]) < hi
        or lo < abs(a[1] - b[1]) < hi
        or lo < abs(a[3] - b[3]) < hi
        or lo < abs(a[5] - b[5]) < hi
    )


def _q6_reference_1(q6_ref) -> float:
    if isinstance(q6_ref, (float, int)) and math.isfinite(q6_ref):  # (np.float64 is a float)
        return float(q6_ref)
    return float(_q6_reference(q6_ref, 1)[0])


def _branches_one(m: URModel, pose: list[float], tcp, q6_ref: float):
    """The 8 branches (tuples of 6 wrapped joints or None) of one validated pose, and its flange target.

    :func:`inverse_one.solve_one` on Python floats; the block solver where that leaves the decision
    to it (turned candidates next to the wrist singularity)."""
    R, p = _flange_target_1(pose, tcp)
    sols = solve_one(m, R, p, q6_ref)
    if sols is None:
        b = _solve(m, frame_matrix(R, p)[None], np.array([q6_ref]))
        sols = [tuple(b.q[:, i, 0].tolist()) if b.valid[i, 0] else None for i in range(8)]
    return sols, (R, p)


def _one_pose(pose, function: str) -> list[float]:
    vals = six_floats(pose, "pose")
    if vals is None:
        raise PlannerError(
            f"pose: {function}() takes one pose of shape (6,), got {np.shape(pose)}; "
            "use inverse_batch() or inverse_path() for many poses"
        )
    return vals


def inverse(model: str | URModel, pose, tcp=None, q6_ref: float = 0.0) -> np.ndarray:
    """All closed-form inverse kinematics solutions of one pose.

    Computed on Python floats (``inverse_one``, about 15 us a call) with the block solver's formulas,
    branch order and singularity handling; it equals :func:`inverse_batch` to round-off.

    Parameters
    ----------
    model : str or URModel
        ``"ur3e"``, ``"ur5e"``, ``"ur10e"``, ``"ur16e"``, ``"ur20"`` or a :class:`URModel`.
    pose : array_like, shape (6,)
        Tool pose ``[x, y, z, rx, ry, rz]`` (m, rotation vector) in the base frame.
    tcp : array_like, shape (6,), optional
        Tool-centre-point offset in the flange frame.
    q6_ref : float, optional
        q6 (rad) used at a wrist singularity (sin q5 = 0), where only q4 + q6 is determined.

    Returns
    -------
    ndarray, shape (k, 6), 0 <= k <= 8
        Joint positions in rad wrapped to (-pi, pi], in branch order (see :class:`IKSolutions`).
        Solutions outside the model's joint limits are filtered out (never the case for the UR
        models, whose joints all cover +-2 pi); coinciding solutions (at singularities) are
        returned once. An unreachable pose gives k = 0; no row ever contains NaN.
    """
    m = get_model(model)
    sols, _ = _branches_one(m, _one_pose(pose, "inverse"), tcp, _q6_reference_1(q6_ref))
    limits = _Limits.of(m)
    keep: list[tuple[float, ...]] = []
    for q in sols:
        if q is None or not limits.within(q):
            continue
        for k in keep:
            if _same_solution(q, k):
                break
        else:
            keep.append(q)
    return np.array(keep) if keep else np.empty((0, 6))


def inverse_nearest(model: str | URModel, pose, q_near, tcp=None) -> np.ndarray:
    """The inverse kinematics solution of one pose nearest to the joints ``q_near`` (a controller's
    ``get_inverse_kin(pose, qnear)``).

    Every valid branch is placed by whole turns on the multiturn joints (all six on the UR e-Series)
    as near to ``q_near`` as the joint limits allow, as :func:`inverse_path` unwraps from its
    ``q_start``; the one at the least Euclidean joint-space distance is returned (the first in branch
    order on a tie). At a wrist singularity q6 is held at ``q_near``'s value. About 20 us a call.

    Parameters
    ----------
    model : str or URModel
    pose : array_like, shape (6,)
        Tool pose ``[x, y, z, rx, ry, rz]`` (m, rotation vector) in the base frame.
    q_near : array_like, shape (6,)
        Joint positions (rad), e.g. the current ones; may lie outside (-pi, pi].
    tcp : array_like, shape (6,), optional
        Tool-centre-point offset in the flange frame.

    Returns
    -------
    ndarray, shape (6,)
        Joint positions in rad, within the model's joint limits.

    Raises
    ------
    UnreachableError
        The pose has no solution (the message says why), or every solution lies outside the joint
        limits.
    """
    m = get_model(model)
    vals = _one_pose(pose, "inverse_nearest")
    qn = six_floats(q_near, "q_near")
    if qn is None:
        raise PlannerError(f"q_near: expected shape (6,), got {np.shape(q_near)}")
    sols, (R, p) = _branches_one(m, vals, tcp, wrap_1(qn[5]))
    best = _Limits.of(m).nearest(sols, qn)
    if best is None:
        if any(q is not None for q in sols):
            raise UnreachableError(f"every inverse kinematics solution lies outside the joint limits of {m.name}")
        raise UnreachableError(f"no inverse kinematics solution: {_why_unreachable(m, frame_matrix(R, p))}")
    return np.array(best)


def _why_unreachable(m: URModel, T: np.ndarray) -> str:
    """A short diagnosis for one flange transform that has no solution."""
    p5 = T[:3, 3] - m.d6 * T[:3, 2]
    r = float(np.hypot(p5[0], p5[1]))
    if r < m.d4:
        return (
            f"wrist centre {r:.4f} m from the base axis, closer than d4 = {m.d4} m "
            "(inside the shoulder cylinder)"
        )
    return f"out of reach of {m.name} (arm lengths |a2| + |a3| = {abs(m.a2) + abs(m.a3):.4f} m)"


def _joint_delta(a: np.ndarray, b: np.ndarray, multiturn: np.ndarray) -> np.ndarray:
    """b - a, wrapped to (-pi, pi] on the multiturn joints (which are unwrapped along paths)."""
    d = b - a
    return np.where(multiturn, wrap_angle(d), d)


def _branch_distances(d: np.ndarray, multiturn: np.ndarray) -> np.ndarray:
    """Joint-space distances (...) of differences d (6, ...) of wrapped solutions (|d| < 2 pi), changed
    in place: the multiturn joints count the shorter way round (one turn at most)."""
    for j in np.flatnonzero(multiturn):
        np.subtract(d[j], 2.0 * np.pi, out=d[j], where=d[j] > np.pi)
        np.add(d[j], 2.0 * np.pi, out=d[j], where=d[j] <= -np.pi)
    return np.sqrt(np.einsum("j...,j...->...", d, d))


def _separation(Q: np.ndarray, multiturn: np.ndarray) -> np.ndarray:
    """A lower bound (8, k) on the joint-space distance from each branch of a sample to its nearest other
    valid branch of the same sample (inf if there is none), for solutions Q (6, 8, k) from ``_solve``.

    Branches that differ in the shoulder solution differ in q1 at least; with the same shoulder, those
    that differ in the wrist solution differ in q5; with both the same, the two elbow solutions differ
    in q3. ``_solve`` gives q1 per shoulder solution and q5 per (shoulder, wrist) pair to all the
    branches that share them (NaN where not valid), so one difference per pair of classes bounds the
    distance of every pair of valid branches.
    """

    def apart(d: np.ndarray, j: int) -> np.ndarray:  # |d| in the joint's metric, inf where undefined
        d = np.abs(d)
        if multiturn[j]:
            d = np.minimum(d, 2.0 * np.pi - d)
        return np.where(np.isnan(d), np.inf, d)

    k = Q.shape[-1]
    q1 = Q[0].reshape(2, 4, k)
    q1 = np.fmax(np.fmax(q1[:, 0], q1[:, 1]), np.fmax(q1[:, 2], q1[:, 3]))  # per shoulder solution
    q5 = Q[4].reshape(2, 2, 2, k)
    q5 = np.fmax(q5[:, :, 0], q5[:, :, 1])  # per (shoulder, wrist)
    q3 = Q[2].reshape(2, 2, 2, k)
    bound = np.minimum(apart(q1[0] - q1[1], 0), apart(q5[:, 0] - q5[:, 1], 4)[:, None, None])  # (2, 1, 1, k)
    bound = np.minimum(bound, apart(q3[:, :, 0] - q3[:, :, 1], 2)[:, :, None])  # (2, 2, 1, k)
    return np.broadcast_to(bound, (2, 2, 2, k)).reshape(8, k)


def _next_branch(Q: np.ndarray, V: np.ndarray, multiturn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each sample i and branch b, the valid branch at i + 1 nearest in joint space.

    Q (6, 8, n) and V (8, n) come from ``_solve`` (see :func:`_separation`). Returns ``nxt`` (n-1, 8) int
    (-1 if sample i + 1 has no valid branch, or b is not valid at i) and its distance.

    Along a path the nearest successor of a branch is almost always the same branch: by the triangle
    inequality it is whenever the branch's step D(b_i, b_i+1) is less than half the distance from
    b_i+1 to every other branch at i + 1 (bounded below by :func:`_separation`). Only the samples where
    that test fails for some branch (next to singularities, where branches meet) compare all 8 x 8
    pairs; the result is the same as comparing all pairs everywhere.
    """
    n = Q.shape[-1]
    nxt = np.full((8, max(n - 1, 0)), -1)
    dist = np.full((8, max(n - 1, 0)), np.inf)
    same = np.arange(8)[:, None]
    full: list[np.ndarray] = []
    for i in range(0, n - 1, _BLOCK):  # blocks: the (6, 8, block) differences stay in cache
        j = min(i + _BLOCK, n - 1)
        D = _branch_distances(Q[:, :, i + 1 : j + 1] - Q[:, :, i:j], multiturn)  # (8, block): b_i to b_i+1
        stays = V[:, i + 1 : j + 1] & (2.0 * D + _SAME_BRANCH_MARGIN < _separation(Q[:, :, i + 1 : j + 1], multiturn))
        nxt[:, i:j] = np.where(stays, same, -1)
        dist[:, i:j] = np.where(stays, D, np.inf)
        settled = (stays | ~V[:, i:j]).all(axis=0)  # a branch not valid at i has no successor (-1, inf)
        full.append(i + np.flatnonzero(~settled))
    rows = np.concatenate(full) if full else np.zeros(0, dtype=np.int64)
    for a in range(0, len(rows), _BLOCK // 8):  # all 8 x 8 pairs where the test fails
        r = rows[a : a + _BLOCK // 8]
        D = _branch_distances(Q[:, None, :, r + 1] - Q[:, :, None, r], multiturn)  # (8 from, 8 to, rows)
        D = np.where(V[None, :, r + 1] & ~np.isnan(D), D, np.inf)
        best = np.argmin(D, axis=1)
        d = np.take_along_axis(D, best[:, None], axis=1)[:, 0]
        nxt[:, r] = np.where(np.isfinite(d), best, -1)
        dist[:, r] = d
    return nxt.T, dist.T


def _nearest(Q_row: np.ndarray, V_row: np.ndarray, q: np.ndarray, multiturn: np.ndarray) -> int:
    """The valid branch of one sample (Q_row (8, 6), V_row (8,)) nearest to joints q (6,)."""
    D = np.linalg.norm(_joint_delta(q, Q_row, multiturn), axis=-1)
    D = np.where(V_row & ~np.isnan(D), D, np.inf)
    return int(np.argmin(D))


def _follow(nxt: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Branch sequences (L, k) from ``start`` (k,) along transition maps ``nxt`` (L - 1, 8).

    Only the maps that are not the identity change a sequence: their prefix compositions
    f_i o ... o f_0 are built by a parallel (Hillis-Steele) scan in log2 steps, and each sample takes
    the composition of the maps before it; -1 (no valid successor) is absorbing.
    """
    L = len(nxt) + 1
    moves = np.flatnonzero((nxt != np.arange(8)).any(axis=1))  # transitions that are not the identity
    P = nxt[moves]
    shift = 1
    while shift < len(P):
        inner = P[:-shift]
        outer = np.take_along_axis(P[shift:], np.maximum(inner, 0), axis=1)
        P[shift:] = np.where(inner < 0, -1, outer)
        shift *= 2
    prefix = np.concatenate([start[None, :], P[:, start]], axis=0)  # after 0, 1, ... of those maps
    return prefix[np.searchsorted(moves, np.arange(L), side="left")]  # maps before sample i: moves < i


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Half-open index ranges [s, e) of the runs of True in a boolean array."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def _track(m: URModel, sol: _Branches, q_start: np.ndarray | None) -> np.ndarray:
    """Chosen branch per sample (n,), -1 where unreachable."""
    Q, V = sol.q, sol.valid
    multiturn = m.multiturn
    nxt, dist = _next_branch(Q, V, multiturn)
    runs = _runs(np.asarray(V.any(axis=0)))
    first = runs[0][0]
    if q_start is not None:
        starts = np.array([_nearest(Q[:, :, first].T, V[:, first], q_start, multiturn)])
    else:
        starts = np.flatnonzero(V[:, first])
    chains = np.full((Q.shape[-1], len(starts)), -1)
    cost = np.zeros(len(starts))
    cur = starts
    for k, (s, e) in enumerate(runs):  # one pass per run of reachable samples (gaps are rare)
        if k:  # leaving a gap: nearest solution to the last one reached before it
            last = runs[k - 1][1] - 1
            cur = np.array([_nearest(Q[:, :, s].T, V[:, s], Q[:, b, last], multiturn) for b in chains[last]])
        chains[s:e] = _follow(nxt[s : e - 1], cur)
        cost += np.take_along_axis(dist[s : e - 1], chains[s : e - 1], axis=1).sum(axis=0)
    return chains[:, int(np.argmin(cost))]  # least total joint travel


def inverse_path(
    model: str | URModel,
    poses,
    q_start=None,
    *,
    tcp=None,
    allow_unreachable: bool = False,
) -> np.ndarray:
    """Joint trajectory for a sequence of poses, staying on one continuous IK branch.

    Each sample takes the valid solution nearest (in joint space) to the previous sample's; on
    joints whose range exceeds 2 pi (all six on the UR e-Series) the result is unwrapped, so it is
    continuous and may leave (-pi, pi]. At a wrist singularity (sin q5 = 0, where only q4 + q6 is
    determined) q6 is interpolated from the neighbouring samples.

    Parameters
    ----------
    model : str or URModel
    poses : array_like, shape (n, 6)
        Tool poses ``[x, y, z, rx, ry, rz]`` (m, rotation vector) in the base frame, in path order.
    q_start : array_like, shape (6,), optional
        Current joint positions (rad): the first sample takes the solution nearest to it, unwrapped
        next to it. Without it, every branch of the first pose is followed and the one with least
        total joint travel is kept, shifted by whole turns to sit mid-range of the joint limits.
    tcp : array_like, shape (6,), optional
        Tool-centre-point offset in the flange frame.
    allow_unreachable : bool
        If False (default), raise on the first pose without a solution. If True, such samples are
        rows of NaN and tracking resumes after them (``check_reachability`` reports them).

    Returns
    -------
    ndarray, shape (n, 6)
        Joint positions in rad. Joint position limits are not enforced here (see
        :func:`planner.kinematics.check_reachability`).

    Raises
    ------
    UnreachableError
        With ``index`` the first sample that has no solution (unless ``allow_unreachable``).
    """
    m = get_model(model)
    P, single = rows_of_six(poses, "poses")
    n = len(P)
    if q_start is not None:
        qs, qs_single = rows_of_six(q_start, "q_start")
        if not qs_single:
            raise PlannerError(f"q_start: expected shape (6,), got {np.shape(q_start)}")
        q_start = qs[0]
    T = _flange_targets(m, P, tcp)
    sol = _solve(m, T, np.zeros(n))
    reach = sol.valid.any(axis=0)
    if not reach.all() and not allow_unreachable:
        i = int(np.argmin(reach))
        raise UnreachableError(f"no inverse kinematics solution: {_why_unreachable(m, T[i])}", i)
    if not reach.any():
        return np.full((n, 6), np.nan)

    chain = _track(m, sol, q_start)
    rows = np.flatnonzero(chain >= 0)
    sing = rows[sol.singular[chain[rows], rows]]
    if len(sing):
        # Wrist-singular samples fix only q4 + q6: re-solve them with q6 interpolated (in sample
        # index) between the nearest regular samples, held constant beyond the last one.
        q6 = sol.q[5, chain[rows], rows]
        is_sing = np.isin(rows, sing)
        if is_sing.all():
            ref = np.full(len(sing), 0.0 if q_start is None else float(wrap_angle(q_start[5])))
        else:
            ref = np.interp(sing, rows[~is_sing], np.unwrap(q6[~is_sing]))
        fixed = _solve(m, T[sing], ref)
        q_all, valid = sol.q.copy(), sol.valid.copy()
        q_all[..., sing], valid[:, sing] = fixed.q, fixed.valid
        sol = _Branches(q_all, valid, sol.singular)
        chain = _track(m, sol, q_start)
        rows = np.flatnonzero(chain >= 0)

    qw = sol.q[:, chain[rows], rows].T  # (r, 6) wrapped solutions on the reached samples
    mt = m.multiturn
    steps = _joint_delta(qw[:-1], qw[1:], mt)
    q0 = qw[0].copy()
    if q_start is not None:
        q0[mt] = q_start[mt] + wrap_angle(qw[0, mt] - q_start[mt])
    qu = q0 + np.concatenate([np.zeros((1, 6)), np.cumsum(steps, axis=0)])
    qu[:, ~mt] = qw[:, ~mt]
    if q_start is None:
        mid = 0.5 * (qu.min(axis=0) + qu.max(axis=0))
        turns = np.round((0.5 * (m.lower + m.upper) - mid) / (2.0 * np.pi))
        qu[:, mt] += 2.0 * np.pi * turns[mt]
    out = np.full((n, 6), np.nan)
    out[rows] = qu
    return out
