"""Rotation matrices to UR rotation vectors, vectorized and continuous along a sample sequence.

A UR pose stores the orientation as a rotation vector r = theta * axis. Each rotation has infinitely
many: (theta + 2 pi k) * axis for any integer k. ``scipy.spatial.transform.Rotation.as_rotvec`` picks
theta in [0, pi], so a motion through theta = pi flips r to the opposite side (a jump of about 2 pi).
Here the rotation vector continues the previous sample instead: the unit quaternions are made
sign-continuous (q and -q are the same rotation), and r = 2 atan2(|v|, w) v / |v| of q = (w, v) then
takes theta in [0, 2 pi]; a sample past pi gets (theta - 2 pi) * axis in scipy's terms. Passing
theta = 2 pi (possible after more than a full turn) is unwrapped by adding 2 pi k along the axis.

The base conversions (matrix <-> quaternion, quaternion -> rotation vector keeping the sign) are
:mod:`planner.rotations`; this module adds the UR continuity rule on top of them.
"""

from __future__ import annotations

import numpy as np

from planner.motion.limits import MotionInputError
from planner.rotations import matrix_to_quaternion, quaternion_to_rotvec
from planner.validation import ArgumentError, finite_floats

__all__ = ["continuous_quaternions", "continuous_rotvec", "rotvec_from_quaternions", "unwrap_rotvec"]


def _rows(values, name: str, row: tuple | None = None) -> np.ndarray:
    """Finite rows of the given shape ``(n, *row)`` (or one value when ``row`` is None), or MotionInputError."""
    try:
        a = finite_floats(values, name, None if row is None else (None, *row))
    except ArgumentError as exc:
        raise MotionInputError(exc.argument, str(exc).partition(": ")[2]) from None
    return a


def continuous_quaternions(q: np.ndarray, previous: np.ndarray | None = None) -> np.ndarray:
    """Quaternions (n, 4) with signs flipped so that consecutive ones have a non-negative dot product.

    The first follows ``previous`` (4,) if given, else has w >= 0 (scipy's convention).
    """
    q = np.array(q, dtype=float)
    if q.shape[0] == 0:
        return q
    ref = np.array([1.0, 0.0, 0.0, 0.0]) if previous is None else np.asarray(previous, dtype=float)
    first = -1.0 if q[0] @ ref < 0.0 else 1.0
    if previous is None and q[0, 0] == 0.0:
        first = 1.0
    step = np.where(np.einsum("ni,ni->n", q[1:], q[:-1]) < 0.0, -1.0, 1.0)
    sign = first * np.concatenate(([1.0], np.cumprod(step)))
    return q * sign[:, None]


def unwrap_rotvec(r: np.ndarray, previous: np.ndarray | None = None) -> np.ndarray:
    """Rotation vectors (n, 3) shifted by 2 pi k along their axis wherever the sequence jumps by > pi.

    The shift of each jump is the k in {-2, ..., 2} that brings the sample closest to its predecessor;
    it applies to the whole run up to the next jump. ``previous`` (3,) is the sample before r[0].
    """
    r = np.array(r, dtype=float)
    if r.shape[0] == 0:
        return r
    prev0 = r[0] if previous is None else np.asarray(previous, dtype=float)
    jump = np.linalg.norm(np.diff(np.vstack((prev0, r)), axis=0), axis=1) > np.pi
    idx = list(np.flatnonzero(jump))
    ks = np.arange(-2, 3, dtype=float)[:, None]
    for n_j, j in enumerate(idx):  # a handful per full turn of the tool: not per sample
        end = idx[n_j + 1] if n_j + 1 < len(idx) else r.shape[0]
        before = prev0 if j == 0 else r[j - 1]
        if np.linalg.norm(r[j] - before) <= np.pi:  # an earlier shift closed this jump already
            continue
        theta = np.linalg.norm(r[j:end], axis=1)
        axis = r[j:end] / np.where(theta > 0.0, theta, 1.0)[:, None]
        cand = r[j] + 2.0 * np.pi * ks * axis[0]
        k = float(ks[np.argmin(np.linalg.norm(cand - before, axis=1)), 0])
        r[j:end] += 2.0 * np.pi * k * axis
    return r


#: Below this w (theta > 2 acos(0.7) ~ 268 deg) the map q -> r gets steep enough for a sample-to-sample jump.
_W_STEEP = -0.7


def rotvec_from_quaternions(q: np.ndarray, previous_q: np.ndarray | None = None,
                            previous_r: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Continuous rotation vectors (n, 3) of unit quaternions (n, 4) along a sequence.

    Returns the rotation vectors and the sign-continuous quaternions. ``previous_q`` and
    ``previous_r`` are those of the sample before q[0] (to continue an earlier chunk).
    """
    q = continuous_quaternions(_rows(q, "q", (4,)), None if previous_q is None else _rows(previous_q, "previous_q"))
    r = quaternion_to_rotvec(q)
    # away from w = -1 the map is smooth and close samples stay close: unwrap only where it can matter
    shifted = previous_r is not None and float(np.linalg.norm(previous_r)) > 1.5 * np.pi
    if shifted or (q.shape[0] and q[:, 0].min() < _W_STEEP):
        r = unwrap_rotvec(r, previous_r)
    return r, q


def continuous_rotvec(R: np.ndarray, previous_q: np.ndarray | None = None,
                      previous_r: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Continuous rotation vectors (n, 3) of rotation matrices (n, 3, 3) along a sequence.

    Parameters
    ----------
    R : ndarray (n, 3, 3)
    previous_q, previous_r : ndarray (4,), (3,), optional
        Quaternion and rotation vector of the sample before R[0] (to continue an earlier chunk).

    Returns
    -------
    (r, q) : ndarray (n, 3), ndarray (n, 4)
        The rotation vectors and the sign-continuous quaternions.
    """
    return rotvec_from_quaternions(matrix_to_quaternion(_rows(R, "R", (3, 3))), previous_q, previous_r)
