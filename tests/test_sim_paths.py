"""Paths of the simulated arm's motion model, in process: ur_rtde's ``movePath`` mixing joint and linear moves
(``move_path_async_example.py``'s path), unblended waypoints, where the arm comes to rest, blends that turn the
tool smoothly where its turn reverses and blends too small for the speed, passed slowly (issue 29: the NX job's
passes 116 and 124 in program mode)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from drivers.report import distance_to_polyline, planned_path
from planner import PlanSettings, plan
from planner.export import job_program
from planner.frontends.cli.main import DEMO_PART
from planner.kinematics import forward
from sim.core import Core
from sim.io_state import IOState
from sim.motion import DT, JOINT_ACCEL_MAX, ROTATION_RADIUS, MotionError, Segment
from tests.cam_excerpts import NX_AXIS_REVERSAL

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


def _tool_angular_accelerations(q: np.ndarray) -> np.ndarray:
    """|change of the tool's angular velocity| / DT (rad/s^2) between consecutive periods of joints q (K, 6)."""
    R = Rotation.from_rotvec(forward("ur5e", q)[:, 3:])
    w = (R[:-1].inv() * R[1:]).as_rotvec() / DT  # in the tool frame
    return np.linalg.norm(np.diff(w, axis=0), axis=1) / DT


def test_linear_blend_turns_the_tool_smoothly_where_its_turn_reverses():
    """A blend blends the orientation with the position (UR's Cartesian blends are smooth transitions): two moves
    along x that turn the tool about its y axis by 0.07 rad and back, blended with r 0.33 mm at 5 mm/s. The tool
    turns at v / ROTATION_RADIUS = 0.05 rad/s each way; turning the angular velocity by 0.1 rad/s within one period
    at the waypoint was 50 rad/s^2 for the tool and a joint (a protective stop); through the blend, 2 r of the
    path parameter at v, it is 0.1 rad/s * v / 2r = 0.76 rad/s^2."""
    core = Core("ur5e", IOState())
    m = core.motion
    P0 = forward(m.model, m.q)
    R0 = Rotation.from_rotvec(P0[3:])

    def pose(dx: float, angle: float) -> np.ndarray:
        return np.r_[P0[:3] + [dx, 0.0, 0.0], (R0 * Rotation.from_rotvec([0.0, angle, 0.0])).as_rotvec()]

    turn, v, r = 0.07, 0.005, 0.00033
    corner = pose(0.002, turn)
    m.plan_linear([Segment(corner, v, 0.5, r), Segment(pose(0.004, 0.0), v, 0.5, 0.0)])
    q, _ = _play(core)
    assert core.safety_mode == 1 and not [x for x in core.log if x[1] == "Safety"], list(core.log)
    P = forward(m.model, q)
    R = Rotation.from_rotvec(P[:, 3:])
    assert np.abs(P[-1, :3] - P0[:3] - [0.004, 0.0, 0.0]).max() < 1e-12
    assert (R[-1].inv() * R0).magnitude() < 1e-9
    # the positions stay on the straight line (collinear waypoints: the blend does not move them off it)
    assert np.abs(P[:, 1:3] - P0[1:3]).max() < 1e-12
    omega = v / ROTATION_RADIUS  # rad/s: the turn is the longer part of the path parameter on both moves
    bound = 2.0 * omega * v / (2.0 * r)
    assert _tool_angular_accelerations(q).max() <= bound * (1 + 1e-3)
    _, acc = _speeds_and_accelerations(q)
    assert np.abs(acc).max() <= 2.0 * bound  # joint 4 turns the tool about its y axis here
    # the blend cuts the turn's corner as the position blend cuts a corner: by r |change of the rate| / 4 at its
    # middle (the rates along the path parameter: +-turn / (turn ROTATION_RADIUS) rad per m)
    cut = r * 2.0 / ROTATION_RADIUS / 4.0
    nearest = (R.inv() * Rotation.from_rotvec(corner[3:])).magnitude().min()
    assert nearest == pytest.approx(cut, rel=1e-3)


def test_blend_too_small_for_the_speed_is_passed_slowly():
    """A move along x at 20 mm/s, then a turn of the tool by 0.02 rad in place (1 um of travel), blended with r 0.1 um:
    the path's direction (position, and rotation times ROTATION_RADIUS, per unit of the path parameter) turns by 1
    within the blend. Passing it at full speed turned the tool's angular velocity from 0 to 0.2 rad/s within one
    period (100 rad/s^2, a protective stop); the time law slows to sqrt(2 a r / 1) = 0.32 mm/s through the blend,
    so the tool's acceleration stays within a (m/s^2) and a / ROTATION_RADIUS (rad/s^2) at every period."""
    core = Core("ur5e", IOState())
    m = core.motion
    P0 = forward(m.model, m.q)
    R0 = Rotation.from_rotvec(P0[3:])
    target = np.r_[P0[:3] + [0.002001, 0.0, 0.0], (R0 * Rotation.from_rotvec([0.0, 0.02, 0.0])).as_rotvec()]
    v, a, r = 0.02, 0.5, 1e-7
    traj = m.plan_linear([Segment(np.r_[P0[:3] + [0.002, 0.0, 0.0], P0[3:]], v, a, r), Segment(target, v, a, 0.0)])
    q, _ = _play(core)
    assert core.safety_mode == 1 and not [x for x in core.log if x[1] == "Safety"], list(core.log)
    P = forward(m.model, q)
    assert np.abs(P[-1, :3] - target[:3]).max() < 1e-12
    assert (Rotation.from_rotvec(P[-1, 3:]).inv() * Rotation.from_rotvec(target[3:])).magnitude() < 1e-9
    speed = np.diff(P[:, :3], axis=0) / DT
    assert np.linalg.norm(np.diff(speed, axis=0), axis=1).max() / DT <= a * (1 + 1e-3)
    assert _tool_angular_accelerations(q).max() <= a / ROTATION_RADIUS * (1 + 1e-3)
    _, acc = _speeds_and_accelerations(q)
    assert np.abs(acc).max() <= JOINT_ACCEL_MAX
    # slow through the blend: the speed along the path parameter in the periods next to the corner
    R = Rotation.from_rotvec(P[:, 3:])
    turning = np.linalg.norm((R[:-1].inv() * R[1:]).as_rotvec(), axis=1) / DT * ROTATION_RADIUS
    along = np.maximum(np.linalg.norm(speed, axis=1), turning)
    i = traj.starts[1]
    assert along[i - 2 : i + 2].min() <= np.sqrt(2 * a * r)
    assert along.max() == pytest.approx(v, rel=1e-6)  # at full speed on both moves


def test_timed_move_is_slowed_down_before_its_joints_are_checked():
    """movel(..., t): the move lasts t, its profile slowed uniformly (speeds over c, accelerations over c^2,
    c = t / the profile's own duration), and the joints are checked on that. A 3 m/s move across the workspace
    needs more than the joints' speed limits at its own pace (a protective stop); given 2 s it runs. The issue-29
    run stopped on such a check at t = 30287 s: a rapid of line 18800 near the wrist singularity, 45 rad/s^2 at its
    own pace, 29 in its planned 0.353 s."""
    core = Core("ur5e", IOState())
    m = core.motion
    q0 = m.q.copy()
    target = forward(m.model, q0) + [0.0, 0.35, -0.2, 0.0, 0.0, 0.0]
    own = m._linear_samples(q0, [Segment(target, 3.0, 20.0)]).q
    v_own, acc_own = _speeds_and_accelerations(np.vstack([q0, q0, own]))
    assert (np.abs(v_own) > m.qd_max).any()  # too fast at its own pace
    duration = 2.0
    c = duration / (len(own) * DT)
    text = "def timed():\n  movel(p[" + ", ".join(f"{x:.9f}" for x in target) + "], a=20.0, v=3.0, t=2.0, r=0)\nend\n"
    assert core.load_program(text)
    qs = [core.motion.q]
    while core.program is not None:
        core.tick()
        qs.append(core.motion.q)
        assert len(qs) < 5000
    assert core.safety_mode == 1 and not [x for x in core.log if x[1] == "Safety"], list(core.log)
    q = np.array(qs)
    moving = np.flatnonzero(np.abs(np.diff(q, axis=0)).max(axis=1) > 0)
    assert (moving[-1] + 1 - moving[0]) * DT == pytest.approx(duration, abs=2 * DT)
    assert np.abs(forward(m.model, q[-1])[:3] - target[:3]).max() < 1e-12
    v, acc = _speeds_and_accelerations(q)
    assert np.abs(v).max() == pytest.approx(np.abs(v_own).max() / c, rel=1e-2)
    assert np.abs(acc).max() == pytest.approx(np.abs(acc_own).max() / c**2, rel=5e-2)


def test_program_of_passes_whose_tool_axis_turns_back_runs_to_its_end():
    """Issue 29: the whole NX job in program mode stopped at t = 7618.6 s in its pass 116 (lines 4703-4727) with
    'movel: joint 5 acceleration 44.9 rad/s^2 beyond the limit 40': the tool axis turns by 82 deg and then back
    by 1.3 deg (line 4712), the movep target there is blended (r 0.33 mm), and the simulator turned the tool's
    angular velocity around within one period at it. With that fixed it stopped at t = 7824.6 s in pass 124 (lines
    4794-4851), 'joint 5 acceleration 44.0 rad/s^2': the axis turns back by 5 deg within 0.081 mm (line 4834), where
    the movep targets are 0.04 um apart with blends of 0.02 um, passed at full speed. The excerpt of those passes
    (the same moves, the same two stops before the fixes) runs to its end: every period's joint accelerations and
    the tool's within limits, the TCP within the program's tolerance of the planned path."""
    job = plan(NX_AXIS_REVERSAL.path, PlanSettings(path="cam", part_frame=DEMO_PART, robot="ur5e",
                                                   cut_output=("standard", 0)))
    assert job.problems == ()
    assert [int(NX_AXIS_REVERSAL.original_line(p.first_line)) for p in job.passes] == [4678, 4703, 4794]
    _, pp, _, _, _ = planned_path(job)
    core = Core("ur5e", IOState())
    core.motion.q = np.array(job.start_joints, dtype=float)
    assert core.load_program(job_program(job)), list(core.log)[-3:]
    qs = [core.motion.q]
    while core.program is not None:
        core.tick()
        qs.append(core.motion.q)
        assert core.time < 1000.0, "the program did not end"
    assert core.safety_mode == 1 and not [x for x in core.log if x[1] == "Safety"], list(core.log)[-5:]
    q = np.array(qs)
    _, acc = _speeds_and_accelerations(q)
    assert np.abs(acc).max() <= 0.25 * JOINT_ACCEL_MAX
    # the tool turns with at most the program's a (0.5 m/s^2) over ROTATION_RADIUS
    assert _tool_angular_accelerations(q).max() <= 0.5 / ROTATION_RADIUS * (1 + 1e-3)
    tcp = forward("ur5e", q)[:, :3]
    assert np.abs(tcp[-1] - pp[-1, :3]).max() < 1e-9
    d, _ = distance_to_polyline(tcp[::5], pp[:, :3])
    assert d.max() <= job.settings.tolerance


def test_path_to_an_unreachable_pose_by_movej_is_refused_before_the_arm_moves():
    core = Core("ur5e", IOState())
    q0 = core.motion.q
    with pytest.raises(MotionError, match="movej target 1: pose is not reachable"):
        core.motion.plan_path([("movej", Segment(np.array(EXAMPLE_PATH[0][1], float), 0.5, 4.0), True),
                               ("movej", Segment(np.array([3.0, 0, 0.1, 0, 3.14, 0]), 0.5, 4.0), True)])
    assert np.array_equal(core.motion.q, q0) and not core.motion.busy
