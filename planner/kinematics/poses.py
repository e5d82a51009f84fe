"""UR poses and rigid transforms: the one owner of pose <-> transform conversion.

A pose is ``p[x, y, z, rx, ry, rz]`` (position in m, rotation vector in rad: the UR convention); a transform is
the homogeneous matrix (4, 4) ``[[R, p], [0, 0, 0, 1]]``. The conversions:

- :func:`pose_to_matrix` and :func:`matrix_to_pose`, for one pose or transform or n at once (the same numbers
  either way), through :mod:`planner.rotations` (scipy): what the planner, the exports and the simulated
  controller's ``pose_trans`` use. :func:`matrix_to_pose` gives the rotation angle in [0, pi].
- :func:`as_transform`: a frame a user gives (a part frame, a TCP offset), as a pose (6,) or a matrix (4, 4),
  checked to be rigid, as a transform; None is the identity.

The float path of forward and inverse kinematics (one pose in a few microseconds, where scipy's per-call overhead
does not fit; see :mod:`planner.rotations`): :func:`pose_frame_1` (one pose on Python floats: the rotation's 9
entries row by row and the origin), its numpy twin :func:`pose_matrices_n` (n poses, identical entries),
:func:`frame_matrix` and :func:`tcp_frame`. Use them only where one pose and a batch holding it must give the
same joints bit for bit; they agree with :func:`pose_to_matrix` to 1e-15.
"""

from __future__ import annotations

import numpy as np

from planner.errors import PlannerError
from planner.kinematics._checks import rows_of_six, six_floats
from planner.rotations import (
    matrix_to_quaternion,
    quaternion_to_rotvec,
    rotvec_to_matrix,
    rotvec_to_matrix_1,
    rotvec_to_matrix_n,
)
from planner.validation import ArgumentError, as_floats, finite_floats

__all__ = ["as_transform", "matrix_to_pose", "pose_to_matrix"]


def pose_to_matrix(pose) -> np.ndarray:
    """Homogeneous transform(s) of UR pose(s).

    Parameters
    ----------
    pose : array_like, shape (6,) or (n, 6)
        ``[x, y, z, rx, ry, rz]`` in m and rad (rotation vector).

    Returns
    -------
    ndarray, shape (4, 4) or (n, 4, 4)
    """
    arr, single = rows_of_six(pose, "pose")
    T = np.zeros((len(arr), 4, 4))
    T[:, :3, :3] = rotvec_to_matrix(arr[:, 3:])
    T[:, :3, 3] = arr[:, :3]
    T[:, 3, 3] = 1.0
    return T[0] if single else T


def matrix_to_pose(T) -> np.ndarray:
    """UR pose(s) ``[x, y, z, rx, ry, rz]`` of homogeneous transform(s) (4, 4) or (n, 4, 4).

    The rotation vector has angle in [0, pi] (the canonical quaternion, w >= 0; scipy's convention). For rotation
    vectors that continue a sequence (a pose stream), see :func:`planner.motion.rotvec.continuous_rotvec`.
    """
    T = as_floats(T, "transform")
    if T.shape[-2:] != (4, 4) or T.ndim not in (2, 3):
        raise PlannerError(f"transform: expected shape (4, 4) or (n, 4, 4), got {T.shape}")
    T = finite_floats(T, "transform")
    pose = np.empty(T.shape[:-2] + (6,))
    pose[..., :3] = T[..., :3, 3]
    pose[..., 3:] = quaternion_to_rotvec(matrix_to_quaternion(T[..., :3, :3]))
    return pose


def as_transform(value, name: str) -> np.ndarray:
    """A rigid transform (4, 4) from a UR pose (6,) ``[x, y, z, rx, ry, rz]`` or a matrix (4, 4); None: identity.

    A matrix must be rigid: orthonormal rotation to 1e-9, det +1, last row 0 0 0 1. Bad values raise
    :class:`planner.validation.ArgumentError` naming ``name`` (and the index of a NaN or infinite entry).
    """
    if value is None:
        return np.eye(4)
    a = finite_floats(value, name)
    if a.shape == (6,):
        return pose_to_matrix(a)
    if a.shape != (4, 4):
        raise ArgumentError(name, f"must be a pose (6,) [x, y, z, rx, ry, rz] or a matrix (4, 4), got {a.shape}")
    R = a[:3, :3]
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-9 or np.linalg.det(R) < 0 or np.any(a[3] != [0, 0, 0, 1]):
        raise ArgumentError(name, "must be a rigid transform: orthonormal rotation, det +1, last row 0 0 0 1")
    return a.copy()


# ---------------------------------------------------------------------------------------------------------------
# The float path of the kinematics: *_1 one pose on Python floats, *_n its numpy twin (identical entries).
# ---------------------------------------------------------------------------------------------------------------
def pose_frame_1(pose) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Rotation (9 entries row by row) and position of one validated pose (6 floats)."""
    return rotvec_to_matrix_1(pose[3], pose[4], pose[5]), (pose[0], pose[1], pose[2])


def pose_matrices_n(poses: np.ndarray) -> np.ndarray:
    """Transforms (n, 4, 4) of validated poses (n, 6): entry for entry ``frame_matrix(*pose_frame_1(pose))``."""
    T = np.zeros((len(poses), 4, 4))
    T[:, :3, :3] = rotvec_to_matrix_n(poses[:, 3:])
    T[:, :3, 3] = poses[:, :3]
    T[:, 3, 3] = 1.0
    return T


def frame_matrix(R, p) -> np.ndarray:
    """Homogeneous transform (4, 4) of a rotation (9 entries row by row) and an origin (3)."""
    return np.array([[R[0], R[1], R[2], p[0]], [R[3], R[4], R[5], p[1]], [R[6], R[7], R[8], p[2]], [0, 0, 0, 1.0]])


def tcp_frame(tcp) -> tuple[tuple[float, ...], tuple[float, ...]] | None:
    """The TCP offset (a pose in the flange frame) as (rotation entries, position), None for no offset."""
    if tcp is None:
        return None
    vals = six_floats(tcp, "tcp")
    if vals is None:
        raise PlannerError(f"tcp: expected one pose of shape (6,), got shape {np.shape(tcp)}")
    return pose_frame_1(vals)
