"""UR robot kinematics: models, forward and closed-form inverse kinematics, reachability checks.

Poses are ``p[x, y, z, rx, ry, rz]`` (m, rotation vector) of the tool in the robot base frame;
joint vectors are ``q[base, shoulder, elbow, wrist 1, wrist 2, wrist 3]`` in rad. The package also owns what the
simulated controller shares with the planner: pose <-> transform conversion (:mod:`planner.kinematics.poses`:
``pose_to_matrix``, ``matrix_to_pose``, ``as_transform``) and the table of the controller's digital outputs
(:mod:`planner.kinematics.ur_outputs`).
"""

from planner.kinematics.errors import UnreachableError
from planner.kinematics.forward import forward, forward_matrix, link_frames
from planner.kinematics.inverse import (
    IKSolutions,
    inverse,
    inverse_batch,
    inverse_frames,
    inverse_nearest,
    inverse_path,
    wrap_angle,
)
from planner.kinematics.poses import as_transform, matrix_to_pose, pose_to_matrix
from planner.kinematics.reachability import (
    ReachabilityReport,
    Violation,
    check_poses,
    check_reachability,
    feed_scale,
    feed_scale_profile,
    joint_speeds,
    speed_ratios,
)
from planner.kinematics.ur_models import MODELS, UnknownModelError, URModel, get_model, model_names

__all__ = [
    "MODELS",
    "IKSolutions",
    "ReachabilityReport",
    "URModel",
    "UnknownModelError",
    "UnreachableError",
    "Violation",
    "as_transform",
    "check_poses",
    "check_reachability",
    "feed_scale",
    "feed_scale_profile",
    "forward",
    "forward_matrix",
    "get_model",
    "inverse",
    "inverse_batch",
    "inverse_frames",
    "inverse_nearest",
    "inverse_path",
    "joint_speeds",
    "link_frames",
    "matrix_to_pose",
    "model_names",
    "pose_to_matrix",
    "speed_ratios",
    "wrap_angle",
]
