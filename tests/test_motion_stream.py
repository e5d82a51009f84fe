"""Sampling at the controller rate: feed ripple, angular limit, rotation vectors, TCP and base frames."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from planner.curves import fit_ph_spline
from planner.errors import PlannerError
from planner.frames.path import frame_field
from planner.motion import (
    ConstantOrientation,
    IOEvent,
    IOEventWarning,
    MotionInputError,
    MotionLimits,
    SplineEvaluator,
    continuous_rotvec,
    io_window,
    plan_feed,
    sample_poses,
    tool_orientation,
)
from planner.rotations import matrix_to_quaternion, quaternion_to_rotvec, rotation_angle

LIM = MotionLimits(speed=1.0, acceleration=2.0, jerk=30.0)


def helix(n=60, turns=2.0, r=0.08, h=0.05, noise=0.0, seed=0, uneven=0.5):
    """Waypoints on a helix, spaced unevenly (neighbour spacing ratio down to ~1:3, as CAM data is)."""
    w = np.linspace(0.0, 1.0, n)
    w = w + uneven * np.sin(10 * np.pi * w) / (10 * np.pi)
    th = 2 * np.pi * turns * w
    rng = np.random.default_rng(seed)
    wp = np.column_stack((r * np.cos(th), r * np.sin(th), h * w))
    return fit_ph_spline(wp + noise * rng.standard_normal(wp.shape))


@pytest.fixture(scope="module")
def job():
    path = helix()
    orient = tool_orientation(frame_field(path, "rmf"), z_column=2)
    prof = plan_feed(path, 0.2, LIM)
    return path, orient, prof


def speed_5point(p, rate):
    """TCP speed from positions (n, 3) by the 4th-order central difference; (n - 4,) for samples 2..n-3."""
    d = (-p[4:] + 8 * p[3:-1] - 8 * p[1:-3] + p[:-4]) * (rate / 12.0)
    return np.linalg.norm(d, axis=1)


def cruise_stencils(stream, path):
    """Samples 2..n-3 whose whole 5-point stencil is in a cruise phase and inside one spline segment.

    Across a knot the C2 spline's third derivative jumps, and the 5-point difference (which assumes a
    smooth curve) errs by O((h kappa)^2) whatever the feed: those stencils measure the estimator.
    """
    c = stream.profile.in_cruise(stream.times)
    k, _ = SplineEvaluator.of(path).locate(stream.s)
    return c[:-4] & c[1:-3] & c[2:-2] & c[3:-1] & c[4:] & (k[:-4] == k[4:])


@pytest.mark.parametrize("rate", [500.0, 125.0])
def test_feed_ripple_in_cruise_is_round_off(job, rate):
    path, orient, prof = job
    st = sample_poses(path, prof, orient, rate=rate)
    assert np.allclose(np.diff(st.times), 1.0 / rate, rtol=0, atol=1e-12)
    assert st.s[0] == 0.0 and st.s[-1] == path.length and st.times[-1] >= prof.duration
    mask = cruise_stencils(st, path)
    assert mask.sum() > 100
    v = speed_5point(st.positions, rate)
    ripple = np.abs(v[mask] / prof.v(st.times[2:-2][mask]) - 1.0).max()
    assert ripple < 1e-6
    # the same time law mapped linearly onto the spline parameter (ordinary spline practice) is far off
    u0, u1 = path.knots[0], path.knots[-1]
    naive = path.points(u0 + (u1 - u0) * st.s / path.length)
    vn = speed_5point(naive, rate)
    assert np.abs(vn[mask] / prof.v(st.times[2:-2][mask]) - 1.0).max() > 1e-3


def test_evaluator_matches_the_spline():
    for seed in range(4):
        path = helix(n=25, noise=0.01, seed=seed)
        ev = SplineEvaluator.of(path)
        s = np.concatenate(([0.0, path.length], np.random.default_rng(seed).uniform(0, path.length, 500)))
        s = np.concatenate((s, path.cumulative_lengths))
        k, t = ev.locate(s)
        u = ev.parameter(k, t)
        np.testing.assert_allclose(path.arc_length(u), s, rtol=0, atol=1e-14)  # Bernstein evaluation, independent
        np.testing.assert_allclose(ev.points(k, t), path.points(u), rtol=0, atol=1e-14)
    with pytest.raises(PlannerError, match=r"s\[1\]"):
        ev.locate([0.0, -1.0])


def test_angular_speed_limit_is_honoured():
    # a tight turn between straight runs: the tool frame turns fast there
    wp = np.array([[0, 0, 0], [0.2, 0, 0], [0.25, 0.01, 0], [0.26, 0.05, 0.01], [0.25, 0.1, 0.02], [0.2, 0.12, 0.02],
                   [0.0, 0.12, 0.02]], float)
    path = fit_ph_spline(wp)
    orient = tool_orientation(frame_field(path, "rmf"))
    lim = MotionLimits(speed=1.0, acceleration=2.0, jerk=30.0, angular_speed=1.5)
    prof = plan_feed(path, 0.3, lim, orientation=orient)
    free = plan_feed(path, 0.3, MotionLimits(1.0, 2.0, 30.0), orientation=orient)
    st = sample_poses(path, prof, orient, rate=500.0)
    w = rotation_angle(st.rotations[:-1], st.rotations[1:]) * 500.0
    assert w.max() <= 1.5 * (1 + 2e-3)
    assert w.max() >= 1.5 * 0.9  # the limit binds (the cap is not needlessly low)
    st_free = sample_poses(path, free, orient, rate=500.0)
    assert (rotation_angle(st_free.rotations[:-1], st_free.rotations[1:]) * 500.0).max() > 2.0
    assert prof.duration > free.duration


class Spin:
    """Tool frame turning about a fixed axis by phi(s) = rate * s (no at_parameter: the matrix path)."""

    def __init__(self, axis, rate):
        self.axis = np.asarray(axis, float) / np.linalg.norm(axis)
        self.rate, self.R0 = rate, np.eye(3)

    def __call__(self, s):
        return Rotation.from_rotvec(np.outer(self.rate * np.atleast_1d(s), self.axis)).as_matrix() @ self.R0


@pytest.mark.parametrize("total", [1.5 * np.pi, 3.7 * np.pi])
def test_rotation_vector_is_continuous_through_pi(total):
    path = fit_ph_spline(np.column_stack((np.linspace(0, 0.5, 5), np.zeros(5), np.zeros(5))))
    prof = plan_feed(path, 0.25, LIM)
    spin = Spin([1.0, 2.0, -0.5], total / path.length)
    st = sample_poses(path, prof, spin, rate=500.0)
    r = st.poses[:, 3:]
    step = np.linalg.norm(np.diff(r, axis=0), axis=1)
    assert step.max() < 0.05  # no flip (a flip is ~ 2 pi)
    # every rotation vector is the sampled rotation
    np.testing.assert_allclose(Rotation.from_rotvec(r).as_matrix(), st.rotations, atol=1e-12)
    # continuing through pi means |r| grows past pi along the same axis: |r| = phi exactly
    np.testing.assert_allclose(np.linalg.norm(r, axis=1), spin.rate * st.s, atol=1e-9)
    assert np.linalg.norm(r[-1]) == pytest.approx(total, abs=1e-9)
    # scipy's vectors flip at pi
    sp = Rotation.from_matrix(st.rotations).as_rotvec()
    assert np.linalg.norm(np.diff(sp, axis=0), axis=1).max() > 5.0


def test_rotvec_conversions_match_scipy():
    R = Rotation.random(2000, random_state=1).as_matrix()
    R[:4] = Rotation.from_rotvec([[np.pi, 0, 0], [0, np.pi, 0], [0, 0, np.pi], [0, 0, 0]]).as_matrix()
    q = matrix_to_quaternion(R)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)
    back = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()
    np.testing.assert_allclose(back, R, atol=1e-14)
    canon = np.where(q[:, :1] < 0, -q, q)
    np.testing.assert_allclose(quaternion_to_rotvec(canon)[4:], Rotation.from_matrix(R[4:]).as_rotvec(), atol=1e-13)
    r, _ = continuous_rotvec(R[:1])
    np.testing.assert_allclose(np.linalg.norm(r), np.pi, atol=1e-15)


def test_chunks_join_continuously(job):
    path, orient, prof = job
    spin = Spin([0.0, 0.3, 1.0], 4 * np.pi / path.length)
    a = sample_poses(path, prof, spin, chunk=16)
    b = sample_poses(path, prof, spin, chunk=100000)
    # same samples; only the number of Newton steps (so the round-off) may differ per chunk
    np.testing.assert_allclose(a.poses, b.poses, rtol=0, atol=1e-14)


def test_quaternion_and_matrix_paths_agree(job):
    path, orient, prof = job
    a = sample_poses(path, prof, orient, base=[0.3, -0.2, 0.1, 0.2, -0.4, 2.9])
    b = sample_poses(path, prof, lambda s: orient(s), base=[0.3, -0.2, 0.1, 0.2, -0.4, 2.9])
    np.testing.assert_allclose(a.rotations, b.rotations, atol=1e-13)
    np.testing.assert_allclose(a.poses, b.poses, atol=1e-12)
    slow = sample_poses(path, prof, orient, inversion="path")
    fast = sample_poses(path, prof, orient)
    np.testing.assert_allclose(fast.u, slow.u, atol=1e-14)
    np.testing.assert_allclose(fast.positions, slow.positions, atol=1e-14)


def test_tcp_offset_and_base_transform(job):
    path, orient, prof = job
    tcp = np.array([0.01, -0.02, 0.15, 0.1, 0.2, -0.3])
    base = np.array([0.5, 0.1, -0.2, 0.3, -2.0, 1.0])
    st = sample_poses(path, prof, orient, tcp=tcp, base=base)
    ref = sample_poses(path, prof, orient)  # part frame, no TCP
    T_base = np.eye(4)
    T_base[:3, :3], T_base[:3, 3] = Rotation.from_rotvec(base[3:]).as_matrix(), base[:3]
    T_tcp = np.eye(4)
    T_tcp[:3, :3], T_tcp[:3, 3] = Rotation.from_rotvec(tcp[3:]).as_matrix(), tcp[:3]
    T_part = np.tile(np.eye(4), (len(ref), 1, 1))
    T_part[:, :3, :3], T_part[:, :3, 3] = ref.rotations, ref.positions
    T_tool = T_base @ T_part
    got = np.tile(np.eye(4), (len(st), 1, 1))
    got[:, :3, :3], got[:, :3, 3] = Rotation.from_rotvec(st.poses[:, 3:]).as_matrix(), st.poses[:, :3]
    np.testing.assert_allclose(got, T_tool, atol=1e-13)
    T_fl = T_tool @ np.linalg.inv(T_tcp)
    fl = st.flange_poses
    np.testing.assert_allclose(fl[:, :3], T_fl[:, :3, 3], atol=1e-13)
    np.testing.assert_allclose(Rotation.from_rotvec(fl[:, 3:]).as_matrix(), T_fl[:, :3, :3], atol=1e-13)
    np.testing.assert_allclose(st.tcp_pose, tcp, atol=1e-15)
    assert np.linalg.norm(np.diff(fl[:, 3:], axis=0), axis=1).max() < 0.05


def test_io_events_are_scheduled_with_lead_time(job):
    path, orient, prof = job
    on, off = io_window(0.1, 0.4, 3, lead_time=0.05, name="spray")
    tool = IOEvent(0.3, 1, True, output="tool")
    st = sample_poses(path, prof, orient, events=[off, tool, on])
    assert [e.event for e in st.events] == [on, tool, off]  # time order
    for e in st.events:
        assert e.time == pytest.approx(prof.time_at(e.event.s)[0] - e.event.lead_time, abs=1e-12)
        assert st.times[e.index] >= e.time - 1e-12 > st.times[e.index - 1]
    states = st.io_states()
    d3 = states[("standard", 3)]
    assert not d3[: st.events[0].index].any() and d3[st.events[0].index : st.events[2].index].all()
    assert not d3[st.events[2].index :].any()
    assert states[("tool", 1)][st.events[1].index :].all()


def test_event_before_start_warns_and_clamps(job):
    path, orient, prof = job
    with pytest.warns(IOEventWarning, match=r"events\[0\]"):
        st = sample_poses(path, prof, orient, events=[IOEvent(0.0, 0, True, lead_time=0.2)])
    assert st.events[0].time == 0.0 and st.events[0].index == 0


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(rate=0.0), "rate"),
        (dict(rate=-500.0), "rate"),
        (dict(rate=float("nan")), "rate"),
        (dict(tcp=[0, 0, np.nan, 0, 0, 0]), r"tcp\[2\]"),
        (dict(tcp=[0, 0, 0.1]), "tcp"),
        (dict(base=np.diag([1.0, 1.0, 2.0, 1.0])), "base"),
        (dict(events=[IOEvent(99.0, 0, True)]), r"events\[0\]\.s"),
        (dict(events=[IOEvent(0.1, 0, True), "spray"]), r"events\[1\]"),
        (dict(chunk=0), "chunk"),
        (dict(inversion="newton"), "inversion"),
        (dict(orientation=np.eye(3)), "orientation"),
    ],
)
def test_bad_sampling_input_names_the_parameter(job, kwargs, name):
    path, orient, prof = job
    orient = kwargs.pop("orientation", orient)
    with pytest.raises(MotionInputError, match=f"^{name}"):
        sample_poses(path, prof, orient, **kwargs)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(s=np.nan, pin=0, value=True), "s"),
        (dict(s=0.1, pin=8, value=True), "pin"),
        (dict(s=0.1, pin=2, value=True, output="tool"), "pin"),
        (dict(s=0.1, pin=0, value=True, output="analog"), "output"),
        (dict(s=0.1, pin=0, value=True, lead_time=-0.1), "lead_time"),
    ],
)
def test_bad_events_name_the_field(kwargs, name):
    with pytest.raises(MotionInputError, match=f"^{name}:"):
        IOEvent(**kwargs)
    with pytest.raises(MotionInputError, match="s_off"):
        io_window(0.5, 0.2, 0)


def test_profile_must_match_the_path(job):
    path, orient, _ = job
    with pytest.raises(MotionInputError, match="profile"):
        sample_poses(path, plan_feed(path.length * 2, 0.1, LIM), orient)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ConstantOrientation(np.eye(3))
    with pytest.raises(MotionInputError, match="R"):
        ConstantOrientation(2 * np.eye(3))
