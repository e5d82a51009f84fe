"""Can the robot do the job? Inverse kinematics along every move, problems named by pass and line.

Each move is checked at its CAM points and every ``reach_step`` metres of path (every 0.02 rad of a
turn in place), at the times the time law reaches them; the joint trajectory follows one branch
from move to move (:func:`planner.kinematics.inverse_path`, unreachable samples allowed) and is
checked against joint position limits and, over the check spacing, joint speed limits
(:func:`planner.kinematics.check_reachability`).

Where a joint would be too fast, the move's feed is lowered locally, only over the stretch that needs
it (:func:`planner.motion.local_feed.lower_feed_locally`). Around the too-fast check intervals the
move is then rated on its own stream at the controller rate (a jump between inverse kinematics
branches looks like a fast swing at the check spacing; no feed fixes it, and the report says so);
elsewhere the check points stand, their joints independent of the time law. The re-planned profiles
and the slowed stretches (named by pass and source lines) come back in :class:`JobReach`; what the
floor of the feed cannot fix is a problem like any other.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from planner.kinematics import check_reachability, inverse_path, speed_ratios
from planner.kinematics.reachability import JOINT_SPEED_REASONS
from planner.motion import poses_at_length, tool_orientation
from planner.motion.evaluator import span_bounds
from planner.motion.local_feed import Measurement, lower_feed_locally
from planner.motion.rotvec import continuous_rotvec
from planner.motion.stream import as_transform

#: Angle step (rad) of the check along a turn in place.
TURN_STEP = 0.02


@dataclass(frozen=True)
class JobReach:
    """Reachability of a job.

    Attributes
    ----------
    passes : dict
        {pass index: message} for every pass with a problem (first problem only).
    problems : list of str
        One message per move with a problem, in order, each naming the source line.
    profiles : dict
        {move index: FeedProfile} for every move whose feed was lowered for the joint speed limits.
    windows : dict
        {move index: tuple of CapWindow} the stretches slowed on those moves (spans of the move's path).
    slowed : list of str
        One message per slowed stretch, in order, naming the pass (or move) and the source lines.
    """

    passes: dict = field(default_factory=dict)
    problems: list = field(default_factory=list)
    profiles: dict = field(default_factory=dict)
    windows: dict = field(default_factory=dict)
    slowed: list = field(default_factory=list)


def _poses_at(m, x: np.ndarray, Tb: np.ndarray) -> np.ndarray:
    """Poses (n, 6) of a move in the robot base frame at coordinates x (n,): arc length along a cut or
    rapid, angle turned on a turn in place."""
    if m.kind in ("cut", "rapid"):
        return poses_at_length(m.path, tool_orientation(m.frames), x, base=Tb)[2]
    R = np.matmul(Tb[:3, :3], m.frames.frames(x))
    r, _ = continuous_rotvec(R)
    p = np.broadcast_to(Tb[:3, :3] @ m.point + Tb[:3, 3], (x.size, 3))
    return np.hstack((p, r))


def _check_points(m, step: float, Tb: np.ndarray):
    """(poses (n, 6), times (n,), arc lengths (n,), CAM spans (n,), check coordinate (n,)) at which a move
    is checked: arc lengths and spans are None on a turn in place, whose coordinate is the angle turned."""
    if m.kind in ("cut", "rapid"):
        L = m.path.length
        b = span_bounds(m.path)
        x = np.union1d(np.linspace(0.0, L, max(2, math.ceil(L / step) + 1)), b)
        x = x[np.concatenate(([True], np.diff(x) > 1e-9 * max(L, 1.0)))]
        x[-1] = min(x[-1], L)
    else:
        angle = m.frames.angle
        x = np.linspace(0.0, angle, max(2, math.ceil(angle / TURN_STEP) + 1))
    t = m.profile.time_at(x)
    keep = np.concatenate(([True], np.diff(t) > 0.0))
    x, t = x[keep], t[keep]
    arc, span = _arc_span(m, x)
    return _poses_at(m, x, Tb), t, arc, span, x


def _arc_span(m, x: np.ndarray):
    """(arc lengths, CAM spans) of check coordinates x: both None on a turn in place."""
    if m.kind not in ("cut", "rapid"):
        return None, None
    b = span_bounds(m.path)
    return x, np.clip(np.searchsorted(b, x, side="right") - 1, 0, b.size - 2)


def _line(m, v) -> int:
    """Source line of a violation: the CAM point's record if the sample is at one, else the record of
    the motion the sample is on (the span's end point)."""
    if m.kind != "cut":
        return int(m.item.line)
    b = span_bounds(m.path)
    at = np.flatnonzero(np.abs(b - v.arc_length) <= 1e-12 * max(1.0, float(b[-1])))
    if at.size:
        return int(m.item.lines[at[0]])
    return int(m.item.lines[min(int(v.span) + 1, len(m.item) - 1)])


def _where(m, line: int) -> str:
    if m.kind == "cut":
        op = f" ({m.item.operation})" if m.item.operation else ""
        return f"pass {m.pass_index}{op} (lines {m.item.first_line}-{m.item.last_line}), line {line}"
    return f"{m.kind} at line {line}"


def _window_text(m, w) -> str:
    """A slowed stretch of a move for a person: factor, length, source lines of a cut, joint."""
    text = replace(w, first_span=None, last_span=None).describe(angular=m.kind == "reorientation")
    if m.kind == "cut":
        lines = m.item.lines
        a, b = int(lines[min(w.first_span + 1, len(lines) - 1)]), int(lines[min(w.last_span + 1, len(lines) - 1)])
        text += f" at line {a}" if a == b else f" at lines {a}-{b}"
        op = f" ({m.item.operation})" if m.item.operation else ""
        where = f"pass {m.pass_index}{op} (lines {m.item.first_line}-{m.item.last_line})"
    else:
        where = f"{m.kind} at line {m.line}"
    return f"{where}: {text} ({JOINT_SPEED_REASONS[w.tag]})"


def _regions(ratio: np.ndarray) -> list[tuple[int, int]]:
    """Check-point index ranges [a, b] around the too-fast intervals (each with its neighbours)."""
    bad = ratio > 1.0
    near = bad.copy()
    near[1:] |= bad[:-1]
    near[:-1] |= bad[1:]
    edges = np.flatnonzero(np.diff(np.concatenate(([0], near.astype(np.int8), [0]))))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))  # intervals a..b-1: points a..b


def _lower_feed(s, m, q: np.ndarray, x: np.ndarray, t: np.ndarray, Tb: np.ndarray):
    """The move's feed lowered where its joints are too fast, measured at the controller rate.

    Between the check points x (n,) (arc length, or angle of a turn) the joints q (n, 6) are only known
    every ``reach_step``: a jump between inverse kinematics branches looks like a fast swing there. So
    around the too-fast check intervals every round samples the move's own stream (local times k / rate)
    and solves the inverse kinematics there, continuing from the check point before; elsewhere the
    check points stand (their joints do not depend on the time law). The measurement's data is
    (coordinates, times, joints) of all the samples rated.
    """
    ratio0, _ = speed_ratios(s.robot, q, t)
    regions = _regions(ratio0)

    def measure(profile) -> Measurement:
        tc = profile.time_at(x)
        keep = np.ones(x.size, bool)
        xs, qs = [], []
        for a, b in regions:
            keep[a + 1 : b + 1] = False  # replaced by the samples of the stream, the end point included
            tf = np.arange(math.floor(tc[a] * s.rate) + 1, math.ceil(tc[b] * s.rate)) / s.rate
            # not within a quarter period of the ends: the joints' round-off over a tiny interval is no speed
            tf = tf[(tf > tc[a] + 0.25 / s.rate) & (tf < tc[b] - 0.25 / s.rate)]
            xf = profile.s(tf)
            xf = np.concatenate(([x[a]], xf[(xf > x[a]) & (xf < x[b])], [x[b]]))
            qf = inverse_path(s.robot, _poses_at(m, xf, Tb), q[a], tcp=s.tcp, allow_unreachable=True)
            xs.append(xf[1:])
            qs.append(qf[1:])
        xa = np.concatenate([x[keep], *xs])
        qa = np.concatenate([q[keep], *qs])
        order = np.argsort(xa, kind="stable")
        xa, qa = xa[order], qa[order]
        ta = profile.time_at(xa)
        if not (np.diff(ta) > 0.0).all():  # samples closer than the clock resolves: rate only the check
            xa, qa, ta = x, q, tc
        ratio, joint = speed_ratios(s.robot, qa, ta)
        return Measurement(xa, ta, ratio, joint, (xa, ta, qa))

    bounds = span_bounds(m.path) if m.kind in ("cut", "rapid") else None
    return lower_feed_locally(m.profile, measure, span_bounds=bounds)


def check_job(job) -> JobReach:
    """Check every move of a planned job with its robot, lowering feeds locally; see the module doc."""
    s = job.settings
    Tb = as_transform(s.part_frame, "part_frame")
    out = JobReach()
    q_prev = None
    for k, m in enumerate(job.moves):
        if m.profile is None:
            continue
        poses, t, arc, span, x = _check_points(m, s.reach_step, Tb)
        q = inverse_path(s.robot, poses, q_prev, tcp=s.tcp, allow_unreachable=True)
        rep = check_reachability(s.robot, q, t, arc_length=arc, span=span)
        if rep.n_speed and np.isfinite(q).all():
            low = _lower_feed(s, m, q, x, t, Tb)
            if low.windows:
                out.profiles[k], out.windows[k] = low.profile, low.windows
                out.slowed.extend(f"{job.source} {_window_text(m, w)}" for w in low.windows)
            x, t, q = low.measurement.data  # the samples rated last: the report names what is left
            arc, span = _arc_span(m, x)
            rep = check_reachability(s.robot, q, t, arc_length=arc, span=span)
        ok_rows = np.flatnonzero(np.isfinite(q).all(axis=1))
        q_prev = q[ok_rows[-1]] if ok_rows.size else None
        if rep.ok:
            continue
        v = rep.first
        line = _line(m, v)
        where = _where(m, line)
        what = v.describe().split(": ", 1)[-1]
        counts = f"{rep.n_unreachable} unreachable, {rep.n_position} outside joint limits, {rep.n_speed} too fast"
        msg = f"{job.source} {where}: {what} ({counts} of {len(t)} checked poses)"
        if k in out.windows:
            msg += f"; the feed is lowered to {100 * min(w.factor for w in out.windows[k]):.3g} % there"
        out.problems.append(msg)
        if m.kind == "cut":
            out.passes.setdefault(m.pass_index, msg)
    return out
