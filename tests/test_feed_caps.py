"""Lowering the feed locally where robot joints would be too fast (planner.motion.caps, local_feed, plan_job,
CAM jobs, `planner plan`)."""

from __future__ import annotations

import math
import re
import warnings

import numpy as np
import pytest

from planner.motion import MotionLimits, plan_feed, scurve, span_bounds
from planner.motion.caps import FeedCaps, caps_from_ratios
from planner.motion.feed import cap_feed
from planner.motion.limits import MotionInputError
from planner.motion.local_feed import Measurement, lower_feed_locally

LIMITS = MotionLimits(speed=0.5, acceleration=0.5, jerk=5.0)
FEED = 0.05
RATE = 500.0


def samples(profile, rate: float = RATE) -> tuple[np.ndarray, np.ndarray]:
    """(t, s) of a profile at the controller rate, the last sample at or after the end."""
    t = np.arange(int(np.ceil(profile.duration * rate - 1e-9)) + 1) / rate
    return t, profile.s(t)


def cruise_mask(profile, s, lo: float, hi: float) -> np.ndarray:
    """Samples at arc lengths s outside [lo, hi] and outside the start and end ramps of the profile."""
    ramp = scurve.distance(0.0, FEED, LIMITS.acceleration, LIMITS.jerk)
    return ((s < lo) | (s > hi)) & (s > ramp) & (s < profile.length - ramp)


# --- caps on a feed profile --------------------------------------------------------------------------


def test_capped_profile_never_exceeds_a_cap_and_is_unchanged_away_from_it():
    L = 1.0
    caps = FeedCaps.on_intervals([0.40, 0.60], [0.45, 0.62], [0.02, 0.035], [5, 3], L)
    prof = plan_feed(L, FEED, LIMITS, caps=caps)
    t = np.linspace(0.0, prof.duration, 200_001)
    s, v = prof.s(t), prof.v(t)
    cap, tag = caps.at(s)
    assert np.all(v <= np.minimum(cap, FEED) * (1 + 1e-12))
    assert set(np.unique(tag)) == {-1, 3, 5}
    # away from the caps and the speed changes into and out of them: the commanded feed
    d = scurve.distance(0.02, FEED, LIMITS.acceleration, LIMITS.jerk)
    away = cruise_mask(prof, s, 0.40 - d, 0.62 + d)
    assert away.sum() > 100_000 and np.abs(v[away] - FEED).max() <= 1e-12 * FEED
    # the tool cruises at the cap inside the long capped window
    inside = (s > 0.401) & (s < 0.449)
    assert np.abs(v[inside] - 0.02).max() <= 1e-12
    # re-planning a planned profile under the same caps gives the same time law
    again = cap_feed(plan_feed(L, FEED, LIMITS), caps)
    assert np.allclose(again.t, prof.t, rtol=0, atol=1e-12) and np.allclose(again.v0, prof.v0, rtol=0, atol=1e-15)


def test_no_caps_leave_the_profile_unchanged():
    prof = plan_feed(0.7, FEED, LIMITS, span_feeds=None)
    same = cap_feed(prof, FeedCaps.none(0.7))
    for a, b in ((same.t, prof.t), (same.s0, prof.s0), (same.v0, prof.v0), (same.j, prof.j)):
        assert np.array_equal(a, b)
    high = cap_feed(prof, FeedCaps.on_intervals([0.2], [0.3], [2 * FEED], [0], 0.7))  # above the feed: no effect
    assert np.array_equal(high.t, prof.t) and np.array_equal(high.v0, prof.v0)


def test_tighten_is_the_pointwise_minimum():
    L = 1.0
    a = FeedCaps.on_intervals([0.1, 0.5], [0.3, 0.7], [0.02, 0.04], [1, 2], L)
    b = FeedCaps.on_intervals([0.25, 0.65], [0.55, 0.9], [0.03, 0.01], [3, 4], L)
    c = a.tighten(b)
    x = np.random.default_rng(1).uniform(0, L, 5000)
    (ca, ta), (cb, tb), (cc, tc) = a.at(x), b.at(x), c.at(x)
    assert np.array_equal(cc, np.minimum(ca, cb))
    assert np.array_equal(tc, np.where(cb < ca, tb, ta))
    assert c.tighten(a).same_as(c) and not c.same_as(a)


def test_caps_from_ratios_cover_the_too_fast_intervals():
    prof = plan_feed(0.5, FEED, LIMITS)
    t, s = samples(prof)
    ratio = np.zeros(t.size - 1)
    assert not caps_from_ratios(s, t, ratio, np.zeros(ratio.size, int), prof)[0].active
    mid = 0.5 * (s[1:] + s[:-1])
    ratio = 1.6 * np.exp(-(((mid - 0.25) / 0.004) ** 2))  # too fast over about 5 mm
    caps, floored = caps_from_ratios(s, t, ratio, np.full(ratio.size, 4), prof, margin=0.9)
    assert not floored
    bad = ratio > 1.0
    cap, tag = caps.at(mid[bad])
    v = np.diff(s) / np.diff(t)
    assert np.all(cap <= v[bad] * 0.9 / ratio[bad] * (1 + 1e-12)) and np.all(tag == 4)
    assert np.all(cap >= v[bad] * 0.9 / ratio.max() / 1.02 * (1 - 1e-12))  # not lower than the worst need
    far = np.abs(mid - 0.25) > 0.01
    assert np.all(np.isinf(caps.at(mid[far])[0]))
    floor_caps, floored = caps_from_ratios(s, t, 1000 * ratio, np.zeros(ratio.size, int), prof, floor=0.05)
    assert floored and floor_caps.at([0.25])[0][0] == pytest.approx(0.05 * FEED, rel=1e-12)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda p: cap_feed(p, "slow"), r"caps: must be a FeedCaps"),
        (lambda p: plan_feed(p.length, FEED, LIMITS, caps=FeedCaps.none(2.0)), r"caps: were made for length 2.0"),
        (lambda p: FeedCaps.on_intervals([0.3, 0.1], [0.4, 0.2], [1, 1], [0, 0], 1.0), r"sorted and disjoint"),
        (lambda p: FeedCaps.on_intervals([0.3], [0.4], [0.0], [0], 1.0), r"caps\[0\]: speed must be > 0"),
        (lambda p: caps_from_ratios([0, 1], [0, 1], [2.0], [0], p, margin=1.5), r"margin"),
        (lambda p: caps_from_ratios([0, 1], [0, 1], [2.0, 1.0], [0, 0], p), r"ratio: expected shape \(1,\)"),
        (lambda p: lower_feed_locally(p, None, rounds=-1), r"rounds: must be an integer >= 0"),
    ],
)
def test_bad_caps_input_names_the_parameter(call, message):
    with pytest.raises(MotionInputError, match=message):
        call(plan_feed(1.0, FEED, LIMITS))


# --- the iteration on a real, analytic joint: a wrist swinging by pi near a singularity ---------------


def swing(width: float, limit: float = 2.0, s0: float = 0.5):
    """Measurement of a joint q(s) = atan((s - s0) / width) (rad) sampled at the controller rate: it turns
    by pi, fastest at s0 (1 / width rad/m), like a wrist passing a singularity at distance ~width."""

    def measure(profile) -> Measurement:
        t, s = samples(profile)
        q = np.arctan((s - s0) / width)
        ratio = np.abs(np.diff(q) / np.diff(t)) / limit
        return Measurement(s, t, ratio, np.full(ratio.size, 4), (t, s, ratio))

    return measure


def test_feed_is_lowered_only_where_the_joint_is_too_fast():
    ref = plan_feed(1.0, FEED, LIMITS)
    measure = swing(0.01)  # 5 rad/s at the feed: 2.5 times too fast at s0
    _, s_ref, r_ref = measure(ref).data
    too_fast = s_ref[1:][r_ref > 1.0]
    out = lower_feed_locally(ref, measure)
    t, s, ratio = out.measurement.data
    assert out.ok and not out.floored and 1 <= out.rounds <= 3
    assert ratio.max() <= 1.0
    (w,) = out.windows
    assert w.start <= too_fast.min() - 1e-4 and w.end >= too_fast.max()  # covers the stretch (sample spacing)
    assert w.length < np.ptp(too_fast) + 2e-3  # and not much more
    assert 0.95 * 0.4 / 1.02 <= w.factor <= 0.4 and w.tag == 4
    assert re.fullmatch(r"feed lowered to 3\d\.?\d? % over 2\d\.?\d? mm \(x\)", w.describe(["", "", "", "", "x"]))
    v = out.profile.v(t)
    d = scurve.distance(w.speed, FEED, LIMITS.acceleration, LIMITS.jerk)
    away = cruise_mask(out.profile, s, w.start - d, w.end + d)
    assert away.sum() > 0.85 * s.size and np.abs(v[away] - FEED).max() <= 1e-12 * FEED
    # far cheaper than lowering the feed of the whole path
    assert out.profile.duration - ref.duration < 0.1 * ref.duration
    assert plan_feed(1.0, FEED * w.factor, LIMITS).duration > 2 * ref.duration


def test_nothing_too_fast_leaves_the_profile_alone():
    ref = plan_feed(1.0, FEED, LIMITS)
    out = lower_feed_locally(ref, swing(0.1))  # 0.5 rad/s at most
    assert out.ok and out.rounds == 0 and out.windows == () and out.profile is ref and not out.caps.active


def test_a_jump_no_feed_can_fix_is_reported_at_the_floor():
    ref = plan_feed(1.0, FEED, LIMITS)
    out = lower_feed_locally(ref, swing(1e-6), floor=0.05)  # pi rad within microns
    assert not out.ok and out.floored
    (w,) = out.windows
    assert w.floored and w.factor == pytest.approx(0.05, rel=1e-9) and "(the floor)" in w.describe()
    assert out.measurement.data[2].max() > 1.0


# --- real robot jobs: a UR5e wrist passing close to its singularity ----------------------------------


def near_singular_pass(eps: float, n: int = 13):
    """A 0.5 m vertical pass in the UR5e base frame whose horizontal tool axis (elevation ``eps`` rad)
    sweeps 80 deg about the vertical: the wrist 2 angle passes within ``eps`` of 0 (every IK branch),
    so wrists 1 and 3 swing by about pi over a short stretch (~16 mm for eps = 0.02 at 50 mm/s)."""
    tau = np.linspace(0.0, 1.0, n)
    points = np.array([0.1, -0.55, 0.35]) + (tau[:, None] - 0.5) * [0.0, 0.0, 0.5]
    th = np.pi + np.radians(40.0 * (2.0 * tau - 1.0))
    axes = np.column_stack((math.cos(eps) * np.cos(th), math.cos(eps) * np.sin(th), np.full(n, math.sin(eps))))
    return points, axes


def plan(points, axes, **kw):
    from planner.job import JobSettings, plan_job

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return plan_job(points, axes, JobSettings(feed=FEED, **kw))


def joint_ratios(model, q, t) -> np.ndarray:
    from planner.kinematics import get_model, joint_speeds

    return np.abs(joint_speeds(q, t)) / get_model(model).speed_limits


def test_plan_job_slows_only_the_stretch_near_the_wrist_singularity():
    from planner.kinematics import inverse_path

    points, axes = near_singular_pass(0.02)
    free = plan(points, axes, robot=None)  # the time law without the robot
    ref = free.profile
    q_ref = inverse_path("ur5e", free.stream.poses)
    r_ref = joint_ratios("ur5e", q_ref, free.stream.times).max(axis=1)
    too_fast = free.stream.s[1:][r_ref > 1.0]
    assert r_ref.max() > 2.0 and np.ptp(too_fast) < 0.05 * free.path.length  # 2 x too fast, locally

    job = plan(points, axes, robot="ur5e")
    t, s = job.stream.times, job.stream.s
    assert job.reachability.ok and joint_ratios("ur5e", job.joints, t).max() <= 1.0  # every sample within
    (w,) = job.feed_caps
    assert w.start <= too_fast.min() - FEED / RATE and w.end >= too_fast.max()  # covers the violating stretch
    assert w.length <= np.ptp(too_fast) + 2e-3 and w.tag == 5 and 0.3 < w.factor < 0.5
    spans = np.searchsorted(span_bounds(job.path), too_fast, side="right") - 1
    assert w.first_span == spans.min() and w.last_span == spans.max()
    assert job.feed_scale == w.factor
    v = job.profile.v(t)
    d = scurve.distance(w.speed, FEED, LIMITS.acceleration, 5.0)
    away = cruise_mask(job.profile, s, w.start - d, w.end + d)
    assert away.sum() > 0.8 * t.size and np.abs(v[away] - FEED).max() <= 1e-12 * FEED
    assert job.profile.duration - ref.duration < 0.05 * ref.duration  # not the whole pass at 43 %
    r = job.summary()
    (line,) = r["feed_lowered"]
    assert re.fullmatch(rf"feed lowered to \d\d\.?\d* % over 1\d\.?\d* mm at span {w.first_span} "
                        r"\(joint 5 \(wrist 3\) speed\)", line)
    assert r["feed_caps"][0]["joint"] == 5 and r["feed_caps"][0]["spans"] == [w.first_span, w.last_span]


def test_plan_job_without_a_too_fast_joint_keeps_the_profile():
    points, axes = near_singular_pass(0.25)  # the wrist stays 14 deg from its singularity
    job, free = plan(points, axes, robot="ur5e"), plan(points, axes, robot=None)
    assert job.reachability.ok and job.feed_caps == () and job.feed_scale == 1.0 and job.feed_rounds == 0
    for a, b in ((job.profile.t, free.profile.t), (job.profile.v0, free.profile.v0), (job.stream.s, free.stream.s)):
        assert np.array_equal(a, b)
    assert job.summary()["feed_lowered"] == []


def test_plan_job_reports_what_the_floor_cannot_fix():
    points, axes = near_singular_pass(3e-4)
    job = plan(points, axes, robot="ur5e", feed_floor=0.02)
    assert not job.reachability.ok and job.reachability.first.kind == "speed"
    (w,) = job.feed_caps
    assert w.floored and w.factor == pytest.approx(0.02, rel=1e-9)
    assert "feed lowered to 2 % (the floor)" in job.summary()["feed_lowered"][0]


def test_no_servoj_program_for_joints_too_fast_at_the_floor(tmp_path):
    """The controller would stop on it: the .script export refuses, naming the joint; a pose stream is written."""
    from pathlib import Path

    from planner.cli import _export
    from planner.errors import PlannerError

    points, axes = near_singular_pass(3e-4)
    job = plan(points, axes, robot="ur5e", feed_floor=0.02)
    with pytest.raises(PlannerError, match=r"not writing pass\.script: .*speed"):
        _export(job, tmp_path / "pass.script", Path("pass.csv"))
    assert not (tmp_path / "pass.script").exists()
    _export(job, tmp_path / "pass.csv", Path("pass.csv"))
    assert (tmp_path / "pass.csv").stat().st_size > 0


def test_cam_job_lowers_the_feed_of_the_pass_locally():
    from planner.cam import plan_cam_job
    from planner.io import Toolpath

    points, axes = near_singular_pass(0.02, n=26)
    n = len(points)
    tp = Toolpath(points=points, axes=-axes, axis_given=np.ones(n, bool), feeds=np.full(n, FEED),
                  rapid=np.zeros(n, bool), lines=np.arange(10, 10 + 2 * n, 2), source="wrist.apt")
    free, job = plan_cam_job(tp), plan_cam_job(tp, robot="ur5e")
    assert job.reachable and not job.problems
    (w,) = job.passes[0].feed_caps
    assert w.tag == 5 and 0.3 < w.factor < 0.5 and w.length < 0.03
    assert job.passes[0].duration == job.duration > free.duration
    assert job.duration - free.duration < 0.05 * free.duration
    (msg,) = job.slowed
    lines = {int(tp.lines[w.first_span + 1]), int(tp.lines[w.last_span + 1])}  # the records moving there
    at = f"line {lines.pop()}" if len(lines) == 1 else f"lines {min(lines)}-{max(lines)}"
    assert re.fullmatch(rf"wrist\.apt pass 0 \(lines 10-60\): feed lowered to \d\d\.?\d* % over \d\d\.?\d* mm "
                        rf"at {at} \(joint 5 \(wrist 3\) speed\)", msg)
    assert any("feed lowered for the joint speed limits on 1 stretch" in x for x in job.describe())
    assert job.summary()["slowed_passes"] == [0]
    # the stream at the controller rate, whose joints the check sampled every 2 mm
    from planner.kinematics import inverse_path

    st = job.pose_stream()
    assert joint_ratios("ur5e", inverse_path("ur5e", st.poses), st.times).max() <= 1.0


def test_cli_plan_names_the_slowed_stretch(tmp_path, capsys):
    from planner.cli import main

    points, axes = near_singular_pass(0.02, n=26)
    src = tmp_path / "wrist.csv"
    src.write_text("x,y,z,i,j,k\n" + "".join(",".join(f"{v:.12g}" for v in (*1e3 * p, *a)) + "\n"
                                             for p, a in zip(points, axes, strict=True)))
    assert main(["plan", str(src), "--robot", "ur5e", "--feed", "50"]) == 0
    out = capsys.readouterr().out
    assert "feed lowered for the joint speed limits on 1 stretch" in out
    assert re.search(r"slowed +feed lowered to \d\d\.?\d* % over 1\d\.?\d* mm at spans? [\d-]+ "
                     r"\(joint 5 \(wrist 3\) speed\), lines? \d+", out)
    assert "all" in out and "within joint position and speed limits" in out


def test_cam_job_reports_what_the_floor_cannot_fix():
    from planner.cam import plan_cam_job
    from planner.io import Toolpath

    points, axes = near_singular_pass(3e-4, n=26)
    n = len(points)
    tp = Toolpath(points=points, axes=-axes, axis_given=np.ones(n, bool), feeds=np.full(n, FEED),
                  rapid=np.zeros(n, bool), lines=np.arange(10, 10 + 2 * n, 2), source="wrist.apt")
    job = plan_cam_job(tp, robot="ur5e")
    assert job.reachable is False and job.passes[0].reachable is False
    caps = job.passes[0].feed_caps
    assert any(w.floored for w in caps) and min(w.factor for w in caps) == pytest.approx(0.01, rel=1e-9)
    assert sum(w.length for w in caps) < 0.02  # still only around the singularity
    msg = job.passes[0].reach_message
    assert msg.startswith("wrist.apt pass 0 (lines 10-60), line ") and "joint 5 (wrist 3) speed" in msg
    # no other arm configuration helps: the message says why and what the user can do
    assert "at the wrist singularity (|sin q5| = " in msg
    assert msg.endswith("the feed is lowered to 1 % there; none of the 7 other arm configurations makes it feasible "
                        "either; re-place the part (part frame) or tilt the tool so that its axis stays away from the "
                        "shoulder axis there")
    assert not job.reconfigurations and job.count("reconfiguration") == 0
