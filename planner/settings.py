"""``PlanSettings``: what a user sets for a planning job, the one schema of the CLI, the Python API and REST.

Every option means the same in every mode (one pass or a whole CAM job, waypoints or a CAM file), or is
refused with a one-line :class:`~planner.errors.PlannerError` naming it; none is silently ignored. SI
units throughout (m, s, rad; thresholds between chords and tool axes in degrees, as CAM systems give them).

Two choices decide the geometry, each printed in the job's summary as resolved:

- ``path``: ``"interpolate"`` fits a C2 PH quintic spline *through* the points (the smooth curve that sparse
  CAD waypoints stand for), ``"cam"`` fits a C1 PH quintic spline within ``tolerance`` of the CAM polyline,
  straight runs kept straight (what a CAM system's dense linearised output means). ``"auto"`` (default):
  interpolate CSV/JSON waypoints and arrays, follow the polyline of APT/CLSF and G-code. Corners sharper than
  ``corner_deg`` split passes in both models.
- ``axes``: where the tool axis (tool z, the approach axis) comes from. ``"file"``: the file's tool axes in
  the CAM convention (from the tool tip towards the spindle, i.e. the surface normal side; the tool
  approaches along its negative), ``"approach"``: the file's vectors already are approach axes, ``"fixed"``:
  the CAM default tool axis +Z (tool z = -Z) everywhere, ``"path"``: the tool z normal to the path tangent,
  carried along by the frame method ``frame`` from a start nearest -Z (for CAD curves without axes).
  ``"auto"`` (default): ``"file"`` where the input has axes, else ``"path"`` for interpolated paths and
  ``"fixed"`` for CAM polylines.

``frame`` is the method of the spin about the tool axis: with the tool z normal to the path ("path" axes)
any of :data:`FRAME_METHODS` (exact RMF, GRM, Jüttler's rational RMM on a G1 PH cubic spline, ER,
double reflection); with tool axes (file, approach, fixed) the spin is the exact rotation-minimizing motion
about the axes, so only ``"rmf"`` applies there.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from planner.errors import PlannerError
from planner.kinematics.ur_outputs import OUTPUT_PINS
from planner.motion.caps import DEFAULT_FLOOR
from planner.motion.limits import MotionLimits
from planner.validation import check_in_range

#: Frame methods (spin about the tool axis).
FRAME_METHODS = ("rmf", "grm", "juttler", "er", "double-reflection")
#: Path models.
PATH_MODELS = ("auto", "interpolate", "cam")
#: Sources of the tool axis.
AXIS_SOURCES = ("auto", "file", "approach", "fixed", "path")
#: UR digital output kinds that a cut can switch, with their number of pins (the UR output table's
#: :data:`planner.kinematics.ur_outputs.OUTPUT_PINS`).
OUTPUT_KINDS = OUTPUT_PINS

#: Default limits of the cutting motion: TCP speed (m/s), acceleration (m/s^2), jerk (m/s^3), angular speed.
DEFAULT_LIMITS = MotionLimits(speed=0.25, acceleration=0.5, jerk=5.0, angular_speed=1.0)
#: Default limits of a turn in place: angular speed (rad/s), acceleration (rad/s^2), jerk (rad/s^3).
DEFAULT_TURN_LIMITS = MotionLimits(speed=1.0, acceleration=2.0, jerk=20.0)
#: Default limits of every joint in a change of arm configuration (UR's movej defaults v = 1.05, a = 1.4).
DEFAULT_JOINT_LIMITS = MotionLimits(speed=1.05, acceleration=1.4, jerk=14.0)


@dataclass(frozen=True)
class PlanSettings:
    """What the user sets for a job (SI units: m, s, rad; ``corner_deg`` and ``axis_jump_deg`` in degrees).

    Attributes
    ----------
    path : str
        Path model: "auto" (default), "interpolate" (C2 PH spline through the points) or "cam" (C1 PH spline
        within ``tolerance`` of the CAM polyline). See the module docstring.
    tolerance : float
        "cam" model: largest distance between the path and the CAM polyline, m (default 1e-5 = 0.01 mm).
    corner_deg : float
        Corners sharper than this (degrees between consecutive chords) stop the tool: a new pass.
    axis_jump_deg : float
        Tool-axis changes larger than this between two points (degrees, at most 90) are made by turning in place.
    arc_tolerance : float or None
        Sagitta of the linearisation of CIRCLE / G02 / G03 arcs, m (default ``tolerance / 10``).
    axes : str
        Source of the tool axis: "auto" (default), "file", "approach", "fixed" or "path" (module docstring).
    frame : str
        Spin about the tool axis: one of :data:`FRAME_METHODS` ("rmf", the exact rotation-minimizing frame,
        by default). Methods other than "rmf" need ``axes="path"`` (or "auto" resolving to it).
    feed : float
        Cutting feed where the input gives none, m/s (default 0.05).
    feed_override : float
        Factor on every cutting feed (the file's and ``feed``), like a CNC feed override.
    rapid_speed : float
        Speed of rapid moves between passes, m/s.
    limits : MotionLimits
        Limits of the cutting motion (its speed caps every feed; its angular speed caps the feed where the
        tool turns fast).
    turn_limits : MotionLimits
        Angular speed, acceleration and jerk of turns in place (rad/s, rad/s^2, rad/s^3).
    joint_limits : MotionLimits
        With a robot: speed, acceleration and jerk of every joint in a change of the arm configuration.
    rate : float
        Controller rate of the trajectory, Hz (500 e-Series, 125 CB-Series).
    robot : str or None
        UR model ("ur3e", "ur5e", "ur10e", "ur16e", "ur20") for inverse kinematics, joint limits and the
        programs; None (default) plans without a robot.
    part_frame : tuple (6,), "auto" or None
        The part (CAM) frame in the robot base frame, p[x, y, z, rx, ry, rz] (m, rotation vector); "auto"
        (with a robot) places the part for it: the translation and turn about the base z with the largest
        singularity and joint-limit margin over the job (:mod:`planner.cam.placement`), the planned job's
        settings then carry the frame found (reusable as the value).
    tcp : tuple (6,) or None
        The tool centre point in the flange frame.
    feed_floor : float
        With a robot: the lowest fraction (0..1] of the commanded feed to which the feed is lowered locally
        where a joint would exceed its speed limit.
    reach_step : float
        With a robot: spacing of the reachability check along each move, m (the CAM points are always checked).
    passes : tuple of int, "longest" or None
        Plan only these cutting passes of the input (numbers as the whole input splits them), or the longest
        one; None (default) plans all. The selected passes keep their source lines; rapids join them.
    max_poses : float
        Work budget: the largest trajectory (poses at ``rate``) a job may have, estimated from the toolpath
        before planning (:mod:`planner.budget`); default 2e8 (111 h at 500 Hz).
    max_points : float
        Work budget: the most points the fit may see after arcs are linearised; default 2e7.
    cut_output : tuple (kind, pin) or None
        A digital output that is on exactly during every cut (spray valve, glue gun, torch): ``("standard",
        0..7)``, ``("configurable", 0..7)`` or ``("tool", 0..1)``; None (default) switches nothing.
    """

    path: str = "auto"
    tolerance: float = 1e-5
    corner_deg: float = 60.0
    axis_jump_deg: float = 90.0
    arc_tolerance: float | None = None
    axes: str = "auto"
    frame: str = "rmf"
    feed: float = 0.05
    feed_override: float = 1.0
    rapid_speed: float = 0.25
    limits: MotionLimits = DEFAULT_LIMITS
    turn_limits: MotionLimits = DEFAULT_TURN_LIMITS
    joint_limits: MotionLimits = DEFAULT_JOINT_LIMITS
    rate: float = 500.0
    robot: str | None = None
    part_frame: tuple | str | None = None
    tcp: tuple | None = None
    feed_floor: float = DEFAULT_FLOOR
    reach_step: float = 2e-3
    cut_output: tuple | None = None
    passes: tuple | str | None = None
    max_poses: float = 2e8
    max_points: float = 2e7

    def checked(self) -> PlanSettings:
        """These settings validated and normalized (poses as 6 floats, ``arc_tolerance`` filled in).

        Raises PlannerError naming the first bad field.
        """
        s = self
        _choice(s.path, "path", PATH_MODELS)
        _choice(s.axes, "axes", AXIS_SOURCES)
        _choice(s.frame, "frame", FRAME_METHODS)
        tol = _number(s.tolerance, "tolerance", 0.0, 1.0)
        arc = tol / 10.0 if s.arc_tolerance is None else _number(s.arc_tolerance, "arc_tolerance", 1e-9, 1.0)
        _number(s.corner_deg, "corner_deg", 0.0, 180.0)
        _number(s.axis_jump_deg, "axis_jump_deg", 0.0, 90.0)
        for name, hi in (("feed", 10.0), ("feed_override", 10.0), ("rapid_speed", 10.0), ("rate", 10_000.0),
                         ("reach_step", 1.0)):
            _number(getattr(s, name), name, 0.0, hi)
        _number(s.feed_floor, "feed_floor", 0.0, 1.0)
        _number(s.max_poses, "max_poses", 0.0, 1e12)
        _number(s.max_points, "max_points", 0.0, 1e10)
        for name in ("limits", "turn_limits", "joint_limits"):
            if not isinstance(getattr(s, name), MotionLimits):
                kind = type(getattr(s, name)).__name__
                raise PlannerError(f"{name} must be a planner.motion.MotionLimits, got {kind}")
        auto = isinstance(s.part_frame, str) and s.part_frame == "auto"
        if isinstance(s.part_frame, str) and not auto:
            raise PlannerError(f"part_frame must be 6 numbers (x, y, z, rx, ry, rz in m, rad), a 4x4 transform, 'auto' "
                               f"or None; got {s.part_frame!r}")
        if auto and s.robot is None:
            raise PlannerError("part_frame='auto' places the part for a robot: set robot (e.g. robot='ur5e')")
        part_frame: tuple | str | None = "auto" if auto else _pose(s.part_frame, "part_frame")
        tcp = _pose(s.tcp, "tcp")
        if s.robot is not None:
            from planner.kinematics import get_model

            get_model(s.robot)  # UnknownModelError names the model and the known ones
        out = s.cut_output
        if out is not None:
            if (not isinstance(out, tuple | list) or len(out) != 2 or out[0] not in OUTPUT_KINDS
                    or isinstance(out[1], bool) or not isinstance(out[1], int | np.integer)
                    or not 0 <= int(out[1]) < OUTPUT_KINDS[out[0]]):
                raise PlannerError(f"cut_output must be (kind, pin) with kind one of {sorted(OUTPUT_KINDS)} and a pin "
                                   f"of that kind (standard/configurable 0..7, tool 0..1), got {out!r}")
            out = (str(out[0]), int(out[1]))
        passes = s.passes
        if passes is not None and passes != "longest":
            if (not isinstance(passes, tuple | list) or not passes
                    or any(isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 0 for k in passes)):
                raise PlannerError(f"passes must be pass numbers (>= 0), 'longest' or None, got {passes!r}")
            passes = tuple(sorted({int(k) for k in passes}))
        return replace(s, tolerance=tol, arc_tolerance=arc, cut_output=out, passes=passes,
                       part_frame=part_frame, tcp=tcp)

    def to_dict(self) -> dict:
        """The settings as plain JSON values (limits as dicts), for job files, exports and REST."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, MotionLimits):
                v = {g.name: getattr(v, g.name) for g in fields(v)}
            elif isinstance(v, tuple):
                v = list(v)
            out[f.name] = v
        return out

    @classmethod
    def from_dict(cls, data: dict) -> PlanSettings:
        """Settings from :meth:`to_dict` output (unknown keys refused by name)."""
        if not isinstance(data, dict):
            raise PlannerError(f"settings must be an object, got {type(data).__name__}")
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise PlannerError(f"unknown setting{'s' * (len(unknown) > 1)} {', '.join(unknown)} "
                               f"(known: {', '.join(sorted(known))})")
        kw = dict(data)
        for name in ("limits", "turn_limits", "joint_limits"):
            if isinstance(kw.get(name), dict):
                try:
                    kw[name] = MotionLimits(**kw[name])
                except TypeError as exc:
                    raise PlannerError(f"{name}: {exc}") from None
        for name in ("part_frame", "tcp", "cut_output", "passes"):
            if isinstance(kw.get(name), list):
                kw[name] = tuple(kw[name])
        return cls(**kw)


def _choice(value, name: str, options: tuple) -> None:
    if value not in options:
        raise PlannerError(f"{name} must be one of {', '.join(options)}; got {value!r}")


def _number(value, name: str, lo: float, hi: float) -> float:
    """A float in (lo, hi], or PlannerError naming ``name``."""
    return check_in_range(value, name, lo, hi)


def _pose(value, name: str) -> tuple | None:
    """A UR pose (6 floats) from a pose or a 4x4 rigid transform; None stays None."""
    if value is None:
        return None
    from planner.kinematics.poses import as_transform, matrix_to_pose

    return tuple(float(x) for x in matrix_to_pose(as_transform(value, name)))
