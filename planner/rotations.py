"""The one owner of rotation conversions: matrices, quaternions, rotation vectors, slerp.

Everything here is vectorized over leading axes and, unless stated otherwise, a thin layer over
``scipy.spatial.transform.Rotation`` (which, in scipy 1.17, is also the fastest way we measured:
bench/bench_frames.py, table 3). Conventions, shared by the whole planner:

- rotation matrices R (..., 3, 3) act on column vectors (v' = R v); a tool frame is a rotation whose
  columns are the frame's x, y, z axes in the base frame;
- quaternions q (..., 4) are laid out **scalar first**, q = (w, x, y, z), as in :mod:`planner.quaternion`
  (scipy's own default is scalar last; every call here passes ``scalar_first=True``);
- rotation vectors r (..., 3) are angle * unit axis (radians), the UR pose convention ``p[x, y, z, rx, ry, rz]``.

Sign rule. ``q`` and ``-q`` are the same rotation. :func:`matrix_to_quaternion` returns the canonical one:
w > 0, or, when w = 0 (a half turn), the first nonzero of x, y, z positive (scipy's ``canonical=True``).
Functions that take a quaternion accept either sign and do not normalize it away unless they say so
(:func:`quaternion_to_rotvec` keeps it, which is what the UR continuity rule of
:mod:`planner.motion.rotvec` builds on).

Hand-written exceptions (both measured faster than any scipy route in bench/bench_frames.py, table 3,
and tested against scipy in tests/test_rotations.py):

- :func:`quaternion_to_rotvec` keeps the sign of q, so its angle lies in [0, 2 pi]; scipy's ``as_rotvec``
  canonicalizes to [0, pi] (a jump of 2 pi in a pose stream) and costs ~15x more per sample (equal to
  scipy within 1e-12 for w >= 0);
- :func:`rotation_angle` (angle between two rotations) from the Frobenius distance, ~2.5x faster than
  forming R1^T R2 and asking scipy for its magnitude (equal within 1e-12 for small angles, see its
  docstring near pi).

The float path of the kinematics (:mod:`planner.kinematics`; the simulated controller converts one pose per
2 ms period, where scipy's per-call overhead of ~10 us does not fit): the two conversions UR poses need,
rotation vector -> matrix and matrix -> rotation vector, each written twice with the same operations in the
same order, so that the two give identical results:

- ``*_1`` for one rotation on Python floats (``math``), taking and returning flat tuples (a matrix as its
  9 entries row by row): :func:`rotvec_to_matrix_1`, :func:`matrix_to_rotvec_1`, a few microseconds a call
  against scipy's ~15;
- ``*_n`` for n rotations in numpy arrays (n, 3) / (n, 3, 3), no shape checks (the callers validated):
  :func:`rotvec_to_matrix_n`, :func:`matrix_to_rotvec_n`.

Both follow scipy's own formulas (quaternion from the rotation vector; Shepperd's choice of the largest
quaternion component from the matrix, canonical sign) and agree with scipy to 1e-12
(tests/test_kinematics_single.py); they are the path of forward and inverse kinematics, where one pose and a
batch holding it must give the same joints bit for bit. Everything else converts through the scipy functions.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from planner.errors import PlannerError

__all__ = [
    "RotationInputError",
    "matrix_to_quaternion",
    "matrix_to_rotvec",
    "matrix_to_rotvec_1",
    "matrix_to_rotvec_n",
    "quaternion_to_matrix",
    "quaternion_to_rotvec",
    "rotate_vectors",
    "rotation_angle",
    "rotvec_to_matrix",
    "rotvec_to_matrix_1",
    "rotvec_to_matrix_n",
    "rotvec_to_quaternion",
    "slerp_matrices",
]


class RotationInputError(PlannerError):
    """An array given to a rotation conversion has the wrong shape or is no rotation (zero quaternion)."""

    def __init__(self, name: str, message: str):
        self.name = name
        super().__init__(f"{name}: {message}")


def _array(a, name: str, tail: tuple[int, ...]) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.shape[a.ndim - len(tail):] != tail or a.ndim < len(tail):
        want = ", ".join(("...",) + tuple(str(t) for t in tail))
        raise RotationInputError(name, f"expected an array of shape ({want}), got shape {a.shape}")
    return a if a.flags.writeable else a.copy()  # scipy's Cython layer refuses read-only views (broadcast_to)


def matrix_to_quaternion(R) -> np.ndarray:
    """Unit quaternions (..., 4), scalar first (w, x, y, z), of rotation matrices R (..., 3, 3); canonical sign.

    w >= 0; for w = 0 the first nonzero of x, y, z is positive (the module's sign rule). R must be a
    rotation to round-off (as every frame the planner computes is; user frames are checked by their
    readers): it is not re-orthogonalized, the quaternion of a slightly perturbed R is that of
    Shepperd's / Markley's method, normalized (scipy ``from_matrix(..., assume_valid=True)``).
    """
    R = _array(R, "R", (3, 3))
    if R.size == 0:
        return np.zeros(R.shape[:-2] + (4,))
    return Rotation.from_matrix(R, assume_valid=True).as_quat(canonical=True, scalar_first=True)


def quaternion_to_matrix(q, out: np.ndarray | None = None) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions q (..., 4) (w, x, y, z), not necessarily unit.

    The rotation v -> q v q* / |q|^2 (q is normalized first; either sign gives the same matrix). Written
    into ``out`` (..., 3, 3) if given. A zero quaternion is no rotation: RotationInputError naming its index.
    """
    q = _array(q, "q", (4,))
    if q.size == 0:
        m = np.zeros(q.shape[:-1] + (3, 3))
    else:
        try:
            m = Rotation.from_quat(q, scalar_first=True).as_matrix()
        except ValueError:
            n2 = np.einsum("...i,...i->...", q, q)
            bad = np.argwhere(~(n2 > 0.0))
            where = f"q[{', '.join(str(int(i)) for i in bad[0])}]" if bad.size else "q"
            raise RotationInputError(where, "is a zero (or non-finite) quaternion, which is no rotation") from None
    if out is None:
        return m
    out[...] = m
    return out


def matrix_to_rotvec(R) -> np.ndarray:
    """Rotation vectors (..., 3) of rotation matrices R (..., 3, 3): angle in [0, pi] times unit axis.

    At exactly pi either of the two opposite vectors may come out. R must be a rotation to round-off
    (see :func:`matrix_to_quaternion`). For a rotation vector that continues a sequence (UR poses), see
    :func:`planner.motion.rotvec.continuous_rotvec`.
    """
    R = _array(R, "R", (3, 3))
    if R.size == 0:
        return np.zeros(R.shape[:-2] + (3,))
    return Rotation.from_matrix(R, assume_valid=True).as_rotvec()


def rotvec_to_matrix(r) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of rotation vectors r (..., 3) (angle |r|, any size, about r / |r|)."""
    r = _array(r, "r", (3,))
    if r.size == 0:
        return np.zeros(r.shape[:-1] + (3, 3))
    return Rotation.from_rotvec(r).as_matrix()


def rotvec_to_quaternion(r) -> np.ndarray:
    """The quaternions (..., 4) (cos(|r|/2), sin(|r|/2) r/|r|) of rotation vectors r (..., 3), any |r|.

    Not canonicalized: for |r| > pi the scalar part is negative, so that
    ``quaternion_to_rotvec(rotvec_to_quaternion(r)) == r`` for |r| < 2 pi (the sample before a chunk of
    a continuous UR pose stream can be restarted from its rotation vector alone).
    """
    r = _array(r, "r", (3,))
    if r.size == 0:
        return np.zeros(r.shape[:-1] + (4,))
    return Rotation.from_rotvec(r).as_quat(scalar_first=True)


def quaternion_to_rotvec(q) -> np.ndarray:
    """Rotation vectors (..., 3) of unit quaternions q (..., 4): 2 atan2(|v|, w) v / |v|, angle in [0, 2 pi].

    Hand-written exception (see the module docstring): the sign of q is kept, so q and -q give r and
    r - 2 pi r / |r| (the same rotation); with w >= 0 the result is scipy's ``as_rotvec``. q = +-1
    (v = 0) gives the zero vector. Near angle 2 pi (w -> -1) the axis v / |v| is ill-conditioned;
    :func:`planner.motion.rotvec.unwrap_rotvec` handles sequences that get there.
    """
    q = _array(q, "q", (4,))
    v = q[..., 1:]
    vn = np.sqrt(np.einsum("...i,...i->...", v, v))
    theta = 2.0 * np.arctan2(vn, q[..., 0])
    factor = np.divide(theta, vn, out=np.zeros_like(vn), where=vn > 0.0)
    return factor[..., None] * v


def rotation_angle(R1, R2) -> np.ndarray:
    """Angle (...) of the relative rotation R2 R1^T (equally R1^T R2), radians in [0, pi], for R1, R2 (..., 3, 3).

    Hand-written exception (see the module docstring): |R2 - R1|_F = 2 sqrt(2) sin(theta / 2), because
    R2 - R1 = (Q - I) R1 with Q a rotation by theta. Round-off in the entries (eps) makes the error about
    eps / cos(theta / 2): ~1e-16 rad for small angles (where the trace formula acos((tr - 1) / 2) loses
    half the digits, ~1e-8 rad), a few 1e-12 rad at pi - 1e-3, and up to ~1e-8 rad at pi itself. The
    planner uses it on small angles (orientation rates, deviations from a slerp).
    """
    R1 = _array(R1, "R1", (3, 3))
    R2 = _array(R2, "R2", (3, 3))
    d = R2 - R1
    f = np.linalg.norm(d.reshape(d.shape[:-2] + (9,)), axis=-1)
    return 2.0 * np.arcsin(np.clip(f / (2.0 * np.sqrt(2.0)), 0.0, 1.0))


def rotate_vectors(r, v) -> np.ndarray:
    """Vectors v (..., 3) rotated by the rotation vectors r (..., 3) (broadcast against each other)."""
    r = _array(r, "r", (3,))
    v = _array(v, "v", (3,))
    shape = np.broadcast_shapes(r.shape, v.shape)
    if 0 in shape:
        return np.zeros(shape)
    r, v = np.broadcast_to(r, shape).copy(), np.broadcast_to(v, shape).copy()
    return Rotation.from_rotvec(r).apply(v)


def slerp_matrices(R0, R1, s) -> np.ndarray:
    """Rotations (..., k, 3, 3) at fractions s (..., k) of the shortest slerps from R0 to R1 (..., 3, 3).

    R(s) = R0 exp(s log(R0^T R1)): constant angular velocity, the path a robot's linear move takes
    between two orientations (what scipy's ``Slerp`` does between two key rotations). s = 0 gives R0,
    s = 1 gives R1; s outside [0, 1] extrapolates. R0 and R1 broadcast against each other and s's
    leading axes; e.g. R0, R1 (3, 3) and s (k,) give (k, 3, 3).
    """
    R0 = _array(R0, "R0", (3, 3))
    R1 = _array(R1, "R1", (3, 3))
    s = np.asarray(s, dtype=float)
    if s.ndim == 0:
        raise RotationInputError("s", "expected an array of fractions of shape (..., k), got a scalar")
    w = matrix_to_rotvec(np.matmul(np.swapaxes(R0, -1, -2), R1))  # (..., 3)
    step = rotvec_to_matrix(s[..., None] * w[..., None, :])  # (..., k, 3, 3)
    return np.matmul(R0[..., None, :, :], step)


# ------------------------------------------------------------------------------------------------------------
# The float path of the kinematics (see the module docstring): *_1 on Python floats, *_n its numpy twin.
# ------------------------------------------------------------------------------------------------------------

# Below this angle (rad) the rotation vector of a quaternion uses the Taylor series of angle / sin(angle / 2).
_SMALL_ANGLE = 1e-3


def rotvec_to_matrix_n(r: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3) of rotation vectors r (n, 3) (axis times angle, rad); float path.

    The unit quaternion (sin(a / 2) / a * r, cos(a / 2)), a = |r|, turned into a matrix; entry for entry
    what :func:`rotvec_to_matrix_1` gives for each row.
    """
    rx, ry, rz = r[:, 0], r[:, 1], r[:, 2]
    a = np.sqrt(rx * rx + ry * ry + rz * rz)
    zero = a == 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(zero, 0.5, np.sin(0.5 * a) / a)  # sin(a / 2) / a, its limit 1/2 at a = 0
    return _quat_matrix(s * rx, s * ry, s * rz, np.cos(0.5 * a)).reshape(-1, 3, 3)


def rotvec_to_matrix_1(rx: float, ry: float, rz: float) -> tuple[float, ...]:
    """:func:`rotvec_to_matrix_n` of one rotation vector on Python floats; the 9 matrix entries row by row."""
    a = math.sqrt(rx * rx + ry * ry + rz * rz)
    s = 0.5 if a == 0.0 else math.sin(0.5 * a) / a
    return _quat_matrix(s * rx, s * ry, s * rz, math.cos(0.5 * a))


def _quat_matrix(x, y, z, w):
    """Entries (row by row) of the rotation matrix of the unit quaternion (x, y, z, w): floats or arrays."""
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    entries = (
        x2 - y2 - z2 + w2, 2.0 * (xy - zw), 2.0 * (xz + yw),
        2.0 * (xy + zw), -x2 + y2 - z2 + w2, 2.0 * (yz - xw),
        2.0 * (xz - yw), 2.0 * (yz + xw), -x2 - y2 + z2 + w2,
    )
    return np.stack(entries, axis=-1) if isinstance(x, np.ndarray) else entries


def matrix_to_rotvec_n(R: np.ndarray) -> np.ndarray:
    """Rotation vectors (n, 3), angle in [0, pi], of rotation matrices R (n, 3, 3); float path.

    Shepperd's method: the quaternion is computed from whichever of its four components is largest
    (chosen by the largest of the diagonal entries and the trace), normalized, and taken with w >= 0
    (at w = 0, with its first non-zero component positive), as scipy does; entry for entry what
    :func:`matrix_to_rotvec_1` gives for each matrix.
    """
    e = R.reshape(-1, 9)
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = (e[:, i] for i in range(9))
    tr = r00 + r11 + r22
    choice = np.argmax(np.stack([r00, r11, r22, tr], axis=-1), axis=-1)
    cases = (
        (1.0 - tr + 2.0 * r00, r10 + r01, r20 + r02, r21 - r12),
        (r10 + r01, 1.0 - tr + 2.0 * r11, r21 + r12, r02 - r20),
        (r20 + r02, r21 + r12, 1.0 - tr + 2.0 * r22, r10 - r01),
        (r21 - r12, r02 - r20, r10 - r01, 1.0 + tr),
    )
    x, y, z, w = (np.choose(choice, [c[i] for c in cases]) for i in range(4))
    n = np.sqrt(x * x + y * y + z * z + w * w)
    flip = (w < 0.0) | ((w == 0.0) & ((x < 0.0) | ((x == 0.0) & ((y < 0.0) | ((y == 0.0) & (z < 0.0))))))
    n = np.where(flip, -n, n)
    x, y, z, w = x / n, y / n, z / n, w / n
    angle = 2.0 * np.arctan2(np.sqrt(x * x + y * y + z * z), w)
    a2 = angle * angle
    small = angle <= _SMALL_ANGLE
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(small, 2.0 + a2 / 12.0 + 7.0 * a2 * a2 / 2880.0, angle / np.sin(0.5 * angle))
    return np.stack([scale * x, scale * y, scale * z], axis=-1)


def matrix_to_rotvec_1(r00, r01, r02, r10, r11, r12, r20, r21, r22) -> tuple[float, float, float]:
    """:func:`matrix_to_rotvec_n` of one matrix given by its 9 entries row by row, on Python floats.

    The arctangent is numpy's (on Python floats), so the result equals the vectorized one exactly.
    """
    tr = r00 + r11 + r22
    best, choice = r00, 0
    for i, d in ((1, r11), (2, r22), (3, tr)):  # the first largest, as argmax
        if d > best:
            best, choice = d, i
    if choice == 0:
        x, y, z, w = 1.0 - tr + 2.0 * r00, r10 + r01, r20 + r02, r21 - r12
    elif choice == 1:
        x, y, z, w = r10 + r01, 1.0 - tr + 2.0 * r11, r21 + r12, r02 - r20
    elif choice == 2:
        x, y, z, w = r20 + r02, r21 + r12, 1.0 - tr + 2.0 * r22, r10 - r01
    else:
        x, y, z, w = r21 - r12, r02 - r20, r10 - r01, 1.0 + tr
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if w < 0.0 or (w == 0.0 and (x < 0.0 or (x == 0.0 and (y < 0.0 or (y == 0.0 and z < 0.0))))):
        n = -n
    x, y, z, w = x / n, y / n, z / n, w / n
    angle = 2.0 * float(np.arctan2(math.sqrt(x * x + y * y + z * z), w))
    a2 = angle * angle
    scale = 2.0 + a2 / 12.0 + 7.0 * a2 * a2 / 2880.0 if angle <= _SMALL_ANGLE else angle / math.sin(0.5 * angle)
    return scale * x, scale * y, scale * z
