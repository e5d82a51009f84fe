"""A planned job: every move with its path, tool frames and time law, the figures, and its trajectory.

:func:`planner.plan` returns a :class:`PlannedJob`. Its :meth:`~PlannedJob.trajectory` is the one stream
that every consumer reads (exports, plot, drivers, simulator, service), produced lazily move by move; a job
saves to a compact versioned file (:meth:`PlannedJob.save`, the layout in :mod:`planner.jobfile`) and loads
back (:func:`load_job`) to the identical trajectory, so a service stores plans, not millions of poses.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path as FilePath
from typing import TYPE_CHECKING

import numpy as np

from planner.cam.axes import AxisField
from planner.cam.fidelity import PassFit
from planner.cam.moves import Reconfiguration, TurningFrames
from planner.cam.passes import CutPass, Dwell, RapidMove, Reorientation, Segmentation, Skipped
from planner.cam.spin import SpunFrames
from planner.errors import PlannerError
from planner.frames.tool_field import PathToolField
from planner.io.toolpath import Toolpath
from planner.jobfile import VERSION, StoredType, dump, load
from planner.jobfile.codec import Arr, Bool, Int, Json, Map, Opt, Ref, Seq, Str
from planner.jobfile.types import CORE_TYPES, FRAME, LINE, NAN, VEC3, need
from planner.motion.profile import FeedProfile
from planner.protocols import FrameField, Path
from planner.settings import PlanSettings
from planner.wording import counted

if TYPE_CHECKING:
    from planner.cam.placement import Placement
    from planner.trajectory import Trajectory

#: What a move carries out: a record of the file, or a change of the arm configuration the planner adds.
MoveItem = CutPass | RapidMove | Reorientation | Dwell | Skipped | Reconfiguration
#: Version of the saved-job format (:meth:`PlannedJob.save`, :mod:`planner.jobfile`).
JOB_FILE_VERSION = VERSION
#: Move kinds and what each carries out.
MOVE_ITEMS = {"cut": CutPass, "rapid": RapidMove, "reorientation": Reorientation, "reconfiguration": Reconfiguration,
              "dwell": Dwell, "skipped": Skipped}
#: The largest trajectory (poses) a saved job may describe: the largest ``max_poses`` a job is planned with.
MAX_SAVED_POSES = 1e12


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
    max_twist_deg : float
        With the tool normal to the path (``axes="path"``): the largest angle between the chosen frame
        method's frames and the exact RMF about the tangent (same start frame), degrees; 0 for "rmf";
        NaN with tool axes (their spin is the exact rotation-minimizing motion; see ``spin_deg``).
    max_waypoint_error : float
        Largest distance of the path from the pass's points, m (round-off for interpolated paths).
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
    max_twist_deg: float = math.nan
    max_waypoint_error: float = 0.0

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"index": self.index, "operation": self.operation, "first_line": self.first_line,
                "last_line": self.last_line, "points": self.points, "length": self.length,
                "max_deviation": self.max_deviation, "max_axis_error_deg": self.max_axis_error_deg,
                "max_axis_departure_deg": self.max_axis_departure_deg, "knots_added": self.knots_added,
                "start_reason": self.start_reason, "end_reason": self.end_reason,
                "start_corner_deg": self.start_corner_deg, "duration": self.duration, "spin_deg": self.spin_deg,
                "slerp_spin_deg": self.slerp_spin_deg, "planning_time": self.planning_time, "merged": self.merged,
                "reachable": self.reachable, "reach_message": self.reach_message, "feed_caps": self.feed_caps,
                "max_twist_deg": self.max_twist_deg, "max_waypoint_error": self.max_waypoint_error}

    @classmethod
    def from_state(cls, state: dict) -> PassReport:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)


@dataclass(frozen=True, eq=False)
class PlannedMove:
    """One move of the job with its path, tool frames and time law.

    Attributes
    ----------
    kind : str
        "cut", "rapid", "reorientation", "reconfiguration", "dwell" or "skipped".
    item : CutPass, RapidMove, Reorientation, Reconfiguration, Dwell or Skipped
        What the file asks for (a Reconfiguration: what the planner adds to change the arm configuration).
        A dwell holds the tool at rest at ``point`` in ``start_frame`` for ``item.seconds`` (no profile:
        nothing moves; its duration is the dwell's).
    path : PHSpline or None
        The path in the part frame (None for moves in place).
    frames : AxisField or TurningFrames or None
        Tool frames: along the path (parameter u), or of the turn (parameter: angle turned); None for a
        reconfiguration (its poses come from forward kinematics of its joints).
    profile : FeedProfile or None
        Time law: arc length (or angle, for a turn; fraction of the joint move, for a reconfiguration)
        against time; None for skipped moves and dwells.
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
    item: MoveItem
    path: Path | None
    frames: FrameField | None
    profile: FeedProfile | None
    start_frame: np.ndarray
    end_frame: np.ndarray
    point: np.ndarray
    pass_index: int = -1
    fit: PassFit | None = None

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"kind": self.kind, "item": self.item, "path": self.path, "frames": self.frames,
                "profile": self.profile, "start_frame": self.start_frame, "end_frame": self.end_frame,
                "point": self.point, "pass_index": self.pass_index, "fit": self.fit}

    @classmethod
    def from_state(cls, state: dict) -> PlannedMove:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)

    @property
    def duration(self) -> float:
        """Time of the move, s (a dwell: its seconds at rest)."""
        if isinstance(self.item, Dwell):
            return float(self.item.seconds)
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
class PlannedJob:
    """A planned job (one pass or a whole CAM toolpath).

    Attributes
    ----------
    source : str
        Name of the file.
    settings : PlanSettings
        As planned: validated, ``path`` and ``axes`` resolved to the model and source used.
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
    warnings : tuple of str
        What the reader and the planner warned about, one line each, naming the place.
    placement : Placement or None
        With ``part_frame="auto"``: the frame found and its margins (:mod:`planner.cam.placement`); the
        settings carry the frame.
    """

    source: str
    settings: PlanSettings
    toolpath: Toolpath
    segmentation: Segmentation
    moves: tuple
    passes: tuple
    timings: dict = field(default_factory=dict)
    problems: tuple = ()
    slowed: tuple = ()
    start_joints: np.ndarray | None = None
    start_note: str = ""
    warnings: tuple = ()
    placement: Placement | None = None

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`); the settings as their JSON
        object (:meth:`PlanSettings.to_dict`)."""
        return {"source": self.source, "settings": self.settings.record(), "toolpath": self.toolpath,
                "segmentation": self.segmentation, "moves": self.moves, "passes": self.passes,
                "timings": self.timings, "problems": self.problems, "slowed": self.slowed,
                "start_joints": self.start_joints, "start_note": self.start_note, "warnings": self.warnings,
                "placement": self.placement}

    @classmethod
    def from_state(cls, state: dict) -> PlannedJob:
        """The job from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**{**state, "settings": PlanSettings.from_dict(state["settings"])})

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

    @property
    def not_executable(self) -> str | None:
        """Why the job cannot run on a robot, in one line, or None when it can: planned without a robot, moves the
        robot cannot make (counted in moves, as the summary counts them, with the first), no start joints. The
        drivers, ``planner run`` and the service refuse a job with a reason before anything moves.

        >>> from planner import PlanSettings, plan
        >>> print(plan("examples/nx_first_pass.cls", PlanSettings(robot="ur5e")).not_executable.split(" (")[0])
        the robot cannot make 2 of the job's moves
        """
        if self.settings.robot is None:
            return "the job was planned without a robot: plan it with robot=... (--robot) to execute it"
        if self.problems:
            return (f"the robot cannot make {len(self.problems)} of the job's moves (first: {self.problems[0]}); "
                    "nothing is executed")
        if self.start_joints is None:
            return "the job has no start joints (no reachable first pose)"
        return None

    def count(self, kind: str) -> int:
        """Number of moves of a kind ("cut", "rapid", "reorientation", "reconfiguration", "dwell", "skipped")."""
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
        from planner.trajectory import sample_counts

        return int(sample_counts(self.moves, rate or self.settings.rate).sum()) + 1

    @property
    def max_twist_deg(self) -> float:
        """Largest angle between the chosen frames and the exact RMF over all cuts, degrees (NaN with tool axes)."""
        v = [p.max_twist_deg for p in self.passes if not math.isnan(p.max_twist_deg)]
        return max(v, default=math.nan)

    @property
    def max_waypoint_error(self) -> float:
        """Largest distance of any cut's path from its points, m."""
        return max((p.max_waypoint_error for p in self.passes), default=0.0)

    def summary(self, program=None) -> dict:
        """The job's figures in human units (mm, s, deg).

        ``program``: the moves of the job's program (:func:`planner.export.plan_job_program`), whose statements
        slowed for the joint speed and acceleration limits join the slowed stretches of the feed: "slowed" (one
        line each, "<source> program: ...") and "program_slowed" (one entry per program move slowed: its kind, pass
        (-1 for no cut), source lines, the statements slowed and the largest stretch c: v over c, a over c^2).
        """
        out = {
            "source": self.source,
            "path_model": self.settings.path,
            "axes": self.settings.axes,
            "frame": self.settings.frame,
            "points": len(self.toolpath),
            "passes": len(self.passes),
            "rapids": self.count("rapid"),
            "reorientations": self.count("reorientation"),
            "skipped": self.count("skipped"),
            "dwells": self.count("dwell"),
            "dwell_s": float(sum(m.duration for m in self.moves if m.kind == "dwell")),
            "corners": self.corners,
            "cut_length_mm": 1e3 * sum(p.length for p in self.passes),
            "duration_s": self.duration,
            "tolerance_mm": 1e3 * self.settings.tolerance,
            "max_deviation_mm": 1e3 * self.max_deviation,
            "max_waypoint_error_mm": 1e3 * self.max_waypoint_error,
            "max_twist_vs_exact_rmf_deg": self.max_twist_deg,
            "max_axis_error_deg": self.max_axis_error_deg,
            "max_axis_departure_deg": self.max_axis_departure_deg,
            "spin_deg": self.spin_deg,
            "slerp_spin_deg": self.slerp_spin_deg,
            "knots_added": int(sum(p.knots_added for p in self.passes)),
            "planning_s": self.timings.get("plan", math.nan),
            "warnings": list(self.warnings),
        }
        if self.settings.robot is not None:
            out["robot"] = self.settings.robot
            if self.placement is not None:
                out["part_frame_auto"] = {"part_frame": list(self.placement.part_frame),
                                          "option": self.placement.option,
                                          "singularity_margin": self.placement.singularity_margin,
                                          "joint_margin_deg": math.degrees(self.placement.joint_margin)}
            out["reachable"] = not self.problems
            out["executable"] = self.not_executable is None
            out["not_executable"] = self.not_executable
            out["unreachable_passes"] = [p.index for p in self.passes if p.reachable is False]
            out["slowed_passes"] = [p.index for p in self.passes if p.feed_caps]
            out["slowed"] = list(self.slowed)
            if program is not None:
                low = [m for m in program if m.slowed]
                out["program_slowed"] = [{"kind": m.kind, "pass": m.pass_index, "first_line": m.first_line,
                                          "last_line": m.last_line, "statements": m.slowed_moves,
                                          "stretch": m.stretch} for m in low]
                out["slowed"] += [f"{self.source} program: {m.slowed}" for m in low]
            out["reconfigurations"] = self.reconfiguration_lines()
            out["reconfigured_passes"] = [r.pass_index for r in self.reconfigurations]
            if self.start_note:
                out["start"] = self.start_note
            if self.settings.spin == "reach":
                from planner.cam.spin_choice import spin_summary

                out["spin"] = spin_summary(self.moves)
        return out

    def _path_line(self, s: dict) -> str:
        if self.settings.path == "interpolate":
            return (f"  path      interpolate: C2 PH spline through the points, {s['cut_length_mm']:.1f} mm of cut, "
                    f"waypoint error {s['max_waypoint_error_mm']:.1e} mm; it bows up to {s['max_deviation_mm']:.4f} "
                    "mm from the chords")
        return (f"  path      cam: {s['cut_length_mm']:.1f} mm of cut; largest deviation from the CAM polyline "
                f"{s['max_deviation_mm']:.4f} mm (tolerance {s['tolerance_mm']:.4f} mm), "
                f"{s['knots_added']} knots added")

    def _axes_line(self, s: dict) -> str:
        if self.settings.axes == "path":
            return (f"  frames    {self.settings.frame} about the path tangent (tool z normal to the path, from -Z): "
                    f"largest twist against the exact RMF {s['max_twist_vs_exact_rmf_deg']:.3g} deg")
        source = {"file": "the file's tool axes", "approach": "the file's approach axes",
                  "fixed": "the CAM default axis +Z"}[self.settings.axes]
        return (f"  axes      {source}, interpolated on great circles (axis_field): largest error at the points "
                f"{s['max_axis_error_deg']:.2e} deg, between them {s['max_axis_departure_deg']:.3g} deg from the "
                f"great circles; spin about the tool axis {s['spin_deg']:.3g} deg (exact rotation-minimizing; "
                f"slerping the orientations: {s['slerp_spin_deg']:.4g} deg)")

    def describe(self, max_lines: int = 10, program=None) -> list[str]:
        """Lines for a person: the job's figures, the worst passes, the robot's problems; with ``program`` (the
        moves of the job's program, see :meth:`summary`) its statements slowed for the joint limits."""
        s = self.summary(program)
        worst = sorted(self.passes, key=lambda p: -p.max_deviation)[:3 if self.settings.path == "cam" else 0]
        lines = [
            f"{s['source']}: {counted(s['points'], 'point')} -> {counted(s['passes'], 'pass')}, "
            f"{counted(s['rapids'], 'rapid')}, {counted(s['reorientations'], 'reorientation')}, {s['skipped']} skipped"
            + (f", {counted(s['dwells'], 'dwell')} ({s['dwell_s']:.3g} s)" if s["dwells"] else "")
            + f"; {counted(s['corners'], 'corner')} "
            f"> {self.settings.corner_deg:g} deg",
            self._path_line(s),
            *["  worst     " + "; ".join(f"pass {p.index} (lines {p.first_line}-{p.last_line}) "
                                         f"{1e3 * p.max_deviation:.4f} mm" for p in worst)] * bool(worst),
            self._axes_line(s),
            f"  motion    {s['duration_s']:.1f} s; paths, frames and feed planned in {_seconds(s['planning_s'])}",
        ]
        if self.settings.robot is not None:
            if self.placement is not None:
                lines.append(f"  placed    {self.placement.describe()}")
            if s.get("spin"):
                lines.append(_spin_line(s["spin"], self.timings.get("spin", math.nan)))
            if self.slowed or program is not None:
                lines.append("  slowed    " + _slowed_line(len(self.slowed), s.get("program_slowed")))
                lines += [f"    {p}" for p in s["slowed"][:max_lines]]
                if len(s["slowed"]) > max_lines:
                    lines.append(f"    ... {len(s['slowed']) - max_lines} more")
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
                lines.append(f"  robot     {self.settings.robot}: {counted(len(self.problems), 'move')} with problems")
                lines += [f"    {p}" for p in self.problems[:max_lines]]
                if len(self.problems) > max_lines:
                    lines.append(f"    ... {len(self.problems) - max_lines} more")
                if self.settings.part_frame is None:
                    lines.append("  hint      no part frame given: the part's origin is the robot's base; place "
                                 "the part with part_frame (m, rad; on the command line in mm and deg, e.g. "
                                 "--part-frame 400mm,0,200mm,180deg,0,0, or --part-frame auto)")
        return lines

    # -- trajectory, save and load ----------------------------------------------------------------
    def trajectory(self, rate: float | None = None) -> Trajectory:
        """The job's trajectory at ``rate`` (default the job's): :class:`planner.trajectory.Trajectory`."""
        from planner.trajectory import Trajectory

        return Trajectory(self, self.settings.rate if rate is None else rate)

    def save(self, target) -> int:
        """Write the planned job to ``target`` (a path; written atomically) and return its size in bytes.

        The file (:mod:`planner.jobfile`: named arrays and a JSON manifest, format version
        :data:`JOB_FILE_VERSION`) holds the whole plan (paths, frames, time laws, arm configurations, reports):
        :func:`load_job` gives back a job whose trajectory and exports are identical, byte for byte, without
        planning again. It holds data only: reading one from anyone runs no code.
        """
        from planner.export.files import write_bytes_atomic

        blob = self.to_bytes()
        write_bytes_atomic(FilePath(target), blob)
        return len(blob)

    def to_bytes(self) -> bytes:
        """The saved job's bytes (what :meth:`save` writes; :func:`load_job` takes them back)."""
        return dump(self, JOB_TYPES)


def load_job(source) -> PlannedJob:
    """A job saved by :meth:`PlannedJob.save` (a path, or the file's bytes).

    Raises PlannerError (one line naming the file) when the file is not a saved job, is of the former pickle
    format (plan the job again), of another format version, or damaged.
    """
    raw = isinstance(source, bytes | bytearray | memoryview)
    name = "the data" if raw else str(os.fspath(source)) if isinstance(source, str | os.PathLike) else None
    if name is None:
        raise PlannerError(f"load_job takes a path or the file's bytes, got {type(source).__name__}")
    return load(source, JOB_TYPES, "PlannedJob", name)


def _check_move(s: dict) -> None:
    """What the trajectory relies on: the item of the move's kind, and for moves that move, their parts."""
    kind, item, frames = s["kind"], s["item"], s["frames"]
    need(isinstance(item, MOVE_ITEMS[kind]), f"a {kind} move carries out a {MOVE_ITEMS[kind].__name__}")
    moving = kind in ("cut", "rapid")
    need(not moving or (s["path"] is not None and frames is not None and s["profile"] is not None),
         f"a {kind} move needs its path, frames and profile")
    base = frames.base if isinstance(frames, SpunFrames) else frames
    need(kind != "cut" or isinstance(base, AxisField | PathToolField), "a cut's frames are a field along it")
    need(kind not in ("rapid", "reorientation") or isinstance(base, TurningFrames), f"a {kind}'s frames turn")
    need(not isinstance(frames, SpunFrames) or kind != "cut" or isinstance(base, AxisField),
         "a spin turns a cut about given tool axes")
    need(kind != "reconfiguration" or s["profile"] is not None, "a reconfiguration needs its profile")
    need(kind != "reconfiguration" or s["profile"].length == 1.0, "a reconfiguration's profile runs over [0, 1]")
    need(not moving or s["frames"].path is s["path"], f"a {kind}'s frames must be on its path")


def _check_job(s: dict) -> None:
    settings = PlanSettings.from_dict(s["settings"])
    settings.checked()  # names the first bad setting; the job keeps them as saved
    moves = s["moves"]
    rate = float(settings.rate)
    samples = sum(math.ceil(m.duration * rate) for m in moves)
    need(samples <= MAX_SAVED_POSES, f"the trajectory would be {samples:.3g} poses (at most {MAX_SAVED_POSES:g})")
    passes = {c.index for c in s["segmentation"].passes}
    for m in moves:
        if m.kind == "reconfiguration":
            need(settings.robot is not None, "a change of arm configuration needs a robot")
            need(m.item.pass_index in passes and m.item.passes[-1] in passes,
                 f"a change of arm configuration for pass {m.item.pass_index}, which the job does not have")
    need(s["start_joints"] is None or settings.robot is not None, "start joints without a robot")


#: The stored types of a saved job: the core's (:mod:`planner.jobfile.types`) and the job's own.
JOB_TYPES = {**{t.name: t for t in (
    StoredType("PlannedJob", PlannedJob, {
        "source": Str(), "settings": Json(depth=2), "toolpath": Ref("Toolpath"), "segmentation": Ref("Segmentation"),
        "moves": Seq(Ref("PlannedMove")), "passes": Seq(Ref("PassReport")), "timings": Map(NAN),
        "problems": Seq(Str()), "slowed": Seq(Str()), "start_joints": Opt(Arr("f8", (6,))), "start_note": Str(),
        "warnings": Seq(Str()), "placement": Opt(Ref("Placement"))}, check=_check_job),
    StoredType("PlannedMove", PlannedMove, {
        "kind": Str(tuple(MOVE_ITEMS)),
        "item": Ref("CutPass", "RapidMove", "Reorientation", "Reconfiguration", "Dwell", "Skipped"),
        "path": Opt(Ref("PHSpline")),
        "frames": Opt(Ref("AxisField", "TurningFrames", "PathToolField", "SpunFrames")),
        "profile": Opt(Ref("FeedProfile")),
        "start_frame": FRAME, "end_frame": FRAME, "point": VEC3, "pass_index": Int(-1), "fit": Opt(Ref("PassFit"))},
        check=_check_move),
    StoredType("PassReport", PassReport, {
        "index": Int(0), "operation": Str(), "first_line": LINE, "last_line": LINE, "points": Int(0),
        "length": NAN, "max_deviation": NAN, "max_axis_error_deg": NAN, "max_axis_departure_deg": NAN,
        "knots_added": Int(0), "start_reason": Str(), "end_reason": Str(), "start_corner_deg": NAN,
        "duration": NAN, "spin_deg": NAN, "slerp_spin_deg": NAN, "planning_time": NAN, "merged": Int(0),
        "reachable": Opt(Bool()), "reach_message": Str(), "feed_caps": Seq(Ref("CapWindow")),
        "max_twist_deg": NAN, "max_waypoint_error": NAN}),
)}, **CORE_TYPES}


def _slowed_line(stretches: int, program: list | None) -> str:
    """The headline of the slowed report: the feed's stretches lowered for the joint speeds; with the program's moves
    (``summary()["program_slowed"]``) its statements slowed for the joint speeds and accelerations."""
    parts = [f"feed lowered for the joint speed limits on {counted(stretches, 'stretch')}"] if stretches else []
    if program is not None:
        if program:
            c = max(p["stretch"] for p in program)
            n = sum(p["statements"] for p in program)
            parts.append(f"program: {counted(n, 'statement')} in {counted(len(program), 'move')} slowed for the "
                         f"joint speed and acceleration limits (v to {100.0 / c:.3g} %, a to {100.0 / c**2:.3g} % at "
                         "the most)")
        else:
            parts.append("program: no statement slowed for the joint limits")
    return "; ".join(parts)


def _spin_line(sp: dict, seconds: float) -> str:
    """The summary's spin figures for a person (spin="reach"), each against the RMM spin on the same samples."""
    a, b = sp["rmm"], sp["reach"]
    only = "; the passes reachable only with this spin" if sp["reachable_only_by_spin"] else ""
    return (f"  spin      reach (axisymmetric tool): {sp['spun_runs']} of {counted(sp['runs'], 'run')} spun, up to "
            f"{sp['max_spin_deg']:.3g} deg from the RMM spin, at most {sp['max_spin_rate_deg_s']:.3g} deg/s and "
            f"{sp['max_spin_acceleration_deg_s2']:.3g} deg/s^2; against the RMM spin on {sp['samples']} samples: "
            f"singularity margin {b['singularity_margin']:.3f} (RMM {a['singularity_margin']:.3f}), joint-limit margin "
            f"{b['joint_margin_deg']:.1f} deg (RMM {a['joint_margin_deg']:.1f}), steps too fast {b['too_fast_steps']} "
            f"(RMM {a['too_fast_steps']}), out of reach {b['out_of_reach_samples']} (RMM "
            f"{a['out_of_reach_samples']}), wrist travel {b['wrist_travel_deg']:.0f} deg (RMM "
            f"{a['wrist_travel_deg']:.0f}){only}; chosen in {_seconds(seconds)}")


def _seconds(t: float) -> str:
    """A duration for people: ms below 0.1 s, s above ("3.2 ms", "1.55 s"); "-" when unknown."""
    if not math.isfinite(t):
        return "-"
    return f"{1e3 * t:.1f} ms" if t < 0.1 else f"{t:.2f} s"


@dataclass(frozen=True)
class FitChunk:
    """The fits of some cutting passes of a job (made apart: :func:`planner.plan.fit_passes_of`), for their way to
    the process that plans the job (:func:`fits_to_bytes`)."""

    fits: tuple[PassFit, ...]

    def to_state(self) -> dict:
        """The fields as data, for the saved-job format (:mod:`planner.jobfile`)."""
        return {"fits": self.fits}

    @classmethod
    def from_state(cls, state: dict) -> FitChunk:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(tuple(state["fits"]))


#: The stored types of a chunk of fits (the job file's own format and types).
FIT_TYPES = {**JOB_TYPES, "FitChunk": StoredType("FitChunk", FitChunk, {"fits": Seq(Ref("PassFit"))})}


def fits_to_bytes(fits) -> bytes:
    """Fits of passes as bytes (the job file's format: arrays and a JSON manifest, nothing executable on load)."""
    return dump(FitChunk(tuple(fits)), FIT_TYPES)


def fits_from_bytes(data: bytes) -> list[PassFit]:
    """The fits :func:`fits_to_bytes` wrote (PlannerError, one line, if they are not)."""
    return list(load(data, FIT_TYPES, "FitChunk", "the fits").fits)


@dataclass(frozen=True, eq=False)
class PlannedPiece:
    """Moves ``first`` .. ``stop - 1`` of a job (indices into its segmentation's moves) planned apart, as
    :func:`planner.plan` plans them: a piece of a large job split across machines (:func:`planner.plan.plan_piece`),
    joined by ``plan(..., pieces=...)``.

    Attributes
    ----------
    first, stop : int
        Its moves in the job's (``segmentation.moves``).
    moves : tuple of PlannedMove
        Its moves, planned (stop - first of them).
    passes : tuple of PassReport
        The figures of its cutting passes.
    fit_warnings, warnings : tuple of str
        What fitting its passes, then planning its moves, warned about (the job's warnings list them in that order).
    timings : dict
        Wall times of its work, s: "fit", "chain" (the frames of the moves before it), "frames", "time_law",
        "piece" (all of it, its file read included).
    settings : str
        The settings it was planned with, resolved (:meth:`PlanSettings.to_dict` as JSON text): the join refuses a
        piece of other settings.
    """

    first: int
    stop: int
    moves: tuple
    passes: tuple
    fit_warnings: tuple = ()
    warnings: tuple = ()
    timings: dict = field(default_factory=dict)
    settings: str = ""

    def to_state(self) -> dict:
        """The fields as data, for the saved-job format (:mod:`planner.jobfile`)."""
        return {"first": self.first, "stop": self.stop, "moves": self.moves, "passes": self.passes,
                "fit_warnings": self.fit_warnings, "warnings": self.warnings, "timings": self.timings,
                "settings": self.settings}

    @classmethod
    def from_state(cls, state: dict) -> PlannedPiece:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**{**state, "moves": tuple(state["moves"]), "passes": tuple(state["passes"]),
                      "fit_warnings": tuple(state["fit_warnings"]), "warnings": tuple(state["warnings"])})


def _check_piece(s: dict) -> None:
    need(0 <= s["first"] < s["stop"], "a piece's moves first .. stop - 1 are not a range")
    need(len(s["moves"]) == s["stop"] - s["first"], "a piece's moves are not stop - first")


#: The stored types of a planned piece of a job (the job file's own format and types).
PIECE_TYPES = {**JOB_TYPES, "PlannedPiece": StoredType("PlannedPiece", PlannedPiece, {
    "first": Int(0), "stop": Int(1), "moves": Seq(Ref("PlannedMove")), "passes": Seq(Ref("PassReport")),
    "fit_warnings": Seq(Str()), "warnings": Seq(Str()), "timings": Map(NAN), "settings": Str()},
    check=_check_piece)}


def piece_to_bytes(piece: PlannedPiece) -> bytes:
    """A planned piece of a job as bytes (the job file's format: arrays and a JSON manifest, nothing executable on
    load)."""
    return dump(piece, PIECE_TYPES)


def piece_from_bytes(data: bytes) -> PlannedPiece:
    """The piece :func:`piece_to_bytes` wrote (PlannerError, one line, if it is not)."""
    return load(data, PIECE_TYPES, "PlannedPiece", "the piece")
