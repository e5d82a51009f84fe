"""Rotation-vector conversions of the kinematics package: the documented fast path.

The rest of the planner converts rotations with ``scipy.spatial.transform`` (``planner.rotations``).
Kinematics converts every pose of a path and, in the simulated controller, one pose per 2 ms period;
scipy's per-call overhead (about 10 us for one rotation) does not fit that budget, so the two
conversions UR poses need are written out here, each twice with the same operations in the same
order: vectorized over n rotations (numpy) and for one rotation on Python floats (``math``). Both
follow scipy's own formulas (quaternion from the rotation vector, Shepperd's choice of the largest
quaternion component from the matrix, canonical quaternion with w >= 0) and are tested against
``scipy.spatial.transform.Rotation`` to 1e-12, and against each other for identical results.

Scalar forms take and return flat tuples: a rotation matrix as its 9 entries row by row.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["rotvec_to_matrix", "matrix_to_rotvec", "rotvec_to_matrix_1", "matrix_to_rotvec_1"]

# Below this angle (rad) the rotation vector of a quaternion uses the Taylor series of angle / sin(angle / 2).
_SMALL_ANGLE = 1e-3


def rotvec_to_matrix(r: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3) of rotation vectors r (n, 3) (axis times angle, rad).

    The unit quaternion (sin(a / 2) / a * r, cos(a / 2)), a = |r|, turned into a matrix.
    """
    rx, ry, rz = r[:, 0], r[:, 1], r[:, 2]
    a = np.sqrt(rx * rx + ry * ry + rz * rz)
    zero = a == 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(zero, 0.5, np.sin(0.5 * a) / a)  # sin(a / 2) / a, its limit 1/2 at a = 0
    return _quat_matrix(s * rx, s * ry, s * rz, np.cos(0.5 * a)).reshape(-1, 3, 3)


def rotvec_to_matrix_1(rx: float, ry: float, rz: float) -> tuple[float, ...]:
    """:func:`rotvec_to_matrix` of one rotation vector; returns the 9 matrix entries row by row."""
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


def matrix_to_rotvec(R: np.ndarray) -> np.ndarray:
    """Rotation vectors (n, 3), angle in [0, pi], of rotation matrices R (n, 3, 3).

    Shepperd's method: the quaternion is computed from whichever of its four components is largest
    (chosen by the largest of the diagonal entries and the trace), normalized, and taken with w >= 0
    (at w = 0, with its first non-zero component positive), as scipy does.
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
    """:func:`matrix_to_rotvec` of one matrix given by its 9 entries row by row.

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
