"""Rotation matrices to UR rotation vectors, vectorized and continuous along a sample sequence.

A UR pose stores the orientation as a rotation vector r = theta * axis. Each rotation has infinitely
many: (theta + 2 pi k) * axis for any integer k. ``scipy.spatial.transform.Rotation.as_rotvec`` picks
theta in [0, pi], so a motion through theta = pi flips r to the opposite side (a jump of about 2 pi).
Here the rotation vector continues the previous sample instead: the unit quaternions are made
sign-continuous (q and -q are the same rotation), and r = 2 atan2(|v|, w) v / |v| of q = (w, v) then
takes theta in [0, 2 pi]; a sample past pi gets (theta - 2 pi) * axis in scipy's terms. Passing
theta = 2 pi (possible after more than a full turn) is unwrapped by adding 2 pi k along the axis.

The conversion matrix -> quaternion is Shepperd's (J. Guidance and Control 1, 1978), written with
numpy for speed (scipy 1.17's ``Rotation.from_matrix`` + ``as_rotvec`` costs ~3.7 us per sample on
the project machine, more than the rest of the sampler); the tests compare it with scipy.
"""

from __future__ import annotations

import numpy as np


def matrix_to_quaternion(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (n, 4), (w, x, y, z), of rotation matrices (n, 3, 3); sign arbitrary.

    Shepperd's method: of 4 w^2, 4 x^2, 4 y^2, 4 z^2 (= 1 + tr, 1 + 2 R_ii - tr) take the largest,
    and divide the off-diagonal sums and differences by it (Shepperd 1978).
    """
    R = np.asarray(R, dtype=float)
    r00, r01, r02 = R[:, 0, 0], R[:, 0, 1], R[:, 0, 2]
    r10, r11, r12 = R[:, 1, 0], R[:, 1, 1], R[:, 1, 2]
    r20, r21, r22 = R[:, 2, 0], R[:, 2, 1], R[:, 2, 2]
    tr = r00 + r11 + r22
    diag = np.stack((tr, r00, r11, r22), axis=1)
    case = np.argmax(diag, axis=1)
    d21, d02, d10 = r21 - r12, r02 - r20, r10 - r01  # 4 w (x, y, z)
    s01, s02, s12 = r01 + r10, r02 + r20, r12 + r21  # 4 x y, 4 x z, 4 y z
    q = np.empty((R.shape[0], 4))
    c0, c1, c2 = case == 0, case == 1, case == 2  # else case 3
    # each row: 4 q_c * (w, x, y, z) for the chosen component c
    q[:, 0] = np.where(c0, 1.0 + tr, np.where(c1, d21, np.where(c2, d02, d10)))
    q[:, 1] = np.where(c0, d21, np.where(c1, 1.0 + r00 - r11 - r22, np.where(c2, s01, s02)))
    q[:, 2] = np.where(c0, d02, np.where(c1, s01, np.where(c2, 1.0 - r00 + r11 - r22, s12)))
    q[:, 3] = np.where(c0, d10, np.where(c1, s02, np.where(c2, s12, 1.0 - r00 - r11 + r22)))
    q /= np.sqrt(np.einsum("ni,ni->n", q, q))[:, None]
    return q


def quaternion_to_matrix(q: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Rotation matrices (n, 3, 3) of unit quaternions (n, 4) (w, x, y, z), written into ``out`` if given.

    The standard formula for unit quaternions (e.g. R[0, 0] = 1 - 2 (y^2 + z^2)); same values as
    ``planner.quaternion.to_matrix`` for unit q, without its temporary stacks.
    """
    q = np.asarray(q, dtype=float)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    R = np.empty((q.shape[0], 3, 3)) if out is None else out
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    R[:, 0, 0] = 1.0 - 2.0 * (yy + zz)
    R[:, 0, 1] = 2.0 * (xy - wz)
    R[:, 0, 2] = 2.0 * (xz + wy)
    R[:, 1, 0] = 2.0 * (xy + wz)
    R[:, 1, 1] = 1.0 - 2.0 * (xx + zz)
    R[:, 1, 2] = 2.0 * (yz - wx)
    R[:, 2, 0] = 2.0 * (xz - wy)
    R[:, 2, 1] = 2.0 * (yz + wx)
    R[:, 2, 2] = 1.0 - 2.0 * (xx + yy)
    return R


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


def quaternion_to_rotvec(q: np.ndarray) -> np.ndarray:
    """Rotation vectors (n, 3) of unit quaternions (n, 4): 2 atan2(|v|, w) v / |v|, angle in [0, 2 pi].

    |v| = sin(theta / 2) and w = cos(theta / 2) for q = (w, v); q = +-1 (v = 0) gives the zero vector.
    Near theta = 2 pi (w -> -1) the axis v / |v| is ill-conditioned; :func:`unwrap_rotvec` handles it.
    """
    q = np.asarray(q, dtype=float)
    v = q[:, 1:]
    vn = np.sqrt(np.einsum("ni,ni->n", v, v))
    theta = 2.0 * np.arctan2(vn, q[:, 0])
    factor = np.divide(theta, vn, out=np.zeros_like(vn), where=vn > 0.0)
    return factor[:, None] * v


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
    q = continuous_quaternions(q, previous_q)
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
    return rotvec_from_quaternions(matrix_to_quaternion(R), previous_q, previous_r)
