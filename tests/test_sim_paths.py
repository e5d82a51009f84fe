"""Paths of the simulated arm's motion model, in process: ur_rtde's ``movePath`` mixing joint and linear moves
(``move_path_async_example.py``'s path), and unblended waypoints, where the arm comes to rest."""

from __future__ import annotations

import numpy as np
import pytest

from planner.kinematics import forward
from sim.core import Core
from sim.io_state import IOState
from sim.motion import DT, JOINT_ACCEL_MAX, MotionError, Segment

# ur_rtde 1.6.5 examples/py/move_path_async_example.py: MoveJ and MoveL entries to tool poses, v 0.5, a 4, r 0.099
EXAMPLE_PATH = [
    ("movej", [-0.140, -0.400, 0.100, 0, 3.14, 0], 0.0),
    ("movel", [-0.140, -0.400, 0.300, 0, 3.14, 0], 0.099),
    ("movel", [-0.140, -0.600, 0.300, 0, 3.14, 0], 0.099),
    ("movej", [-0.140, -0.600, 0.100, 0, 3.14, 0], 0.099),
    ("movej", [-0.140, -0.400, 0.100, 0, 3.14, 0], 0.0),
]


def _play(core: Core) -> np.ndarray:
    """Every period's joints (K, 6) until the motion ends, with the path entry the model reports."""
    qs, progress = [core.motion.q], []
    while core.motion.busy:
        progress.append(core.motion.progress())
        core.tick()
        qs.append(core.motion.q)
        assert len(qs) < 100_000
    return np.array(qs), np.array(progress)


def _speeds_and_accelerations(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    v = np.diff(q, axis=0) / DT
    return v, np.diff(v, axis=0) / DT


def test_path_mixing_joint_and_linear_moves_runs_through_every_waypoint():
    core = Core("ur5e", IOState())
    m = core.motion
    traj = m.plan_path([(kind, Segment(np.array(p, float), 0.5, 4.0, r), True) for kind, p, r in EXAMPLE_PATH])
    assert traj.fault is None and len(traj.starts) == len(EXAMPLE_PATH)
    q, progress = _play(core)
    assert core.safety_mode == 1
    # the progress the async register reports runs 0, 1, ... 4 in order, each entry for a while
    assert list(np.unique(progress)) == list(range(len(EXAMPLE_PATH)))
    assert np.all(np.diff(progress) >= 0)
    # ends exactly on the last pose
    assert np.allclose(forward(m.model, q[-1]), EXAMPLE_PATH[-1][1], atol=1e-9)
    # where the family changes (entry 0 -> 1, 2 -> 3) the arm is at rest on the waypoint
    for k in (1, 3):
        i = traj.starts[k]
        assert np.allclose(forward(m.model, q[i])[:3], EXAMPLE_PATH[k - 1][1][:3], atol=1e-6)
        v, _ = _speeds_and_accelerations(q[i - 1 : i + 2])
        assert np.abs(v).max() < 0.05
    # the linear run is straight up to its blend: entry 1's samples on the segment from waypoint 0 to waypoint 1
    run = q[traj.starts[1] : traj.starts[2]]
    P = forward(m.model, run)[:, :3]
    a, b = np.array(EXAMPLE_PATH[0][1][:3]), np.array(EXAMPLE_PATH[1][1][:3])
    u = (b - a) / np.linalg.norm(b - a)
    along = (P - a) @ u
    straight = along < np.linalg.norm(b - a) - EXAMPLE_PATH[1][2] - 1e-9
    assert straight.sum() > 50
    assert np.linalg.norm(np.cross(P[straight] - a, u), axis=1).max() < 1e-6
    _, acc = _speeds_and_accelerations(q)
    assert np.abs(acc).max() <= JOINT_ACCEL_MAX


def test_unblended_waypoint_of_a_linear_path_is_a_stop():
    """ur_rtde's movel_path_with_blend_example.py: r = 0 at the first waypoint: the arm stops there instead of
    turning the corner at speed (which took a joint beyond its acceleration limit: a protective stop)."""
    core = Core("ur5e", IOState())
    m = core.motion
    poses = [[-0.143, -0.435, 0.20, -0.001, 3.12, 0.04], [-0.143, -0.51, 0.21, -0.001, 3.12, 0.04],
             [-0.32, -0.61, 0.31, -0.001, 3.12, 0.04]]
    traj = m.plan_linear([Segment(np.array(p), 0.5, 0.5, r) for p, r in zip(poses, (0.0, 0.02, 0.0), strict=True)])
    q, _ = _play(core)
    assert core.safety_mode == 1, list(core.log)
    i = traj.starts[1]
    # a sample within a period's crawl (a / 2 * DT^2 = 1e-6 m) of the waypoint
    assert np.linalg.norm(forward(m.model, q[i - 2 : i + 2])[:, :3] - poses[0][:3], axis=1).min() < 2e-6
    v, acc = _speeds_and_accelerations(q)
    tool_speed = np.linalg.norm(np.diff(forward(m.model, q)[:, :3], axis=0), axis=1) / DT
    assert tool_speed[i - 1 : i + 1].max() < 2e-3  # at rest on the unblended waypoint
    assert tool_speed.max() <= 0.5 * (1 + 1e-6)
    assert np.abs(acc).max() <= JOINT_ACCEL_MAX
    # the blended waypoint (r 0.02) is passed at speed
    j = traj.starts[2]
    assert tool_speed[j - 2 : j + 2].min() > 0.05


def test_path_to_an_unreachable_pose_by_movej_is_refused_before_the_arm_moves():
    core = Core("ur5e", IOState())
    q0 = core.motion.q
    with pytest.raises(MotionError, match="movej target 1: pose is not reachable"):
        core.motion.plan_path([("movej", Segment(np.array(EXAMPLE_PATH[0][1], float), 0.5, 4.0), True),
                               ("movej", Segment(np.array([3.0, 0, 0.1, 0, 3.14, 0]), 0.5, 4.0), True)])
    assert np.array_equal(core.motion.q, q0) and not core.motion.busy
