"""Can the robot do the job? Inverse kinematics along every move, problems named by pass and line.

Each move is checked at its CAM points and every ``reach_step`` metres of path (every 0.02 rad of a
turn in place), at the times the time law reaches them; the joint trajectory follows one branch
from move to move (:func:`planner.kinematics.inverse_path`, unreachable samples allowed) and is
checked against joint position limits and, over the check spacing, joint speed limits
(:func:`planner.kinematics.check_reachability`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from planner.kinematics import check_reachability, inverse_path
from planner.motion import poses_at_length, tool_orientation
from planner.motion.evaluator import span_bounds
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
    """

    passes: dict = field(default_factory=dict)
    problems: list = field(default_factory=list)


def _check_points(m, step: float, Tb: np.ndarray):
    """(poses (n, 6), times (n,), arc lengths (n,), CAM spans (n,)) at which a move is checked."""
    if m.kind in ("cut", "rapid"):
        L = m.path.length
        b = span_bounds(m.path)
        s = np.union1d(np.linspace(0.0, L, max(2, math.ceil(L / step) + 1)), b)
        s = s[np.concatenate(([True], np.diff(s) > 1e-9 * max(L, 1.0)))]
        s[-1] = min(s[-1], L)
        t = m.profile.time_at(s)
        keep = np.concatenate(([True], np.diff(t) > 0.0))
        s, t = s[keep], t[keep]
        _, _, poses = poses_at_length(m.path, tool_orientation(m.frames), s, base=Tb)
        span = np.clip(np.searchsorted(b, s, side="right") - 1, 0, b.size - 2)
        return poses, t, s, span
    angle = m.frames.angle
    a = np.linspace(0.0, angle, max(2, math.ceil(angle / TURN_STEP) + 1))
    t = m.profile.time_at(a)
    keep = np.concatenate(([True], np.diff(t) > 0.0))
    a, t = a[keep], t[keep]
    R = np.matmul(Tb[:3, :3], m.frames.frames(a))
    r, _ = continuous_rotvec(R)
    p = np.broadcast_to(Tb[:3, :3] @ m.point + Tb[:3, 3], (a.size, 3))
    return np.hstack((p, r)), t, None, None


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


def check_job(job) -> JobReach:
    """Check every move of a planned job with its robot; see the module doc."""
    s = job.settings
    Tb = as_transform(s.part_frame, "part_frame")
    out = JobReach()
    q_prev = None
    for m in job.moves:
        if m.profile is None:
            continue
        poses, t, arc, span = _check_points(m, s.reach_step, Tb)
        q = inverse_path(s.robot, poses, q_prev, tcp=s.tcp, allow_unreachable=True)
        rep = check_reachability(s.robot, q, t, arc_length=arc, span=span)
        ok_rows = np.flatnonzero(np.isfinite(q).all(axis=1))
        q_prev = q[ok_rows[-1]] if ok_rows.size else None
        if rep.ok:
            continue
        v = rep.first
        line = _line(m, v)
        if m.kind == "cut":
            op = f" ({m.item.operation})" if m.item.operation else ""
            where = f"pass {m.pass_index}{op} (lines {m.item.first_line}-{m.item.last_line}), line {line}"
        else:
            where = f"{m.kind} at line {line}"
        what = v.describe().split(": ", 1)[-1]
        counts = f"{rep.n_unreachable} unreachable, {rep.n_position} outside joint limits, {rep.n_speed} too fast"
        msg = f"{job.source} {where}: {what} ({counts} of {len(t)} checked poses)"
        out.problems.append(msg)
        if m.kind == "cut":
            out.passes.setdefault(m.pass_index, msg)
    return out
