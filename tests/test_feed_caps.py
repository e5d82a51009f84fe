"""Lowering the feed locally where robot joints would be too fast (planner.motion.caps, local_feed; planner.plan on
waypoints and CAM toolpaths; `planner plan`)."""

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


def plan_pass(points, axes, **kw):
    """One pass through the waypoints (the C2 spline through them), tool approach axes ``axes``, feed 50 mm/s."""
    from planner import PlanSettings, plan

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the tool axis passes near the direction of travel: warned, expected
        return plan(points, PlanSettings(**{"path": "interpolate", "axes": "approach", "feed": FEED, **kw}), axes=axes)


def joint_ratios(model, q, t) -> np.ndarray:
    from planner.kinematics import get_model, joint_speeds

    return np.abs(joint_speeds(q, t)) / get_model(model).speed_limits


def stream(job):
    """(t, s, poses, joints) of a one-pass job's whole trajectory at its rate (s: arc length along the pass)."""
    c = job.trajectory().collect()
    return c.times, job.moves[0].profile.s(c.times), c.poses, c.joints


def test_pass_slows_only_the_stretch_near_the_wrist_singularity():
    from planner.kinematics import inverse_path

    points, axes = near_singular_pass(0.02)
    free = plan_pass(points, axes)  # the time law without the robot
    ref = free.moves[0].profile
    t_ref, s_ref, poses_ref, _ = stream(free)
    q_ref = inverse_path("ur5e", poses_ref)
    r_ref = joint_ratios("ur5e", q_ref, t_ref).max(axis=1)
    too_fast = s_ref[1:][r_ref > 1.0]
    assert r_ref.max() > 2.0 and np.ptp(too_fast) < 0.05 * free.moves[0].path.length  # 2 x too fast, locally

    job = plan_pass(points, axes, robot="ur5e")
    assert [m.kind for m in job.moves] == ["cut"] and job.passes[0].length == free.passes[0].length
    t, s, _, q = stream(job)
    assert job.reachable and joint_ratios("ur5e", q, t).max() <= 1.0  # every sample within
    (w,) = job.passes[0].feed_caps
    assert w.start <= too_fast.min() - FEED / RATE and w.end >= too_fast.max()  # covers the violating stretch
    assert w.length <= np.ptp(too_fast) + 2e-3 and w.tag == 5 and 0.3 < w.factor < 0.5 and not w.floored
    spans = np.searchsorted(span_bounds(job.moves[0].path), too_fast, side="right") - 1
    assert w.first_span == spans.min() and w.last_span == spans.max()
    profile = job.moves[0].profile
    v = profile.v(t)
    d = scurve.distance(w.speed, FEED, LIMITS.acceleration, 5.0)
    away = cruise_mask(profile, s, w.start - d, w.end + d)
    assert away.sum() > 0.8 * t.size and np.abs(v[away] - FEED).max() <= 1e-12 * FEED
    assert profile.duration - ref.duration < 0.05 * ref.duration  # not the whole pass at 43 %
    assert job.passes[0].duration == job.duration == profile.duration
    (line,) = job.slowed  # waypoint arrays: the "line" of a record is the waypoint index
    at = {w.first_span + 1, w.last_span + 1}
    at = f"line {at.pop()}" if len(at) == 1 else f"lines {min(at)}-{max(at)}"
    assert re.fullmatch(rf"<waypoints> pass 0 \(lines 0-12\): feed lowered to \d\d\.?\d* % over 1\d\.?\d* mm at {at} "
                        r"\(joint 5 \(wrist 3\) speed\)", line)
    assert job.summary()["slowed_passes"] == [0] and job.summary()["slowed"] == [line]


def test_pass_without_a_too_fast_joint_keeps_the_profile():
    points, axes = near_singular_pass(0.25)  # the wrist stays 14 deg from its singularity
    job, free = plan_pass(points, axes, robot="ur5e"), plan_pass(points, axes)
    assert job.reachable and job.passes[0].feed_caps == () and job.slowed == ()
    a, b = job.moves[0].profile, free.moves[0].profile
    for x, y in ((a.t, b.t), (a.v0, b.v0)):
        assert np.array_equal(x, y)
    assert np.array_equal(job.trajectory().collect().poses, free.trajectory().collect().poses)
    assert job.summary()["slowed"] == [] and job.summary()["slowed_passes"] == []


def test_pass_reports_what_the_floor_cannot_fix():
    points, axes = near_singular_pass(3e-4)
    job = plan_pass(points, axes, robot="ur5e", feed_floor=0.02)
    assert job.reachable is False and job.passes[0].reachable is False
    msg = job.passes[0].reach_message
    assert msg.startswith("<waypoints> pass 0 (lines 0-12), line ") and "joint 5 (wrist 3) speed" in msg
    assert "the feed is lowered to 2 % there" in msg and job.problems == (msg,)
    caps = job.passes[0].feed_caps
    (w,) = [c for c in caps if c.floored]  # the wrist 3 stretch, at the floor; others (if any) above it
    assert w.tag == 5 and w.factor == pytest.approx(0.02, rel=1e-9)
    assert min(c.factor for c in caps) == w.factor and sum(c.length for c in caps) < 0.02  # only near it
    assert any(x.startswith("<waypoints> pass 0 (lines 0-12): feed lowered to 2 % (the floor) over ")
               and x.endswith("(joint 5 (wrist 3) speed)") for x in job.slowed)


def test_no_program_for_joints_too_fast_at_the_floor(tmp_path):
    """The controller would stop on it: the .script export refuses, naming the joint; a pose stream is written
    (its joints as planned, the too-fast stretch included)."""
    from planner.errors import PlannerError
    from planner.frontends.cli.main import export

    points, axes = near_singular_pass(3e-4)
    job = plan_pass(points, axes, robot="ur5e", feed_floor=0.02)
    with pytest.raises(PlannerError, match=r"not writing pass\.script: .*joint 5 \(wrist 3\) speed"):
        export(job, tmp_path / "pass.script", {"input": "pass.csv"})
    assert not (tmp_path / "pass.script").exists()
    assert export(job, tmp_path / "pass.csv", {"input": "pass.csv"}).endswith("poses, with joints")
    rows = [ln for ln in (tmp_path / "pass.csv").read_text().splitlines() if not ln.startswith("#")]
    assert rows[0].endswith(",q0,q1,q2,q3,q4,q5") and len(rows) - 1 == job.trajectory().n_samples


def test_cam_job_lowers_the_feed_of_the_pass_locally():
    from planner import PlanSettings, plan
    from planner.io import Toolpath

    points, axes = near_singular_pass(0.02, n=26)
    n = len(points)
    tp = Toolpath(points=points, axes=-axes, axis_given=np.ones(n, bool), feeds=np.full(n, FEED),
                  rapid=np.zeros(n, bool), lines=np.arange(10, 10 + 2 * n, 2), source="wrist.apt")
    free, job = plan(tp, PlanSettings(path="cam")), plan(tp, PlanSettings(path="cam", robot="ur5e"))
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
    # the trajectory at the controller rate, whose joints the check sampled every 2 mm: within the limits, both
    # as tracked and solved afresh
    from planner.kinematics import inverse_path

    st = job.trajectory().collect()
    assert joint_ratios("ur5e", st.joints, st.times).max() <= 1.0
    assert joint_ratios("ur5e", inverse_path("ur5e", st.poses), st.times).max() <= 1.0


def test_cli_plan_names_the_slowed_stretch(tmp_path, capsys):
    from planner.frontends.cli.main import main

    points, axes = near_singular_pass(0.02, n=26)
    src = tmp_path / "wrist.csv"
    # a file's tool axes point from the tool tip towards the spindle: the approach axes negated
    src.write_text("x,y,z,i,j,k\n" + "".join(",".join(f"{v:.12g}" for v in (*1e3 * p, *-a)) + "\n"
                                             for p, a in zip(points, axes, strict=True)))
    assert main(["plan", str(src), "--robot", "ur5e", "--feed", "50"]) == 0
    out = capsys.readouterr().out
    assert "path      interpolate:" in out and "the file's tool axes" in out
    assert "feed lowered for the joint speed limits on 1 stretch" in out
    assert re.search(r"\n    wrist\.csv pass 0 \(lines 2-27\): feed lowered to \d\d\.?\d* % over 1\d\.?\d* mm at "
                     r"lines? [\d-]+ \(joint 5 \(wrist 3\) speed\)\n", out)
    assert "ur5e: every move reachable within joint limits" in out


def test_cam_job_reports_what_the_floor_cannot_fix():
    from planner import PlanSettings, plan
    from planner.io import Toolpath

    points, axes = near_singular_pass(3e-4, n=26)
    n = len(points)
    tp = Toolpath(points=points, axes=-axes, axis_given=np.ones(n, bool), feeds=np.full(n, FEED),
                  rapid=np.zeros(n, bool), lines=np.arange(10, 10 + 2 * n, 2), source="wrist.apt")
    job = plan(tp, PlanSettings(path="cam", robot="ur5e"))
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
