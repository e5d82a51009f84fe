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

The arm configuration (inverse-kinematics branch and whole turns) is chosen per run of passes
(:mod:`planner.cam.configure`): the moves before a run and the run itself are first checked on the
configuration the arm is in. If that fails (out of reach, outside the joint limits, or a jump or swing
the feed floor cannot slow: the arm stretched out of reach on that branch, or passing the wrist
singularity), the other configurations are tried, nearest in joint space first, starting at the safe
point of a rapid before the run (before the first rapid that fails, if one does); the first on which the
rest of the rapids and the run have no problem is taken, and the change is a joint move there
(:class:`planner.cam.moves.Reconfiguration`). At the job start the arm simply starts on it. Where no
configuration helps, the problem is reported as before, with what causes it (wrist singularity, arm
stretched out) and what the user can do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from planner.cam.configure import (
    candidates,
    describe_change,
    groups,
    safe_point,
    tcp_excursion,
    turn_shift,
    where_text,
)
from planner.cam.moves import Reconfiguration
from planner.kinematics import check_reachability, inverse_path, speed_ratios
from planner.kinematics.poses import as_transform
from planner.kinematics.reachability import JOINT_SPEED_REASONS
from planner.motion import poses_at_length, tool_orientation
from planner.motion.evaluator import span_bounds
from planner.motion.local_feed import Measurement, lower_feed_locally
from planner.motion.rotvec import continuous_rotvec

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
    reconfigurations : list of (int, Reconfiguration)
        Changes of the arm configuration: the move (index in ``PlannedJob.moves``) to insert each before.
    start_joints : ndarray (6,) or None
        Joints at the job's first pose (rad), on the configuration the check followed.
    start_note : str
        Why the arm starts on another configuration than the one of least joint travel ("" if it does not).
    """

    passes: dict = field(default_factory=dict)
    problems: list = field(default_factory=list)
    profiles: dict = field(default_factory=dict)
    windows: dict = field(default_factory=dict)
    slowed: list = field(default_factory=list)
    reconfigurations: list = field(default_factory=list)
    start_joints: np.ndarray | None = None
    start_note: str = ""


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
    return lower_feed_locally(m.profile, measure, span_bounds=bounds, floor=s.feed_floor)


@dataclass(frozen=True, eq=False)
class MoveCheck:
    """One move checked from a start joint vector (see :func:`check_move`).

    Attributes
    ----------
    k : int
        Index of the move in ``PlannedJob.moves``.
    q, t : ndarray (n, 6), (n,)
        Joints (rad; rows of NaN: unreachable) and times (s) of the samples rated last.
    problem : str
        The first problem, naming the pass or move and the source line ("" if none).
    profile : FeedProfile or None
        The move's time law with the feed lowered locally (None: unchanged).
    windows : tuple of CapWindow
        The stretches slowed (empty if none).
    slowed : tuple of str
        One message per slowed stretch.
    cause : str
        What makes the first problem, if it is a joint too fast: "wrist" (the wrist singularity), "elbow"
        (the arm stretched out of reach), "jump" (another jump between branches) or "".
    """

    k: int
    q: np.ndarray
    t: np.ndarray
    problem: str = ""
    profile: object = None
    windows: tuple = ()
    slowed: tuple = ()
    cause: str = ""

    @property
    def ok(self) -> bool:
        return not self.problem

    @property
    def q_end(self) -> np.ndarray | None:
        """The last reachable joint vector (None if none is)."""
        rows = np.flatnonzero(np.isfinite(self.q).all(axis=1))
        return self.q[rows[-1]] if rows.size else None


#: |sin q5| (wrist singularity) and |sin q3| (arm stretched out) below which a joint too fast is put down to
#: that singularity.
WRIST_HINT = 0.05
ELBOW_HINT = 0.15
#: A step with a joint faster than this (rad) between two rated samples is a jump to another branch.
_JUMP = 0.5


def _diagnosis(q: np.ndarray, i: int) -> tuple[str, str]:
    """Why a joint is too fast between samples i - 1 and i of joints q, for a person: (kind, text).

    kind is "wrist" (the wrist passes its singularity: wrist 2 near 0 or pi, wrists 1 and 3 swing round),
    "elbow" (the arm is stretched out: this configuration runs out of reach and the joints jump to another
    branch), "jump" (another jump between branches) or "" (a fast swing with no singularity near).
    """
    a, b = q[max(i - 1, 0)], q[i]
    step = np.abs(b - a)
    if step[4] < _JUMP:  # q5 moves continuously: the wrist may pass its singularity (q5 = 0 or pi)
        crossing = np.floor(a[4] / np.pi) != np.floor(b[4] / np.pi)
        sine = 0.0 if crossing else float(min(abs(np.sin(a[4])), abs(np.sin(b[4]))))
        if sine < WRIST_HINT:
            near = "wrist 2 passes through 0" if crossing else f"|sin q5| = {sine:.2g}"
            return "wrist", (f"at the wrist singularity ({near}: the tool axis is parallel to the shoulder axis there, "
                             "and wrists 1 and 3 swing round)")
    if step.max() < _JUMP:
        return "", ""
    if abs(np.sin(a[2])) < ELBOW_HINT:
        return "elbow", (f"where the arm is stretched out (elbow at {a[2]:.2g} rad): this arm configuration runs out "
                         "of reach and the joints jump to another one")
    return "jump", "where the joints jump to another arm configuration"


class _Checker:
    """Checks moves of one job from given start joints; the check points of every move are computed once."""

    def __init__(self, job):
        self.job = job
        self.s = job.settings
        self.Tb = as_transform(self.s.part_frame, "part_frame")
        self._points: dict = {}

    def points(self, k: int):
        """(poses, times, arc lengths, spans, coordinates) of move k's check points (see _check_points)."""
        if k not in self._points:
            self._points[k] = _check_points(self.job.moves[k], self.s.reach_step, self.Tb)
        return self._points[k]

    def move(self, k: int, q_start) -> MoveCheck:
        """Move k checked from joints q_start (None: the branch of least joint travel): inverse kinematics at
        its check points, the feed lowered locally where a joint is too fast, the first problem named."""
        job, s, m = self.job, self.s, self.job.moves[k]
        poses, t, arc, span, x = self.points(k)
        q = inverse_path(s.robot, poses, q_start, tcp=s.tcp, allow_unreachable=True)
        rep = check_reachability(s.robot, q, t, arc_length=arc, span=span)
        profile = None
        windows: tuple = ()
        slowed: tuple[str, ...] = ()
        if rep.n_speed and np.isfinite(q).all():
            low = _lower_feed(s, m, q, x, t, self.Tb)
            if low.windows:
                profile, windows = low.profile, tuple(low.windows)
                slowed = tuple(f"{job.source} {_window_text(m, w)}" for w in low.windows)
            x, t, q = low.measurement.data  # the samples rated last: the report names what is left
            arc, span = _arc_span(m, x)
            rep = check_reachability(s.robot, q, t, arc_length=arc, span=span)
        if rep.ok:
            return MoveCheck(k, q, t, "", profile, windows, slowed)
        v = rep.first
        assert v is not None  # a report that is not ok names its first problem
        where = _where(m, _line(m, v))
        what = v.describe().split(": ", 1)[-1]
        cause, text = _diagnosis(q, v.index) if v.kind == "speed" else ("", "")
        if text:
            what += " " + text
        counts = f"{rep.n_unreachable} unreachable, {rep.n_position} outside joint limits, {rep.n_speed} too fast"
        msg = f"{job.source} {where}: {what} ({counts} of {len(t)} checked poses)"
        if windows:
            msg += f"; the feed is lowered to {100 * min(w.factor for w in windows):.3g} % there"
        return MoveCheck(k, q, t, msg, profile, windows, slowed, cause)

    def moves(self, ks, q_start) -> list[MoveCheck]:
        """Moves ks (skipping those without motion) checked in order, each from where the last one ended."""
        out = []
        q = q_start
        for k in ks:
            if self.job.moves[k].profile is None:
                continue
            c = self.move(k, q)
            out.append(c)
            q = c.q_end
        return out


def _end(checks: list[MoveCheck], q_before):
    """Joints after a sequence of checked moves (q_before if there are none)."""
    return checks[-1].q_end if checks else q_before


def _poses(checker: _Checker, ks) -> np.ndarray:
    """Check poses (n, 6) of the moving moves ks, in order."""
    parts = [checker.points(k)[0] for k in ks if checker.job.moves[k].profile is not None]
    return np.concatenate(parts) if parts else np.zeros((0, 6))


@dataclass(frozen=True, eq=False)
class _Choice:
    """A configuration that makes a group feasible: the boundary s of the gap where it starts, the joints
    there before and after (q_from None at the job start), and the checks of the moves made on it."""

    s: int
    q_from: np.ndarray | None
    q_to: np.ndarray
    checks: list


def _choose(checker: _Checker, g, current: list[MoveCheck], q_before, at_start: bool) -> tuple[_Choice | None, int]:
    """Another configuration for group g (whose moves fail on the current one), or None; and the number
    of configurations tried.

    At the job start the arm may start on any configuration (the whole gap is made on it); later it
    changes configuration at the gap's safe point (:func:`planner.cam.configure.safe_point`), before the
    first gap move that fails on the current configuration. Candidates are the inverse-kinematics
    branches at the run's first pose, each with the whole turns that keep it within the joint limits
    (nearest to where the arm is), tried nearest first: the first one on which the rest of the gap and
    the run have no problem is taken.
    """
    s_robot, moves = checker.s, checker.job.moves
    failing = [c.k for c in current if not c.ok]
    gap_fail = [i for i, k in enumerate(g.gap) if k in failing]
    if at_start:
        s = 0
    else:
        safe = safe_point(moves, g, gap_fail[0] if gap_fail else len(g.gap))
        if safe is None:
            return None, 0
        s = safe
    before = [c for c in current if c.k in g.gap[:s]]
    q_from = None if at_start else _end(before, q_before)
    if not at_start and q_from is None:
        return None, 0
    # the joints the candidates are compared with, where they start: at the job start, those of the
    # configuration of least joint travel there
    q_ref = q_from
    if at_start:
        q_ref = current[0].q[0] if current and np.isfinite(current[0].q[0]).all() else None
    after_ks = [k for k in g.gap[s:] if moves[k].profile is not None]
    run_ks = [k for k in g.run if moves[k].profile is not None]
    forward = _poses(checker, run_ks)
    backward = np.concatenate([checker.points(k)[0][::-1] for k in reversed(after_ks)]) if after_ks else None
    options = []
    for q0 in candidates(s_robot.robot, forward[0], s_robot.tcp):
        q_run = inverse_path(s_robot.robot, forward, q0, tcp=s_robot.tcp, allow_unreachable=True)
        q_back = (inverse_path(s_robot.robot, backward, q0, tcp=s_robot.tcp, allow_unreachable=True)
                  if backward is not None else q_run[:1])
        if not (np.isfinite(q_run).all() and np.isfinite(q_back).all()):
            continue  # the branch does not reach every pose: a problem on it anyway
        q_at = q_back[-1]  # at the safe point (the job start)
        shift = turn_shift(s_robot.robot, np.vstack((q_run, q_back)), q_ref, q_at)
        if shift is None:
            continue
        q_to = q_at + shift
        dist = float(np.linalg.norm(q_to - q_ref)) if q_ref is not None else 0.0
        options.append((dist, q_to))
    options.sort(key=lambda o: o[0])
    tried = 0
    for dist, q_to in options:
        if q_ref is not None and dist < 1e-6:
            continue  # the current configuration
        tried += 1
        checks = checker.moves(list(g.gap[s:]) + list(g.run), q_to)
        if all(c.ok for c in checks):
            return _Choice(s, q_from, q_to, checks), tried
    return None, tried


def check_job(job) -> JobReach:
    """Check every move of a planned job with its robot, lowering feeds locally and choosing the arm
    configuration of every run of passes; see the module doc."""
    s = job.settings
    checker = _Checker(job)
    accepted: list[MoveCheck] = []
    changes: list = []
    start_note = ""
    q = None  # where the arm is after the moves accepted so far
    for g in groups(job.moves):
        current = checker.moves(list(g.gap) + list(g.run), q)
        choice, tried = (None, 0)
        if g.run and not all(c.ok for c in current):
            choice, tried = _choose(checker, g, current, q, at_start=not accepted)
        if choice is None:
            failed = [i for i, c in enumerate(current) if not c.ok]
            if failed:
                note = f"; none of the {tried} other arm configurations makes it feasible either" if tried else ""
                causes = {current[i].cause for i in failed}
                if "wrist" in causes:
                    note += ("; re-place the part (part frame) or tilt the tool so that its axis stays away from the "
                             "shoulder axis there")
                elif "elbow" in causes:
                    note += "; re-place the part nearer to the robot"
                c = current[failed[0]]
                current[failed[0]] = replace(c, problem=c.problem + note)
            accepted += current
            q = _end(current, q)
            continue
        keep = [c for c in current if c.k in g.gap[: choice.s]]
        accepted += keep + choice.checks
        q = _end(choice.checks, q)
        reason = next(c.problem for c in current if not c.ok)
        cuts = [job.moves[k] for k in g.run if job.moves[k].kind == "cut"]
        first_move = job.moves[g.gap[choice.s] if choice.s < len(g.gap) else g.run[0]]
        if choice.q_from is None:  # the job start: the arm starts on this configuration
            start_note = (f"starts on the arm configuration that makes pass {cuts[0].pass_index} (lines "
                          f"{cuts[0].item.first_line}-{cuts[-1].item.last_line}) feasible; the configuration of "
                          f"least joint travel fails: {reason}")
            continue
        where, line = where_text(job.moves, g, choice.s)
        pose = checker.points(_first_moving(job, g, choice.s))[0][0]
        item = Reconfiguration(
            q_from=choice.q_from, q_to=choice.q_to, point=np.asarray(first_move.point, dtype=float).copy(),
            line=line, pass_index=cuts[0].pass_index, passes=tuple(c.pass_index for c in cuts), reason=reason,
            change=describe_change(s.robot, pose, choice.q_from, choice.q_to, s.tcp), where=where,
            tcp_excursion=tcp_excursion(s.robot, choice.q_from, choice.q_to, s.tcp),
        )
        changes.append((g.gap[choice.s] if choice.s < len(g.gap) else g.run[0], item))
    out = JobReach(reconfigurations=changes, start_note=start_note)
    for c in accepted:
        m = job.moves[c.k]
        if c.windows:
            out.profiles[c.k], out.windows[c.k] = c.profile, c.windows
            out.slowed.extend(c.slowed)
        if c.problem:
            out.problems.append(c.problem)
            if m.kind == "cut":
                out.passes.setdefault(m.pass_index, c.problem)
    if accepted and np.isfinite(accepted[0].q[0]).all():
        out = replace(out, start_joints=accepted[0].q[0].copy())
    return out


def _first_moving(job, g, s: int) -> int:
    """The moving move that starts at boundary s of group g's gap (its first check pose is the safe pose)."""
    ks = [k for k in list(g.gap[s:]) + list(g.run) if job.moves[k].profile is not None]
    return ks[0]
