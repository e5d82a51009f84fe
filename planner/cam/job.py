"""A whole CAM job: passes fitted within tolerance, modal tool axes, rapids, timing, robot check.

``plan_cam_job(toolpath)`` runs, for a toolpath read by :func:`planner.io.read_toolpath`:

1. arcs linearised to a tenth of the tolerance (:func:`planner.io.linearize_arcs`);
2. the split into cutting passes, rapid moves and reorientations (:mod:`planner.cam.passes`);
3. every pass fitted with a C1 PH quintic spline within the tolerance of its CAM polyline
   (:mod:`planner.cam.fidelity`);
4. the tool frames of every pass: the CAM axes interpolated without overshoot, spin
   rotation-minimizing, each move starting from the previous move's end frame (:mod:`planner.cam.axes`,
   :mod:`planner.cam.moves`), so the whole job is free of spin about the tool axis;
5. the jerk-limited time law of every move (cuts at the file's feeds, rapids at rapid speed, turns at
   the turning speed), starting and ending at rest;
6. with a robot: inverse kinematics along every move, unreachable passes reported by pass number and
   source line; where a joint would exceed its speed limit the feed is lowered locally, only over the
   stretch that needs it, and every stretch slowed is named (:mod:`planner.cam.reach`);
7. with a robot: the arm configuration (shoulder, elbow, wrist branch and whole turns) of every run of
   passes: the current one is kept while it can make the run; otherwise the nearest one that can is
   taken, changed by a joint move (movej) at the safe point of the rapid before the run, never during a
   cut (:mod:`planner.cam.configure`); each change is a "reconfiguration" move of the job, named by pass
   and source line.

The 500 Hz pose stream of the job is produced on demand, move by move (:mod:`planner.cam.stream`):
a whole NX job is millions of poses.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field, replace

import numpy as np

from planner.cam.axes import (
    AxisField,
    axis_departure,
    axis_field,
    frame_with_axis,
    spin_about_axis,
    transport,
    travel_spin,
)
from planner.cam.fidelity import DEFAULT_TOLERANCE, PassFit, fit_passes
from planner.cam.moves import rapid_frames, straight_path, turn_frames, turn_profile
from planner.cam.passes import (
    DEFAULT_AXIS_JUMP_DEG,
    DEFAULT_CORNER_DEG,
    CamInputError,
    CutPass,
    RapidMove,
    Reorientation,
    Segmentation,
    Skipped,
    check_threshold,
    split_passes,
)
from planner.errors import PlannerError
from planner.motion import MotionLimits, plan_feed, tool_orientation
from planner.motion.stream import as_transform, transform_to_pose

#: Default limits of the cutting motion: TCP speed (m/s), acceleration (m/s^2), jerk (m/s^3) and tool
#: angular speed (rad/s).
DEFAULT_LIMITS = MotionLimits(speed=0.25, acceleration=0.5, jerk=5.0, angular_speed=1.0)
#: Default limits of a turn in place: angular speed (rad/s), acceleration (rad/s^2), jerk (rad/s^3).
DEFAULT_TURN_LIMITS = MotionLimits(speed=1.0, acceleration=2.0, jerk=20.0)
#: Default feed where the file gives none, m/s (600 mm/min).
DEFAULT_FEED = 0.01
#: Default speed of rapid moves, m/s.
DEFAULT_RAPID_SPEED = 0.25
#: Default limits of every joint in a reconfiguration (joint move): speed rad/s, acceleration rad/s^2 (UR's
#: movej defaults v = 1.05, a = 1.4), jerk rad/s^3; the model's joint speed limits apply too.
DEFAULT_JOINT_LIMITS = MotionLimits(speed=1.05, acceleration=1.4, jerk=14.0)
#: The CAM default tool axis (APT: +Z, from the tip towards the spindle).
CAM_DEFAULT_AXIS = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class CamSettings:
    """What the user sets for a CAM job (SI units: m, s, rad; thresholds in degrees)."""

    tolerance: float = DEFAULT_TOLERANCE
    corner_deg: float = DEFAULT_CORNER_DEG
    axis_jump_deg: float = DEFAULT_AXIS_JUMP_DEG
    arc_tolerance: float | None = None
    part_frame: tuple | None = None
    tcp: tuple | None = None
    robot: str | None = None
    feed: float = DEFAULT_FEED
    feed_override: float = 1.0
    rapid_speed: float = DEFAULT_RAPID_SPEED
    limits: MotionLimits = DEFAULT_LIMITS
    turn_limits: MotionLimits = DEFAULT_TURN_LIMITS
    rate: float = 500.0
    reach_step: float = 2e-3
    joint_limits: MotionLimits = DEFAULT_JOINT_LIMITS


@dataclass(frozen=True)
class PassReport:
    """Figures of one cutting pass (SI units, angles in degrees).

    Attributes
    ----------
    index : int
        Pass number.
    operation : str
        CAM operation name ("" if none).
    first_line, last_line : int
        Source lines of the pass's first and last point.
    points : int
        CAM points (after merging duplicates).
    length : float
        Exact arc length of the fitted path, m.
    max_deviation : float
        Largest distance between the fitted path and the CAM polyline, m.
    max_axis_error_deg : float
        Largest angle between the planned tool axis and the CAM axis at the CAM points.
    max_axis_departure_deg : float
        Largest distance of the planned tool axis from the great-circle arcs between consecutive CAM
        axes (the path a 5-axis machine takes), sampled between the CAM points.
    knots_added : int
        Knots inserted on CAM chords to meet the tolerance.
    start_reason, end_reason : str
        Why the pass starts and ends (rapid, corner, ...).
    start_corner_deg : float
        Turning angle of the corner the pass starts at (NaN if it does not start at a corner).
    duration : float
        Time of the pass, s.
    spin_deg : float
        Total spin of the planned tool frames about the tool axis.
    slerp_spin_deg : float
        Total spin when the CAM orientations (tool axis, x along the direction of travel) are
        slerped point to point.
    planning_time : float
        Wall time spent on the pass (its share of the batched fit, its frames and its time law), s.
    merged : int
        Duplicate points merged.
    reachable : bool or None
        Whether the robot reaches the whole pass within its joint limits (None without a robot).
    reach_message : str
        The first problem, naming the pass and the source line ("" if none).
    feed_caps : tuple of CapWindow
        Stretches of the pass where the feed was lowered for the joint speed limits (spans of the
        pass; tag = joint index); ``duration`` includes them.
    """

    index: int
    operation: str
    first_line: int
    last_line: int
    points: int
    length: float
    max_deviation: float
    max_axis_error_deg: float
    max_axis_departure_deg: float
    knots_added: int
    start_reason: str
    end_reason: str
    start_corner_deg: float
    duration: float
    spin_deg: float
    slerp_spin_deg: float
    planning_time: float
    merged: int = 0
    reachable: bool | None = None
    reach_message: str = ""
    feed_caps: tuple = ()


@dataclass(frozen=True, eq=False)
class PlannedMove:
    """One move of the job with its path, tool frames and time law.

    Attributes
    ----------
    kind : str
        "cut", "rapid", "reorientation", "reconfiguration" or "skipped".
    item : CutPass, RapidMove, Reorientation, Reconfiguration or Skipped
        What the file asks for (a Reconfiguration: what the planner adds to change the arm configuration).
    path : PHSpline or None
        The path in the part frame (None for moves in place).
    frames : AxisField or TurningFrames or None
        Tool frames: along the path (parameter u), or of the turn (parameter: angle turned); None for a
        reconfiguration (its poses come from forward kinematics of its joints).
    profile : FeedProfile or None
        Time law: arc length (or angle, for a turn; fraction of the joint move, for a reconfiguration)
        against time; None for skipped moves.
    start_frame, end_frame : ndarray (3, 3)
        Tool frame (part frame; column 2 the approach axis) at the start and end.
    point : ndarray (3,)
        Position at the start of the move.
    pass_index : int
        Pass number for cuts, -1 otherwise.
    fit : PassFit or None
        The fit of a cut.
    """

    kind: str
    item: object
    path: object
    frames: object
    profile: object
    start_frame: np.ndarray
    end_frame: np.ndarray
    point: np.ndarray
    pass_index: int = -1
    fit: PassFit | None = None

    @property
    def duration(self) -> float:
        return 0.0 if self.profile is None else float(self.profile.duration)

    @property
    def line(self) -> int:
        """Source line of the move's first record."""
        it = self.item
        if isinstance(it, CutPass):
            return it.first_line
        if isinstance(it, Skipped):
            return it.first_line
        return int(it.line)


@dataclass(frozen=True, eq=False)
class CamJob:
    """A planned CAM job.

    Attributes
    ----------
    source : str
        Name of the file.
    settings : CamSettings
    toolpath : Toolpath
        The toolpath as planned (arcs linearised).
    segmentation : Segmentation
        The split into moves.
    moves : tuple of PlannedMove
        Every move in order (cuts, rapids, reorientations, skipped records).
    passes : tuple of PassReport
        Figures of every cutting pass.
    timings : dict
        Wall times, s: "parse" (if read here), "split", "fit", "frames", "time_law", "plan" (all of the
        planning after parsing), "reach" (robot check).
    problems : tuple of str
        Reachability problems of the whole job (passes, rapids, turns), each naming its source line.
    slowed : tuple of str
        Stretches where the feed was lowered for the joint speed limits, each naming the pass (or move),
        the source lines, the factor and the joint.
    start_joints : ndarray (6,) or None
        With a robot: the joints (rad) at the job's first pose, on the configuration the check followed
        (the joint streams and the program start there).
    start_note : str
        Why the arm starts on another configuration than the one of least joint travel ("" if not).
    """

    source: str
    settings: CamSettings
    toolpath: object
    segmentation: Segmentation
    moves: tuple
    passes: tuple
    timings: dict = field(default_factory=dict)
    problems: tuple = ()
    slowed: tuple = ()
    start_joints: np.ndarray | None = None
    start_note: str = ""

    # -- figures -------------------------------------------------------------------------------
    @property
    def duration(self) -> float:
        """Total motion time (s), at rest between moves."""
        return float(sum(m.duration for m in self.moves))

    @property
    def corners(self) -> int:
        """Corners sharper than the threshold found (each one splits a pass)."""
        return self.segmentation.corners

    @property
    def max_deviation(self) -> float:
        """Largest distance between any fitted pass and its CAM polyline, m."""
        return max((p.max_deviation for p in self.passes), default=0.0)

    @property
    def max_axis_error_deg(self) -> float:
        """Largest tool-axis angle error at the CAM points, degrees."""
        return max((p.max_axis_error_deg for p in self.passes), default=0.0)

    @property
    def max_axis_departure_deg(self) -> float:
        """Largest distance of the planned axis from the CAM great-circle arcs between points, degrees."""
        return max((p.max_axis_departure_deg for p in self.passes), default=0.0)

    @property
    def spin_deg(self) -> float:
        """Total spin of the planned frames about the tool axis over all cuts, degrees."""
        return float(sum(p.spin_deg for p in self.passes))

    @property
    def slerp_spin_deg(self) -> float:
        """Total spin of the CAM orientations slerped point to point over all cuts, degrees."""
        return float(sum(p.slerp_spin_deg for p in self.passes))

    @property
    def reachable(self) -> bool | None:
        """Whether the robot can do the whole job (None without a robot)."""
        return None if self.settings.robot is None else not self.problems

    def count(self, kind: str) -> int:
        """Number of moves of a kind ("cut", "rapid", "reorientation", "reconfiguration", "skipped")."""
        return sum(1 for m in self.moves if m.kind == kind)

    @property
    def reconfigurations(self) -> tuple:
        """The changes of the arm configuration (:class:`~planner.cam.moves.Reconfiguration`), in order."""
        return tuple(m.item for m in self.moves if m.kind == "reconfiguration")

    def reconfiguration_lines(self) -> list[str]:
        """One line per change of the arm configuration, for a person: before which pass, where (source
        line), what changes, how long, how far the tool swings, and what the former configuration could
        not do."""
        out = []
        for m in self.moves:
            if m.kind != "reconfiguration":
                continue
            r = m.item
            cut = next(c for c in self.segmentation.passes if c.index == r.pass_index)
            last = next(c for c in self.segmentation.passes if c.index == r.passes[-1])
            run = f"pass {r.pass_index}" if len(r.passes) == 1 else f"passes {r.pass_index}-{r.passes[-1]}"
            out.append(f"{self.source} before {run} (lines {cut.first_line}-{last.last_line}), {r.where}: "
                       f"joint move of {m.duration:.2f} s ({r.change}; the tool swings up to "
                       f"{1e3 * r.tcp_excursion:.0f} mm from the point); the former configuration: {r.reason}")
        return out

    def n_samples(self, rate: float | None = None) -> int:
        """Number of poses of the stream at ``rate`` (default the job's)."""
        from planner.cam.stream import sample_counts

        return int(sample_counts(self.moves, rate or self.settings.rate).sum()) + 1

    def summary(self) -> dict:
        """The job's figures in human units (mm, s, deg)."""
        out = {
            "source": self.source,
            "points": len(self.toolpath),
            "passes": len(self.passes),
            "rapids": self.count("rapid"),
            "reorientations": self.count("reorientation"),
            "skipped": self.count("skipped"),
            "corners": self.corners,
            "cut_length_mm": 1e3 * sum(p.length for p in self.passes),
            "duration_s": self.duration,
            "tolerance_mm": 1e3 * self.settings.tolerance,
            "max_deviation_mm": 1e3 * self.max_deviation,
            "max_axis_error_deg": self.max_axis_error_deg,
            "max_axis_departure_deg": self.max_axis_departure_deg,
            "spin_deg": self.spin_deg,
            "slerp_spin_deg": self.slerp_spin_deg,
            "knots_added": int(sum(p.knots_added for p in self.passes)),
            "planning_s": self.timings.get("plan", math.nan),
        }
        if self.settings.robot is not None:
            out["robot"] = self.settings.robot
            out["reachable"] = not self.problems
            out["unreachable_passes"] = [p.index for p in self.passes if p.reachable is False]
            out["slowed_passes"] = [p.index for p in self.passes if p.feed_caps]
            out["slowed"] = list(self.slowed)
            out["reconfigurations"] = self.reconfiguration_lines()
            out["reconfigured_passes"] = [r.pass_index for r in self.reconfigurations]
            if self.start_note:
                out["start"] = self.start_note
        return out

    def describe(self, max_lines: int = 10) -> list[str]:
        """Lines for a person: the job's figures, the worst passes, the robot's problems."""
        s = self.summary()
        worst = sorted(self.passes, key=lambda p: -p.max_deviation)[:3]
        lines = [
            f"{s['source']}: {s['points']} points -> {s['passes']} passes, {s['rapids']} rapids, "
            f"{s['reorientations']} reorientations, {s['skipped']} skipped; {s['corners']} corners "
            f"> {self.settings.corner_deg:g} deg",
            f"  path      {s['cut_length_mm']:.1f} mm of cut; largest deviation from the CAM polyline "
            f"{s['max_deviation_mm']:.4f} mm (tolerance {s['tolerance_mm']:.4f} mm), {s['knots_added']} knots added",
            "  worst     " + "; ".join(f"pass {p.index} (lines {p.first_line}-{p.last_line}) "
                                        f"{1e3 * p.max_deviation:.4f} mm" for p in worst),
            f"  axes      largest error at the CAM points {s['max_axis_error_deg']:.2e} deg, between them "
            f"{s['max_axis_departure_deg']:.3g} deg from the CAM great circles; spin about the tool axis "
            f"{s['spin_deg']:.3g} deg (slerping the CAM orientations: {s['slerp_spin_deg']:.4g} deg)",
            f"  motion    {s['duration_s']:.1f} s, planned in {s['planning_s']:.2f} s",
        ]
        if self.settings.robot is not None:
            if self.slowed:
                n = len(self.slowed)
                lines.append(f"  slowed    feed lowered for the joint speed limits on {n} stretch{'es' * (n > 1)}")
                lines += [f"    {p}" for p in self.slowed[:max_lines]]
                if len(self.slowed) > max_lines:
                    lines.append(f"    ... {len(self.slowed) - max_lines} more")
            if self.start_note:
                lines.append(f"  arm       {self.start_note}")
            changes = s["reconfigurations"]
            if changes:
                n = len(changes)
                lines.append(f"  arm       {n} change{'s' * (n > 1)} of the arm configuration (joint moves in rapids)")
                lines += [f"    {p}" for p in changes[:max_lines]]
                if n > max_lines:
                    lines.append(f"    ... {n - max_lines} more")
            if not self.problems:
                lines.append(f"  robot     {self.settings.robot}: every move reachable within joint limits")
            else:
                lines.append(f"  robot     {self.settings.robot}: {len(self.problems)} moves with problems")
                lines += [f"    {p}" for p in self.problems[:max_lines]]
                if len(self.problems) > max_lines:
                    lines.append(f"    ... {len(self.problems) - max_lines} more")
        return lines

    # -- pose stream ---------------------------------------------------------------------------
    def iter_stream(self, rate: float | None = None):
        """The job's poses at the controller rate, one :class:`~planner.cam.stream.StreamChunk` per move.

        See :func:`planner.cam.stream.iter_stream`.
        """
        from planner.cam.stream import iter_stream

        return iter_stream(self, rate or self.settings.rate)

    def pose_stream(self, rate: float | None = None, max_samples: int = 20_000_000):
        """The whole pose stream in memory (:class:`~planner.cam.stream.JobStream`).

        Raises CamInputError when the job has more than ``max_samples`` poses (use
        :meth:`iter_stream` for those).
        """
        from planner.cam.stream import collect

        return collect(self, rate or self.settings.rate, max_samples)


def _settings(**kw) -> CamSettings:
    s = CamSettings(**kw)
    tol = check_threshold(s.tolerance, "tolerance", 0.0, math.inf)
    arc = tol / 10.0 if s.arc_tolerance is None else check_threshold(s.arc_tolerance, "arc_tolerance", 0.0, math.inf)
    check_threshold(s.corner_deg, "corner_deg", 0.0, 180.0)
    check_threshold(s.axis_jump_deg, "axis_jump_deg", 0.0, 90.0)
    for name in ("feed", "feed_override", "rapid_speed", "rate", "reach_step"):
        check_threshold(getattr(s, name), name, 0.0, math.inf)
    for name in ("limits", "turn_limits", "joint_limits"):
        if not isinstance(getattr(s, name), MotionLimits):
            raise CamInputError(f"{name} must be a planner.motion.MotionLimits, got {type(getattr(s, name)).__name__}")
    poses = {}
    for name in ("part_frame", "tcp"):
        v = getattr(s, name)
        if v is not None:
            try:
                poses[name] = tuple(float(x) for x in transform_to_pose(as_transform(v, name)))
            except PlannerError as exc:
                raise CamInputError(str(exc)) from None
    if s.robot is not None:
        from planner.kinematics import get_model

        get_model(s.robot)  # UnknownModelError names the model and the known ones
    return CamSettings(**{**s.__dict__, "tolerance": tol, "arc_tolerance": arc, **poses})


def _approach(axes: np.ndarray | None, n: int) -> np.ndarray:
    """Unit tool approach axes (tool z) from CAM vectors (tip towards spindle): their negatives."""
    if axes is None:
        return np.broadcast_to(-CAM_DEFAULT_AXIS, (n, 3)).copy()
    a = np.asarray(axes, dtype=float)
    return -a / np.linalg.norm(a, axis=-1, keepdims=True)  # files write 7 digits: |v| = 1 +- 1e-7


def _where(source: str, item) -> str:
    if isinstance(item, CutPass):
        return f"{source} lines {item.first_line}-{item.last_line} ({item.describe()})"
    if isinstance(item, RapidMove | Reorientation):
        return f"{source} line {item.line} ({item.kind})"
    return source


def plan_cam_job(
    toolpath,
    *,
    tolerance: float = DEFAULT_TOLERANCE,
    corner_deg: float = DEFAULT_CORNER_DEG,
    axis_jump_deg: float = DEFAULT_AXIS_JUMP_DEG,
    arc_tolerance: float | None = None,
    part_frame=None,
    tcp=None,
    robot: str | None = None,
    feed: float = DEFAULT_FEED,
    feed_override: float = 1.0,
    rapid_speed: float = DEFAULT_RAPID_SPEED,
    limits: MotionLimits = DEFAULT_LIMITS,
    turn_limits: MotionLimits = DEFAULT_TURN_LIMITS,
    rate: float = 500.0,
    reach_step: float = 2e-3,
    joint_limits: MotionLimits = DEFAULT_JOINT_LIMITS,
    read_options: dict | None = None,
    progress=None,
) -> CamJob:
    """Plan a whole CAM toolpath: passes within tolerance, modal tool axes, rapids, time law, robot.

    Parameters
    ----------
    toolpath : planner.io.Toolpath, str or os.PathLike
        A reader's output, or a file to read with :func:`planner.io.read_toolpath` (``read_options``
        are passed to it, e.g. ``{"machine": "haas-umc-750"}``).
    tolerance : float
        Largest distance between the planned path and the CAM polyline, m (default 1e-5 = 0.01 mm).
    corner_deg : float
        Corners sharper than this (degrees between consecutive chords) stop the tool: new pass.
    axis_jump_deg : float
        Tool-axis changes larger than this (degrees, at most 90) are made by turning in place.
    arc_tolerance : float, optional
        Sagitta of the linearisation of CIRCLE / G02 / G03 arcs, m (default ``tolerance / 10``).
    part_frame : pose (6,) or matrix (4, 4), optional
        The CAM (part) frame in the robot base frame, p[x, y, z, rx, ry, rz] (m, rotation vector).
    tcp : pose (6,) or matrix (4, 4), optional
        The tool centre point (tool tip) in the robot flange frame.
    robot : str, optional
        UR model ("ur3e", "ur5e", "ur10e", "ur16e", "ur20"); None plans without kinematics.
    feed : float
        Cutting feed where the file gives none, m/s.
    feed_override : float
        Factor on every cutting feed (file feeds and ``feed``), like a CNC feed override.
    rapid_speed : float
        Speed of rapid moves, m/s (the acceleration and jerk limits of ``limits`` apply).
    limits : MotionLimits
        Limits of the cutting motion (speed caps the feeds; the angular speed limit caps the feed
        where the tool axis turns fast).
    turn_limits : MotionLimits
        Angular speed, acceleration and jerk of turns in place (rad/s, rad/s^2, rad/s^3).
    rate : float
        Controller rate of the pose stream, Hz.
    reach_step : float
        With a robot: spacing of the reachability check along each move, m (the CAM points are
        always checked).
    joint_limits : MotionLimits
        With a robot: speed (rad/s), acceleration (rad/s^2) and jerk (rad/s^3) of every joint in a change
        of the arm configuration (a joint move in a rapid); the model's joint speed limits apply too.
    read_options : dict, optional
        Options for the reader when ``toolpath`` is a file.

    Returns
    -------
    CamJob

    Raises
    ------
    CamInputError
        A bad parameter (naming it); a pass that cannot be planned (naming the file and its lines).
    planner.io.InputFileError
        The file cannot be read (naming the file, line and field).
    """
    from planner.io import Toolpath, linearize_arcs, read_toolpath

    settings = _settings(
        tolerance=tolerance, corner_deg=corner_deg, axis_jump_deg=axis_jump_deg, arc_tolerance=arc_tolerance,
        part_frame=part_frame, tcp=tcp, robot=robot, feed=feed,
        feed_override=feed_override, rapid_speed=rapid_speed, limits=limits, turn_limits=turn_limits, rate=rate,
        reach_step=reach_step, joint_limits=joint_limits,
    )  # fmt: skip
    timings = {}
    if isinstance(toolpath, str | os.PathLike):
        tic = time.perf_counter()
        toolpath = read_toolpath(toolpath, **(read_options or {}))
        timings["parse"] = time.perf_counter() - tic
    elif read_options:
        raise CamInputError("read_options are for a file name; the toolpath is already read")
    if not isinstance(toolpath, Toolpath):
        raise CamInputError(f"toolpath must be a planner.io.Toolpath or a file name, got {type(toolpath).__name__}")
    t_plan = time.perf_counter()
    tp = linearize_arcs(toolpath, settings.arc_tolerance)
    tic = time.perf_counter()
    seg = split_passes(tp, corner_deg=settings.corner_deg, axis_jump_deg=settings.axis_jump_deg)
    timings["split"] = time.perf_counter() - tic
    cuts = seg.passes
    tic = time.perf_counter()
    try:
        fits = fit_passes([p.points for p in cuts], settings.tolerance)
    except PlannerError as exc:  # pragma: no cover - split_passes hands over valid passes
        raise CamInputError(f"{tp.source}: {exc}") from exc
    fit_time = time.perf_counter() - tic
    timings["fit"] = fit_time
    spans_total = max(sum(len(p) - 1 for p in cuts), 1)
    if progress is not None:
        progress("fit", len(cuts), len(cuts))
    moves, reports = _plan_moves(tp, seg, fits, settings, fit_time / spans_total, timings, progress)
    if progress is not None:
        progress("moves", len(seg.moves), len(seg.moves))
    timings["plan"] = time.perf_counter() - t_plan
    job = CamJob(tp.source, settings, tp, seg, tuple(moves), tuple(reports), timings)
    if settings.robot is not None:
        from planner.cam.reach import check_job

        if progress is not None:
            progress("reach", 0, 1)
        tic = time.perf_counter()
        reach = check_job(job)
        timings["reach"] = time.perf_counter() - tic
        # moves whose feed was lowered locally for the joint speed limits take their new time law
        moves = [replace(m, profile=reach.profiles[k]) if k in reach.profiles else m for k, m in enumerate(moves)]
        caps = {m.pass_index: reach.windows[k] for k, m in enumerate(moves) if m.kind == "cut" and k in reach.windows}
        duration = {m.pass_index: m.duration for m in moves if m.kind == "cut"}
        reports = [
            PassReport(**{**r.__dict__, "reachable": reach.passes.get(r.index) is None,
                          "reach_message": reach.passes.get(r.index, ""), "feed_caps": caps.get(r.index, ()),
                          "duration": duration[r.index]}) for r in reports
        ]
        moves = _with_reconfigurations(moves, reach.reconfigurations, settings)
        job = CamJob(tp.source, settings, tp, seg, tuple(moves), tuple(reports), timings, tuple(reach.problems),
                     tuple(reach.slowed), reach.start_joints, reach.start_note)
    return job


def _with_reconfigurations(moves: list, changes: list, s: CamSettings) -> list:
    """The moves with a joint move inserted before move k for every (k, Reconfiguration) in ``changes``."""
    from planner.cam.moves import joint_move_profile
    from planner.kinematics import get_model

    out = list(moves)
    speeds = get_model(s.robot).speed_limits
    for k, r in sorted(changes, key=lambda c: c[0], reverse=True):
        F = moves[k].start_frame
        profile = joint_move_profile(r.q_from, r.q_to, s.joint_limits, speeds)
        out.insert(k, PlannedMove("reconfiguration", r, None, None, profile, F, F, r.point.copy()))
    return out


def _plan_moves(tp, seg: Segmentation, fits, s: CamSettings, fit_share: float, timings: dict, progress=None):
    """Frames and time laws of every move, in order, each starting from the previous end frame."""
    moves: list[PlannedMove] = []
    reports: list[PassReport] = []
    frame: np.ndarray | None = None  # tool frame at the end of the previous move
    t_frames = t_law = 0.0
    cut_limits = MotionLimits(s.limits.speed, s.limits.acceleration, s.limits.jerk)
    for n_done, item in enumerate(seg.moves):
        if progress is not None and n_done % 25 == 0:
            progress("moves", n_done, len(seg.moves))
        try:
            if isinstance(item, CutPass):
                tic = time.perf_counter()
                fit = fits[item.index]
                z = _approach(item.axes, len(item))
                field = axis_field(fit.path, z, start=frame)
                t1 = time.perf_counter()
                feeds = item.feeds[1:] * s.feed_override
                job_feed = s.feed * s.feed_override
                capped = s.limits.angular_speed is not None and _turns_fast(field, feeds, job_feed, s.limits)
                f = np.where(np.isnan(feeds), job_feed, feeds)
                if not capped and (f == f[0]).all():  # one feed: plan on the bare length (same profile)
                    profile = plan_feed(float(fit.path.length), float(f[0]), cut_limits)
                else:
                    profile = plan_feed(fit.path, job_feed, s.limits if capped else cut_limits,
                                        span_feeds=None if np.isnan(feeds).all() else feeds,
                                        orientation=tool_orientation(field) if capped else None)
                t2 = time.perf_counter()
                end = field.end
                moves.append(PlannedMove("cut", item, fit.path, field, profile, field.start, end,
                                         item.points[0], item.index, fit))
                reports.append(_pass_report(item, fit, field, profile, z, t2 - tic + fit_share * (len(item) - 1)))
                t_frames += t1 - tic
                t_law += t2 - t1
                frame = end
            elif isinstance(item, RapidMove):
                tic = time.perf_counter()
                z0 = _approach(None if item.start_axis is None else item.start_axis[None], 1)[0]
                z1 = _approach(None if item.end_axis is None else item.end_axis[None], 1)[0]
                start = frame_with_axis(z0, item.end - item.start) if frame is None else transport(frame, z0)
                path = straight_path(item.start, item.end)
                fr = rapid_frames(path, start, z1)
                v = s.rapid_speed
                if fr.angle > 0.0 and s.limits.angular_speed is not None:  # the axis turns at angle / L rad/m
                    v = min(v, s.limits.angular_speed * path.length / fr.angle)
                profile = plan_feed(float(path.length), v, MotionLimits(v, s.limits.acceleration, s.limits.jerk))
                frame = transport(fr.end, z1)  # column 2 exactly z1 (the rotation leaves round-off)
                moves.append(PlannedMove("rapid", item, path, fr, profile, start, frame, item.start.copy()))
                t_law += time.perf_counter() - tic
            elif isinstance(item, Reorientation):
                z0, z1 = _approach(np.vstack((item.axis_from, item.axis_to)), 2)
                start = frame_with_axis(z0, np.array([1.0, 0.0, 0.0])) if frame is None else transport(frame, z0)
                fr = turn_frames(start, z1)
                profile = turn_profile(fr.angle, s.turn_limits) if fr.angle > 0.0 else None
                frame = transport(fr.end, z1)
                moves.append(PlannedMove("reorientation", item, None, fr, profile, start, frame, item.point.copy()))
            else:  # Skipped: nothing moves
                F = frame if frame is not None else frame_with_axis(-CAM_DEFAULT_AXIS, np.array([1.0, 0.0, 0.0]))
                moves.append(PlannedMove("skipped", item, None, None, None, F, F, item.point.copy()))
        except PlannerError as exc:
            raise CamInputError(f"{_where(tp.source, item)}: {exc}") from exc
    tic = time.perf_counter()
    cut_items = [m.item for m in moves if m.kind == "cut"]
    slerp = np.degrees(travel_spin([c.points for c in cut_items], [_approach(c.axes, len(c)) for c in cut_items]))
    reports = [PassReport(**{**r.__dict__, "slerp_spin_deg": float(v)}) for r, v in zip(reports, slerp, strict=True)]
    timings["frames"] = t_frames + time.perf_counter() - tic
    timings["time_law"] = t_law
    return moves, reports


def _turns_fast(field: AxisField, feeds: np.ndarray, job_feed: float, limits: MotionLimits) -> bool:
    """Whether the angular speed limit can matter on a pass: the tool axis turns by |dz/ds| rad/m
    (the rotation-minimizing frames turn only with the axis), sampled 8 times per span, times the
    fastest feed exceeds half the limit (the margin covers peaks between samples)."""
    if field.motion is None:
        return False
    k = field.path.waypoint_knots
    u = (k[:-1, None] + np.diff(k)[:, None] * np.linspace(0.0, 1.0, 9)).ravel()
    rate = np.linalg.norm(field.motion.dz(u), axis=1) / field.path.speed(u)  # |dz/ds| = |dz/du| / |dr/du|
    v = min(float(np.max(np.where(np.isnan(feeds), job_feed, feeds))), limits.speed)
    return float(rate.max()) * v > 0.5 * limits.angular_speed


def _pass_report(item: CutPass, fit: PassFit, field: AxisField, profile, z: np.ndarray, elapsed: float) -> PassReport:
    path = fit.path
    if field.motion is None:
        spin = 0.0
    else:  # frames at every knot and 4 points per segment, slerped between (the RMM's spin is 0)
        k = path.knots
        u = (k[:-1, None] + np.diff(k)[:, None] * np.linspace(0.0, 1.0, 5)[:-1]).ravel()
        spin = spin_about_axis(field.frames(np.append(u, k[-1])))
    return PassReport(
        index=item.index, operation=item.operation, first_line=item.first_line, last_line=item.last_line,
        points=len(item), length=path.length, max_deviation=fit.max_deviation,
        max_axis_error_deg=float(np.degrees(field.axis_errors().max())),
        max_axis_departure_deg=float(np.degrees(axis_departure(field))), knots_added=fit.knots_added,
        start_reason=item.start_reason, end_reason=item.end_reason, start_corner_deg=item.start_corner_deg,
        duration=float(profile.duration), spin_deg=float(np.degrees(spin)), slerp_spin_deg=math.nan,
        planning_time=elapsed, merged=item.merged,
    )

