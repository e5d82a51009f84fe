"""Time law: jerk-limited S-curves, per-span feeds, limits, exact duration and arc length."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

from planner.curves import fit_ph_spline
from planner.motion import MotionInputError, MotionLimits, plan_feed, scurve, span_feeds_from_point_feeds

RATE = 500.0
LIM = MotionLimits(speed=0.5, acceleration=2.0, jerk=20.0)


def sampled(profile, rate=RATE):
    """s at the controller rate, and finite-difference speed, acceleration and jerk."""
    t = np.arange(int(np.ceil(profile.duration * rate)) + 4) / rate
    s = profile.s(t)
    dt = 1.0 / rate
    return t, s, np.diff(s) / dt, np.diff(s, 2) / dt**2, np.diff(s, 3) / dt**3


def line_path(n=11, length=1.0):
    x = np.linspace(0.0, length, n)
    return fit_ph_spline(np.column_stack((x, 0.02 * np.sin(3 * x), np.zeros(n))))


@settings(max_examples=60, deadline=None)
@given(v0=st.floats(0.0, 2.0), ell=st.floats(1e-6, 5.0), A=st.floats(0.1, 10.0), J=st.floats(0.5, 200.0))
def test_reach_is_the_inverse_of_the_transition_distance(v0, ell, A, J):
    v = scurve.reach(v0, ell, A, J)
    assert v >= v0
    # v is a float: a speed change far below v0 keeps only part of its digits, so allow the change
    # of distance that 4 ulps of v make
    ulp = abs(scurve.distance(v0, v * (1 + 4 * np.finfo(float).eps), A, J) - scurve.distance(v0, v, A, J))
    assert abs(scurve.distance(v0, v, A, J) - ell) <= 1e-12 * ell + ulp


@settings(max_examples=40, deadline=None)
@given(va=st.floats(0.0, 1.0), vb=st.floats(0.0, 1.0), A=st.floats(0.2, 5.0), J=st.floats(1.0, 100.0))
def test_transition_phases_integrate_to_the_closed_form(va, vb, A, J):
    dur, s0, v0, a0, j = scurve.transition_phases([va], [vb], [0.0], A, J)
    dur, s0, v0, a0, j = dur[0], s0[0], v0[0], a0[0], j[0]
    # chain the phases by exact integration of constant jerk: speed and distance must join up
    s, v, a = 0.0, va, 0.0
    for p in range(3):
        assert s == pytest.approx(s0[p], abs=1e-12) and v == pytest.approx(v0[p], abs=1e-12)
        assert a == pytest.approx(a0[p], abs=1e-9)
        T = dur[p]
        s += v * T + a * T**2 / 2 + j[p] * T**3 / 6
        v += a * T + j[p] * T**2 / 2
        a += j[p] * T
        assert abs(a0[p]) <= A * (1 + 1e-12)
    assert v == pytest.approx(vb, abs=1e-12) and a == pytest.approx(0.0, abs=1e-9)
    # distance against numerical quadrature of the speed
    edges = np.concatenate(([0.0], np.cumsum(dur)))

    def speed(t):
        p = min(np.searchsorted(edges, t, side="right") - 1, 2)
        tau = t - edges[p]
        return v0[p] + a0[p] * tau + j[p] * tau**2 / 2

    total = sum(quad(speed, edges[p], edges[p + 1])[0] for p in range(3) if dur[p] > 0)
    assert total == pytest.approx(scurve.distance(va, vb, A, J), rel=1e-9, abs=1e-14)


@pytest.mark.parametrize("length", [2.0, 0.05, 1e-4])
def test_single_level_duration_and_length_are_exact(length):
    prof = plan_feed(length, 0.3, LIM)
    assert prof.s(prof.duration)[0] == length
    assert prof.s(np.array([prof.duration * (1 - 1e-12)]))[0] == pytest.approx(length, rel=1e-10)
    v = prof.cruise[0]
    # two symmetric transitions of mean speed v / 2 plus the cruise: T = L / v + T_transition
    assert prof.duration == pytest.approx(length / v + scurve.duration(v, LIM.acceleration, LIM.jerk), rel=1e-12)
    if length == 2.0:
        assert v == 0.3
    else:  # too short to reach the feed: the peak's ramps fill the length
        assert v < 0.3
        assert 2 * scurve.distance(0.0, v, LIM.acceleration, LIM.jerk) == pytest.approx(length, rel=1e-9)


def test_limits_hold_on_samples():
    path = line_path(11)
    feeds = np.array([0.1, 0.45, 0.45, np.nan, 0.05, 0.4, 0.4, 0.4, 0.1, 0.9])
    prof = plan_feed(path, 0.2, LIM, span_feeds=feeds)
    t, s, v, a, j = sampled(prof)
    tol = 1e-6
    assert v.min() >= -1e-12 and v.max() <= LIM.speed * (1 + tol)
    assert np.abs(a).max() <= LIM.acceleration * (1 + tol)
    assert np.abs(j).max() <= LIM.jerk * (1 + tol)
    # the closed-form derivatives agree with the limits everywhere, and with the finite differences
    tt = np.linspace(0, prof.duration, 20001)
    assert prof.v(tt).max() <= LIM.speed + 1e-15
    assert np.abs(prof.a(tt)).max() <= LIM.acceleration * (1 + 1e-12)
    assert np.abs(prof.jerk(tt)).max() <= LIM.jerk
    mid = 0.5 * (t[1:] + t[:-1])
    # central difference of a cubic over h = dt / 2 either side: error exactly j h^2 / 6
    assert np.abs(v - prof.v(mid)).max() <= LIM.jerk * (0.5 / RATE) ** 2 / 6 * (1 + 1e-6) + 1e-12
    assert s[-1] == path.length and np.all(np.diff(s) >= 0)


def test_per_span_feeds_are_honoured():
    path = line_path(11)
    feeds = np.array([0.1, 0.45, 0.45, np.nan, 0.05, 0.4, 0.4, 0.4, 0.1, 0.9])
    prof = plan_feed(path, 0.2, LIM, span_feeds=feeds)
    bounds = path.arc_length(path.waypoint_knots)
    expect = np.minimum(np.where(np.isnan(feeds), 0.2, feeds), LIM.speed)
    t = np.linspace(0, prof.duration, 200001)
    s, v = prof.s(t), prof.v(t)
    span = np.clip(np.searchsorted(bounds, s, side="right") - 1, 0, 9)
    assert np.all(v <= expect[span] * (1 + 1e-12) + 1e-15)  # never above the span's feed
    mids = 0.5 * (bounds[1:] + bounds[:-1])
    np.testing.assert_array_equal(prof.commanded_at(mids), expect)
    level = np.clip(np.searchsorted(prof.level_bounds, s, side="right") - 1, 0, prof.commanded.size - 1)
    reached = prof.cruise == prof.commanded
    assert reached.sum() >= prof.commanded.size - 1  # only the short last span (0.9 -> 0.5 m/s) falls short
    for k in np.flatnonzero(reached):  # levels long enough cruise at exactly their feed
        inside = (level == k) & prof.in_cruise(t)
        assert inside.any(), k
        assert np.all(v[inside] == prof.commanded[k])
    last = prof.cruise[-1]  # the short last span: ramps up from the previous feed and down to rest fill it
    A, J = LIM.acceleration, LIM.jerk
    ell = prof.level_bounds[-1] - prof.level_bounds[-2]
    assert last < prof.commanded[-1]
    assert scurve.distance(prof.cruise[-2], last, A, J) + scurve.distance(last, 0.0, A, J) == pytest.approx(ell)


def test_point_feeds_map_to_spans():
    f = np.array([np.nan, 0.1, 0.2, np.nan])
    np.testing.assert_array_equal(span_feeds_from_point_feeds(f), f[1:])


def test_time_at_inverts_s():
    prof = plan_feed(line_path(11), 0.2, LIM, span_feeds=np.linspace(0.05, 0.4, 10))
    s = np.linspace(0, prof.length, 1001)
    t = prof.time_at(s)
    assert np.all(np.diff(t) > 0)
    np.testing.assert_allclose(prof.s(t), s, rtol=0, atol=1e-13)
    assert t[0] == 0.0 and t[-1] == prof.duration


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(feed=-0.1), "feed"),
        (dict(feed=float("nan")), "feed"),
        (dict(feed=0.0), "feed"),
        (dict(span_feeds=[0.1, -0.2, 0.1]), "span_feeds[1]"),
        (dict(span_feeds=[0.1, np.inf, 0.1]), "span_feeds[1]"),
        (dict(span_feeds=[0.1, 0.1]), "span_feeds"),
    ],
)
def test_bad_feed_input_names_the_parameter(kwargs, name):
    path = line_path(4)
    args = dict(feed=0.1)
    args.update(kwargs)
    with pytest.raises(MotionInputError, match=r"^" + name.replace("[", r"\[").replace("]", r"\]") + ":"):
        plan_feed(path, args.pop("feed"), LIM, **args)


@pytest.mark.parametrize("field", ["speed", "acceleration", "jerk", "angular_speed"])
@pytest.mark.parametrize("value", [0.0, -1.0, float("nan"), float("inf")])
def test_bad_limits_name_the_field(field, value):
    args = dict(speed=1.0, acceleration=1.0, jerk=1.0, angular_speed=1.0)
    args[field] = value
    with pytest.raises(MotionInputError, match=f"limits.{field}"):
        MotionLimits(**args)


def test_angular_limit_needs_an_orientation():
    with pytest.raises(MotionInputError, match="orientation"):
        plan_feed(1.0, 0.1, MotionLimits(1, 1, 1, angular_speed=1.0))


class SpanPath:
    """A stand-in path: only the span ends matter to the time law (arc length = parameter)."""

    def __init__(self, bounds):
        self.waypoint_knots = np.asarray(bounds, float)
        self.length = float(self.waypoint_knots[-1])

    def arc_length(self, u):
        return np.asarray(u, float)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(1, 12),
    A=st.floats(0.2, 5.0),
    J=st.floats(2.0, 200.0),
)
def test_random_span_feeds_respect_every_limit(seed, n, A, J):
    rng = np.random.default_rng(seed)
    spans = rng.uniform(0.001, 0.3, n)
    feeds = rng.uniform(0.01, 0.6, n)
    feeds[rng.random(n) < 0.2] = np.nan
    lim = MotionLimits(speed=0.5, acceleration=A, jerk=J)
    path = SpanPath(np.concatenate(([0.0], np.cumsum(spans))))
    prof = plan_feed(path, 0.2, lim, span_feeds=feeds)
    assert prof.s(prof.duration)[0] == path.length
    # phases join up: integrating each phase exactly lands on the next phase's start values
    dur = np.diff(prof.t)
    s_end = prof.s0 + prof.v0 * dur + prof.a0 * dur**2 / 2 + prof.j * dur**3 / 6
    v_end = prof.v0 + prof.a0 * dur + prof.j * dur**2 / 2
    a_end = prof.a0 + prof.j * dur
    np.testing.assert_allclose(s_end[:-1], prof.s0[1:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(v_end[:-1], prof.v0[1:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(a_end[:-1], prof.a0[1:], rtol=0, atol=1e-9)
    assert s_end[-1] == pytest.approx(path.length, abs=1e-12) and abs(v_end[-1]) < 1e-12 and abs(a_end[-1]) < 1e-9
    # limits at the phase ends (extremes of each phase: v is monotone or has its peak where a = 0)
    assert np.all(prof.v0 >= -1e-15) and np.all(v_end >= -1e-12)
    assert np.all(np.abs(prof.a0) <= A * (1 + 1e-12)) and np.all(np.abs(prof.j) <= J)
    # never above the span's feed: check the speed at every phase end against the feed where it is
    cmd = np.minimum(np.where(np.isnan(feeds), 0.2, feeds), 0.5)
    ends = np.concatenate((prof.s0, [path.length]))
    speeds = np.concatenate((prof.v0, [0.0]))
    for s_at, v_at in ((ends[:-1], speeds[:-1]), (ends[1:], np.concatenate((v_end[:-1], [0.0])))):
        k_lo = np.clip(np.searchsorted(path.waypoint_knots, s_at, side="left") - 1, 0, n - 1)
        k_hi = np.clip(np.searchsorted(path.waypoint_knots, s_at, side="right") - 1, 0, n - 1)
        assert np.all(v_at <= np.maximum(cmd[k_lo], cmd[k_hi]) * (1 + 1e-12) + 1e-15)
        inside = k_lo == k_hi
        assert np.all(v_at[inside] <= cmd[k_lo][inside] * (1 + 1e-12) + 1e-15)
