"""Branch tracking along paths and per-job reachability reports (planner.kinematics)."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from planner.errors import PlannerError
from planner.kinematics import (
    UnreachableError,
    check_poses,
    check_reachability,
    feed_scale,
    feed_scale_profile,
    forward,
    forward_matrix,
    get_model,
    inverse_path,
    joint_speeds,
    matrix_to_pose,
    model_names,
    speed_ratios,
    wrap_angle,
)

NAMES = model_names()


def smooth_joint_path(n: int = 400) -> np.ndarray:
    """A smooth joint path (n, 6); wrist 3 turns from 2.0 to 5.5 rad, crossing pi."""
    s = np.linspace(0.0, 1.0, n)[:, None]
    q0 = np.array([0.5, -1.4, 1.6, -1.7, 1.3, 2.0])
    q1 = np.array([1.6, -0.9, 1.1, -2.3, 0.7, 5.5])
    return q0 + (q1 - q0) * (3 * s**2 - 2 * s**3) + 0.2 * np.sin(3 * np.pi * s) * [1, 0.5, -0.5, 1, 1, 1]


@pytest.mark.parametrize("name", NAMES)
def test_path_recovers_generating_joints(name):
    q = smooth_joint_path()
    out = inverse_path(name, forward(name, q), q_start=q[0])
    np.testing.assert_allclose(out, q, atol=1e-9)  # same branch throughout, wrist 3 unwrapped past pi


@pytest.mark.parametrize("name", NAMES)
def test_path_without_start_is_continuous_and_exact(name):
    q = smooth_joint_path()
    poses = forward(name, q)
    out = inverse_path(name, poses)
    np.testing.assert_allclose(forward_matrix(name, out), forward_matrix(name, q), atol=1e-12)
    step = np.abs(np.diff(out, axis=0)).max()
    assert step <= 1.01 * np.abs(np.diff(q, axis=0)).max()  # the least-travel branch, no jumps
    m = get_model(name)
    assert np.all(out >= m.lower) and np.all(out <= m.upper)


def test_start_whole_turns_are_kept():
    q = smooth_joint_path()
    shifted = q[0] + np.array([0, 0, 0, 2 * np.pi, 0, -2 * np.pi])
    out = inverse_path("ur5e", forward("ur5e", q), q_start=shifted)
    np.testing.assert_allclose(out, q + [0, 0, 0, 2 * np.pi, 0, -2 * np.pi], atol=1e-9)


def test_path_through_wrist_singularity():
    # q5 passes exactly through 0 at sample 100: the wrist branch labels swap there.
    s = np.linspace(-1.0, 1.0, 201)[:, None]
    q = np.array([0.3, -1.2, 1.5, -1.8, 0.0, 0.5]) + s * [0.1, 0.1, 0.1, 0.1, 0.3, 0.2]
    out = inverse_path("ur10e", forward("ur10e", q), q_start=q[0])
    np.testing.assert_allclose(out, q, atol=1e-9)


def test_path_through_stretched_elbow():
    # q3 passes through 0 (arm stretched): the elbow branches swap; IK of q3 is sqrt-ill-conditioned.
    s = np.linspace(-1.0, 1.0, 201)[:, None]
    q = np.array([0.3, -1.0, 0.0, -1.2, 1.0, 0.5]) + s * [0.1, 0.1, 0.2, 0.1, 0.1, 0.1]
    out = inverse_path("ur16e", forward("ur16e", q), q_start=q[0])
    np.testing.assert_allclose(out, q, atol=1e-6)
    assert np.abs(np.diff(out[:, 2])).max() < 0.0021


def _next_branch_by_definition(Q, V, multiturn):
    """Nearest valid branch at sample i + 1 for every branch at i, comparing all 8 x 8 pairs (the definition)."""
    Qs, Vs = Q.transpose(2, 1, 0), V.T  # (n, 8, 6), (n, 8)
    d = Qs[1:, None] - Qs[:-1, :, None]  # (n - 1, from, to, 6)
    d = np.where(multiturn, wrap_angle(d), d)
    D = np.linalg.norm(d, axis=-1)
    D = np.where(Vs[1:, None, :] & ~np.isnan(D), D, np.inf)
    nxt, dist = np.argmin(D, axis=-1), np.min(D, axis=-1)
    nxt[~np.isfinite(dist)] = -1
    return nxt, dist


def _radial_through_shoulder_cylinder(name, n=301):
    """Poses whose wrist centre moves radially from 5 cm outside the d4 cylinder to 1 cm inside it."""
    m = get_model(name)
    T = forward_matrix(name, [0.4, -1.3, 1.9, -0.5, 1.0, 0.2])
    p5 = T[:3, 3] - m.d6 * T[:3, 2]
    r = np.hypot(*p5[:2])
    Ts = np.repeat(T[None], n, axis=0)
    Ts[:, :2, 3] += p5[:2] * ((m.d4 + np.linspace(0.05, -0.01, n)) / r - 1.0)[:, None]
    return matrix_to_pose(Ts)


@pytest.mark.parametrize("name", NAMES)
def test_same_branch_shortcut_gives_the_nearest_branch_by_definition(name):
    """The tracker compares all 8 x 8 branch pairs only where the same-branch test fails; it must pick the
    nearest valid branch exactly as comparing every pair does: through the wrist, elbow and shoulder
    singularities, across unreachable gaps and with steps so coarse that branches swap."""
    m = get_model(name)
    s = np.linspace(-1.0, 1.0, 401)[:, None]
    rng = np.random.default_rng(11)
    paths = [
        forward(name, np.array([0.3, -1.2, 1.5, -1.8, 0.0, 0.5]) + s * [0.1, 0.1, 0.1, 0.1, 0.3, 0.2]),
        forward(name, np.array([0.3, -1.0, 0.0, -1.2, 1.0, 0.5]) + s * [0.1, 0.1, 0.2, 0.1, 0.1, 0.1]),
        forward(name, smooth_joint_path(400)[::8]),  # about 0.1 rad per sample
        forward(name, np.cumsum(rng.normal(scale=0.4, size=(400, 6)), axis=0)),  # branches cross
        _radial_through_shoulder_cylinder(name),
    ]
    inv = importlib.import_module("planner.kinematics.inverse")
    shortcut_rows = 0
    for poses in paths:
        sol = inv._solve(m, inv._flange_targets(m, poses, None), np.zeros(len(poses)))
        nxt, dist = inv._next_branch(sol.q, sol.valid, m.multiturn)
        ref_nxt, ref_dist = _next_branch_by_definition(sol.q, sol.valid, m.multiturn)
        assert np.array_equal(nxt, ref_nxt)
        np.testing.assert_allclose(dist, ref_dist, rtol=1e-12, atol=1e-15)
        shortcut_rows += int((nxt == np.arange(8)).all(axis=1).sum())
    assert 0 < shortcut_rows < sum(len(p) - 1 for p in paths)  # both ways exercised


def test_first_unreachable_sample_is_reported():
    q = smooth_joint_path(50)
    poses = forward("ur3e", q)
    poses[17, :3] = [3.0, 0.0, 0.5]
    poses[30, :3] = [3.0, 1.0, 0.5]
    message = r"sample 17: no inverse kinematics solution: out of reach"
    with pytest.raises(UnreachableError, match=message) as e:
        inverse_path("ur3e", poses, q_start=q[0])
    assert e.value.index == 17
    out = inverse_path("ur3e", poses, q_start=q[0], allow_unreachable=True)
    assert np.isnan(out[[17, 30]]).all()
    keep = np.setdiff1d(np.arange(50), [17, 30])
    np.testing.assert_allclose(out[keep], q[keep], atol=1e-9)  # tracking resumes on the same branch


def test_inside_shoulder_cylinder_is_diagnosed():
    m = get_model("ur5e")
    poses = forward("ur5e", smooth_joint_path(5))
    poses[2] = [0.0, 0.0, 0.5 - m.d6, 0.0, 0.0, 0.0]
    with pytest.raises(UnreachableError, match=r"sample 2: .*closer than d4"):
        inverse_path("ur5e", poses)


# --- reachability -----------------------------------------------------------------------------------


def timed_path(n: int = 200, duration: float = 20.0):
    q = smooth_joint_path(n)
    return q, np.linspace(0.0, duration, n)


def test_reachable_job_is_ok():
    q, t = timed_path()
    report = check_reachability("ur5e", q, t)
    assert report.ok and report.first is None and report.feed_scale == 1.0
    assert report.n_unreachable == report.n_position == report.n_speed == 0
    peak = np.max(np.abs(joint_speeds(q, t)) / get_model("ur5e").speed_limits)
    assert report.max_speed_ratio == pytest.approx(peak, rel=1e-12) and peak < 1
    assert "all 200 samples reachable" in report.message


def test_speed_violation_reported_at_the_right_sample():
    q, t = timed_path()
    q[37:, 2] += 0.5  # elbow jumps by 0.5 rad between samples 36 and 37 (0.1 s): 5 rad/s > pi rad/s
    s = np.linspace(0.0, 1.2, len(t))
    report = check_reachability("ur5e", q, t, arc_length=s, span=np.arange(len(t)) // 50)
    v = report.first
    assert not report.ok and v.kind == "speed" and v.index == 37 and v.joint == 2
    assert v.time == t[37] and v.arc_length == s[37] and v.span == 0
    assert v.value == pytest.approx(abs(q[37, 2] - q[36, 2]) / (t[37] - t[36]), rel=1e-12)
    assert v.limit == pytest.approx(np.pi)
    assert report.n_speed == 1
    assert "sample 37 (t = 3.71859 s, s = 0.223116 m, span 0): joint 2 (elbow) speed" in report.message


def test_position_and_unreachable_violations_and_their_order():
    q, t = timed_path()
    q[:, 5] = 2 * np.pi + 1e-3 * (np.arange(200) - 119.5)  # wrist 3 slowly passes 2 pi at sample 120
    report = check_reachability("ur5e", q, t)
    v = report.first
    assert v.kind == "position" and v.index == 120 and v.joint == 5
    assert v.value == q[120, 5] and v.limit == pytest.approx(2 * np.pi)
    assert report.n_position == 200 - 120 and report.n_speed == 0
    assert "above its limit" in report.message
    q[60] = np.nan  # an unreachable sample comes first
    report = check_reachability("ur5e", q, t)
    assert report.first.kind == "unreachable" and report.first.index == 60 and report.n_unreachable == 1
    assert report.first.joint is None and "sample 60" in report.message


def test_feed_scale_brings_speeds_within_limits():
    q, t = timed_path(duration=0.5)  # far too fast
    report = check_reachability("ur10e", q, t)
    assert not report.ok and report.first.kind == "speed" and report.first.index == 1
    for margin in (1.0, 0.8):
        f = feed_scale("ur10e", q, t, margin=margin)
        assert 0 < f < 1
        slowed = check_reachability("ur10e", q, t / f)  # feed x f stretches times by 1 / f
        assert slowed.ok and slowed.max_speed_ratio == pytest.approx(margin, rel=1e-12)
    profile = feed_scale_profile("ur10e", q, t)
    assert profile.shape == t.shape and np.all(profile <= 1.0)
    assert profile.min() == pytest.approx(feed_scale("ur10e", q, t), rel=1e-12)
    q_slow, t_slow = timed_path(duration=200.0)
    assert feed_scale("ur10e", q_slow, t_slow) == 1.0
    assert np.all(feed_scale_profile("ur10e", q_slow, t_slow) == 1.0)


def test_speed_ratios_name_the_fastest_joint_per_interval():
    q, t = timed_path(duration=0.5)
    limits = get_model("ur10e").speed_limits
    ratio, joint = speed_ratios("ur10e", q, t)
    full = np.abs(joint_speeds(q, t)) / limits
    assert ratio.shape == joint.shape == (len(t) - 1,)
    assert np.array_equal(ratio, full.max(axis=1)) and np.array_equal(joint, full.argmax(axis=1))
    assert ratio.max() == check_reachability("ur10e", q, t).max_speed_ratio
    q[50] = np.nan  # an unreachable sample: its two intervals are undefined
    ratio, _ = speed_ratios("ur10e", q, t)
    assert np.isnan(ratio[[49, 50]]).all() and np.isfinite(np.delete(ratio, [49, 50])).all()


def test_check_poses_end_to_end():
    q, t = timed_path()
    poses = forward("ur20", q)
    q_out, report = check_poses("ur20", poses, t, q_start=q[0])
    np.testing.assert_allclose(q_out, q, atol=1e-9)
    assert report.ok
    poses[150, :3] = [5.0, 0.0, 0.0]
    q_out, report = check_poses("ur20", poses, t, q_start=q[0])
    assert np.isnan(q_out[150]).all()
    assert report.first.kind == "unreachable" and report.first.index == 150 and report.first.time == t[150]


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda q, t: check_reachability("ur5e", q, t[:-1]), r"t: expected shape \(200,\)"),
        (lambda q, t: check_reachability("ur5e", q, np.r_[t[:9], t[8], t[10:]]),
         r"t\[9\] = .* is not after t\[8\]"),
        (lambda q, t: check_reachability("ur5e", q, np.r_[t[:4], np.nan, t[5:]]), r"t\[4\] is nan"),
        (lambda q, t: check_reachability("ur5e", np.r_[q[:3], [[0, 1, np.nan, 0, 0, 0]], q[4:]], t),
         r"q\[3, 2\] \(row 3\) is nan"),
        (lambda q, t: check_reachability("ur5e", q, t, arc_length=t[:5]), r"arc_length: expected shape"),
        (lambda q, t: check_reachability("ur5e", q, t, span=t[:5]), r"span: expected shape"),
        (lambda q, t: feed_scale("ur5e", q, t, margin=1.5), r"margin: must be in \(0, 1\]"),
        (lambda q, t: check_reachability("ur5", q, t), r"unknown robot model 'ur5'"),
        (lambda q, t: inverse_path("ur5e", forward("ur5e", q), q_start=np.zeros(5)), r"q_start: expected"),
        (lambda q, t: inverse_path("ur5e", np.zeros((3, 5))), r"poses: expected shape"),
    ],
)
def test_bad_input_names_the_place(call, message):
    q, t = timed_path()
    with pytest.raises(PlannerError, match=message):
        call(q, t)
