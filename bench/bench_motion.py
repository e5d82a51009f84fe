"""Time law and pose sampling: feed ripple (exact arc length vs uniform parameter) and poses per second.

Run: python bench/bench_motion.py

Path: 1000 waypoints on a wavy spiral (radius 0.25..0.35 m, 6 turns, ~12 m) with CAM-like uneven
spacing (5..17 mm, neighbouring spans differ up to ~1:3),
C2 PH quintic spline, exact RMF tool frames (tool z = frame column 2), feed 0.25 m/s.

Feed ripple: TCP speed from the sampled positions by the 4th-order 5-point central difference,
relative deviation from the commanded feed, over samples whose stencil lies in a cruise phase. The
"one segment" column also keeps the stencil inside one spline segment: across a knot the C2 spline's
third derivative jumps and the 5-point formula itself errs by O((h kappa)^2) whatever the feed.
Baselines ("uniform u"): the same time law mapped linearly onto a spline parameter, what users of
ordinary splines do: on the same PH spline (chord-length knots), and on ordinary C2 cubic splines
through the same waypoints with chord-length or index (uniform) knots, the parameter scaled to the
curve's own length.

Poses per second: the whole sampler (time law, exact arc-length inversion, points, exact RMF frames,
rotation vectors), best of 5; the frame evaluation alone on the same samples is reported beside it.

Joint speed limits: a 0.5 m pass whose horizontal tool axis sweeps past a UR5e wrist singularity
(wrist 2 within 0.02 rad of 0), feed 50 mm/s, planned as waypoints with ``planner.plan`` (the C2 spline
through them, the given approach axes): the feed lowered locally where a joint would be too fast (the
robot check every 2 mm along the pass, re-planned until every check is within the limits; the peak is
measured on the 500 Hz trajectory's joints) against the whole pass at the lowest factor (what the planner
did before), best of 3.

Inverse kinematics: ``inverse_path`` (UR5e, all 8 branches solved and tracked, least-travel branch kept)
on the spiral's poses sampled at 2 kHz (~10^5 poses), best of 3; the baseline is the same function as
of commit 545be10 (before the blocked, trig-free solver and the same-branch shortcut), loaded from git
history in the same run when it is available, with the largest joint difference between the two.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import best_time, print_table  # noqa: E402

from planner import PlanSettings, plan  # noqa: E402
from planner.curves import fit_ph_spline  # noqa: E402
from planner.frames.path import frame_field  # noqa: E402
from planner.kinematics import get_model, inverse_path, joint_speeds  # noqa: E402
from planner.kinematics.reachability import JOINT_SPEED_REASONS  # noqa: E402
from planner.motion import MotionLimits, SplineEvaluator, plan_feed, sample_poses, tool_orientation  # noqa: E402

FEED = 0.25
LIMITS = MotionLimits(speed=1.0, acceleration=2.0, jerk=30.0)
CHUNK = 8192


def waypoints(n: int = 1000) -> np.ndarray:
    w = np.linspace(0.0, 1.0, n)
    w = w + 0.5 * np.sin(2 * np.pi * 50 * w) / (2 * np.pi * 50)  # uneven spacing, as CAM output is
    th = 2 * np.pi * 6 * w
    r = 0.3 + 0.05 * np.sin(3 * th)
    return np.column_stack((r * np.cos(th), r * np.sin(th), 0.2 * w))


def speed_5point(p: np.ndarray, rate: float) -> np.ndarray:
    return np.linalg.norm((-p[4:] + 8 * p[3:-1] - 8 * p[1:-3] + p[:-4]) * (rate / 12.0), axis=1)


def ripple(p, st, seg) -> tuple[float, float, int]:
    c = st.profile.in_cruise(st.times)
    cruise = c[:-4] & c[1:-3] & c[2:-2] & c[3:-1] & c[4:]
    inside = cruise & (seg[:-4] == seg[4:])
    rel = np.abs(speed_5point(p, st.rate) / st.profile.v(st.times[2:-2]) - 1.0)
    return (float(rel[inside].max()) if inside.any() else float("nan")), float(rel[cruise].max()), int(inside.sum())


class _Scaled:
    """A curve c(u) reparametrized linearly so that u runs over [0, length]: x[-1] = length."""

    def __init__(self, cs, length):
        self.cs, self.x = cs, np.array([0.0, length])
        self.k0, self.k1 = cs.x[0], cs.x[-1]

    def __call__(self, u):
        return self.cs(self.k0 + (self.k1 - self.k0) * np.asarray(u) / self.x[-1])


def main() -> None:
    wp = waypoints()
    t0 = time.perf_counter()
    path = fit_ph_spline(wp)
    t_fit = time.perf_counter() - t0
    t0 = time.perf_counter()
    field = frame_field(path, "rmf")
    t_field = time.perf_counter() - t0
    orient = tool_orientation(field, z_column=2)
    t0 = time.perf_counter()
    prof = plan_feed(path, FEED, LIMITS)
    t_plan = time.perf_counter() - t0
    lim_w = MotionLimits(LIMITS.speed, LIMITS.acceleration, LIMITS.jerk, angular_speed=1.0)
    t0 = time.perf_counter()
    prof_w = plan_feed(path, FEED, lim_w, orientation=orient)
    t_plan_w = time.perf_counter() - t0
    ev = SplineEvaluator.of(path)
    print(f"path: {len(wp)} waypoints, length {path.length:.4f} m, {path.continuity}; feed {FEED} m/s, "
          f"duration {prof.duration:.3f} s\n")

    # ordinary C2 cubic splines through the same waypoints, stepped uniformly in u (u scaled so that
    # the mean speed is right: the best a user without arc length can do)
    cubics = []
    for label, knots in (("uniform u, cubic spline, chord knots", np.concatenate(
            ([0.0], np.cumsum(np.linalg.norm(np.diff(wp, axis=0), axis=1))))),
            ("uniform u, cubic spline, index knots", np.arange(len(wp), dtype=float))):
        cs = CubicSpline(knots, wp)
        uu = np.linspace(knots[0], knots[-1], 2_000_001)
        length = np.linalg.norm(np.diff(cs(uu), axis=0), axis=1).sum()  # its own length (to ~1e-11)
        # rescale the curve's parameter so that u in [0, x_end] and stepping u at the feed covers it
        cubics.append((label, _Scaled(cs, length)))

    rows = []
    streams = {}
    for rate in (500.0, 125.0):
        st = sample_poses(path, prof, orient, rate=rate)
        streams[rate] = st
        seg, _ = ev.locate(st.s)
        u0, u1 = path.knots[0], path.knots[-1]
        cases = [("exact arc length (PH, this planner)", st.positions),
                 ("uniform u, same PH spline (chord knots)", path.points(u0 + (u1 - u0) * st.s / path.length))]
        for label, spline in cubics:
            cases.append((label, spline(spline.x[-1] * st.s / prof.length)))
        for name, p in cases:
            inside, every, n = ripple(p, st, seg)
            rows.append([name, f"{rate:.0f}", n, f"{inside:.2e}", f"{every:.2e}"])
    print("Feed ripple in cruise: max |v_sampled / v_commanded - 1| (5-point differences of positions)")
    print_table(["sampling", "rate Hz", "stencils", "ripple (one segment)", "ripple (all cruise)"], rows)

    rows = []
    for rate in (500.0, 125.0):
        st = streams[rate]
        n = len(st)
        t_all = best_time(lambda r=rate: sample_poses(path, prof, orient, rate=r))
        u = st.u

        def frames_only(u=u):
            for a in range(0, u.size, CHUNK):
                field.quaternions(u[a:a + CHUNK])

        t_fr = best_time(frames_only)
        rows.append([f"{rate:.0f}", n, f"{t_all * 1e3:.1f}", f"{n / t_all:,.0f}", f"{t_fr * 1e3:.1f}",
                     f"{100 * t_fr / t_all:.0f} %", f"{n / max(t_all - t_fr, 1e-12):,.0f}"])
    print("\nPoses generated per second (whole sampler, exact RMF frames included; target > 1e6/s)")
    print_table(["rate Hz", "poses", "time ms", "poses/s", "RMF frames ms", "frames share",
                 "poses/s without frames"], rows)

    s = streams[500.0].s[:CHUNK]
    t_fast = best_time(lambda: ev.locate(s))
    s_small = s[:: max(1, s.size // 1000)]
    t_path = best_time(lambda: path.parameter_at_length(s_small), repeat=3)
    print("\nExact arc-length inversion, per sample (same results to round-off)")
    print_table(["method", "ns/sample"], [["SplineEvaluator.locate (used)", f"{t_fast / s.size * 1e9:.0f}"],
                                          ["PHSpline.parameter_at_length", f"{t_path / s_small.size * 1e9:.0f}"]])

    print("\nOne-off setup per job")
    print_table(["step", "time s"], [
        ["fit_ph_spline (1000 waypoints, C2)", f"{t_fit:.3f}"],
        ["frame_field rmf", f"{t_field:.3f}"],
        ["plan_feed", f"{t_plan:.4f}"],
        [f"plan_feed with angular limit ({len(prof_w.commanded)} levels)", f"{t_plan_w:.3f}"],
    ])


def near_singular_pass(eps: float = 0.02, n: int = 13) -> tuple[np.ndarray, np.ndarray]:
    """Waypoints and tool axes (UR5e base frame) of a vertical 0.5 m pass whose horizontal tool axis
    (elevation eps) sweeps 80 deg about the vertical: wrist 2 passes within eps of its singularity."""
    tau = np.linspace(0.0, 1.0, n)
    points = np.array([0.1, -0.55, 0.35]) + (tau[:, None] - 0.5) * [0.0, 0.0, 0.5]
    th = np.pi + np.radians(40.0 * (2.0 * tau - 1.0))
    axes = np.column_stack((np.cos(eps) * np.cos(th), np.cos(eps) * np.sin(th), np.full(n, np.sin(eps))))
    return points, axes


def joint_speed_table() -> None:
    import warnings

    warnings.simplefilter("ignore")  # the tool axis passes near the direction of travel: warned, expected
    points, axes = near_singular_pass()
    limits = get_model("ur5e").speed_limits

    def peak(job) -> str:
        if job.settings.robot is None:
            return "-"
        c = job.trajectory().collect()
        return f"{(np.abs(joint_speeds(c.joints, c.times)) / limits).max():.3f}"

    def run(settings):
        return plan(points, settings, axes=axes)

    base = PlanSettings(path="interpolate", axes="approach", feed=0.05)
    rows = []
    for label, settings in (("no robot check", base), ("feed lowered locally (plan)", replace(base, robot="ur5e"))):
        job = run(settings)
        t = best_time(lambda s=settings: run(s), repeat=3)
        caps = job.passes[0].feed_caps
        slowed = "; ".join(w.describe(JOINT_SPEED_REASONS) for w in caps) or "-"
        rows.append([label, f"{job.duration:.3f}", peak(job), slowed, f"{t:.3f}"])
    factor = min((w.factor for w in caps), default=1.0)
    whole = run(replace(base, robot="ur5e", feed=0.05 * factor))
    rows.append([f"whole pass at {100 * factor:.3g} % (former behaviour)", f"{whole.duration:.3f}",
                 peak(whole), "the whole 500 mm", "-"])
    print("\nJoint speed limits near a UR5e wrist singularity (0.5 m pass, feed 50 mm/s, 500 Hz)")
    print_table(["plan", "duration s", "peak joint speed / limit", "slowed", "plan s"], rows)


#: The last commit with the former inverse kinematics (8 x 8 branch comparisons at every sample, sin/cos).
IK_BASELINE_COMMIT = "545be10"


def _baseline_inverse_path(poses: np.ndarray) -> tuple[float, np.ndarray] | None:
    """Best time (s) of 3 and joints of ``inverse_path`` as of IK_BASELINE_COMMIT on ``poses``: that commit's
    ``planner`` package from git history, run in a child process of its own (its modules import helpers the
    present package no longer has); None if git or the commit is not available."""
    root = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as tmp:
        try:
            tar = subprocess.run(["git", "archive", IK_BASELINE_COMMIT, "planner"], cwd=root, capture_output=True,
                                 check=True, timeout=60).stdout
            subprocess.run(["tar", "-x", "-C", tmp], input=tar, check=True, timeout=60)
        except (OSError, subprocess.SubprocessError):
            return None
        np.save(Path(tmp) / "poses.npy", poses)
        code = (
            "import sys, time, numpy as np\n"
            f"sys.path.insert(0, {tmp!r})\n"
            "from planner.kinematics.inverse import inverse_path\n"
            f"p = np.load({str(Path(tmp) / 'poses.npy')!r})\n"
            "best = float('inf')\n"
            "for _ in range(3):\n"
            "    t0 = time.perf_counter(); q = inverse_path('ur5e', p); best = min(best, time.perf_counter() - t0)\n"
            f"np.save({str(Path(tmp) / 'q.npy')!r}, q)\n"
            "print(best)\n"
        )
        try:
            out = subprocess.run([sys.executable, "-c", code], cwd=tmp, capture_output=True, text=True, check=True,
                                 timeout=600).stdout
        except (OSError, subprocess.SubprocessError):
            return None
        return float(out.split()[-1]), np.load(Path(tmp) / "q.npy")


def ik_table() -> None:
    path = fit_ph_spline(waypoints())
    orient = tool_orientation(frame_field(path, "rmf"), z_column=2)
    poses = sample_poses(path, plan_feed(path, FEED, LIMITS), orient, rate=2000.0).poses
    n = len(poses)
    q = inverse_path("ur5e", poses)
    rows = []
    t = best_time(lambda: inverse_path("ur5e", poses), repeat=3)
    rows.append(["inverse_path (this version)", n, f"{t:.3f}", f"{n / t:,.0f}", f"{t / n * 1e6:.2f}", "-"])
    old = _baseline_inverse_path(poses)
    if old is None:
        rows.append([f"inverse_path as of {IK_BASELINE_COMMIT}", n, "-", "not available (no git history)", "-", "-"])
    else:
        t_old, q_old = old
        rows.append([f"inverse_path as of {IK_BASELINE_COMMIT}", n, f"{t_old:.3f}", f"{n / t_old:,.0f}",
                     f"{t_old / n * 1e6:.2f}", f"{np.abs(q - q_old).max():.1e}"])
    print(f"\nInverse kinematics along the spiral (UR5e, {n} poses at 2 kHz, every pose reachable)")
    print_table(["method", "poses", "time s", "IK poses/s", "us/pose", "max |q - q_this| rad"], rows)


if __name__ == "__main__":
    main()
    joint_speed_table()
    ik_table()
