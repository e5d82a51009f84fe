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
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from planner.errors import PlannerError

__all__ = [
    "RotationInputError",
    "matrix_to_quaternion",
    "matrix_to_rotvec",
    "quaternion_to_matrix",
    "quaternion_to_rotvec",
    "rotate_vectors",
    "rotation_angle",
    "rotvec_to_matrix",
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
