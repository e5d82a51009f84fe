"""``PlanSettings``: what a user sets for a planning job, the one schema of the CLI, the Python API and REST.

Every option means the same in every mode (one pass or a whole CAM job, waypoints or a CAM file), or is
refused with a one-line :class:`~planner.errors.PlannerError` naming it; none is silently ignored. SI
units throughout (m, s, rad; thresholds between chords and tool axes in degrees, as CAM systems give them).

Each field is declared once, in the dataclass itself (:class:`Setting`: its kind, range, SI unit, the unit people
type with the factor, its command-line option and a one-line description; :data:`SETTINGS` lists them in field
order). :meth:`PlanSettings.checked` validates from the declarations; the command line's options
(:mod:`planner.frontends.cli.options`) and the REST model (:mod:`planner.frontends.service.schemas`) are generated
from them. A new setting is one field here (and, when the planner uses it, the code that does). A refused value
raises :class:`~planner.errors.PlannerError` with ``field`` set to the field's name.

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

import contextlib
import math
from collections.abc import Iterator
from dataclasses import dataclass, field, fields, replace
from typing import Any

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
#: Feeds below this (m/s: one micrometre per second) are refused: a typing or unit mistake.
MIN_FEED = 1e-6
#: Feeds above this (m/s) are refused: no tool path is cut at 10 m/s.
MAX_FEED = 10.0

#: Default limits of the cutting motion: TCP speed (m/s), acceleration (m/s^2), jerk (m/s^3), angular speed.
DEFAULT_LIMITS = MotionLimits(speed=0.25, acceleration=0.5, jerk=5.0, angular_speed=1.0)
#: Default limits of a turn in place: angular speed (rad/s), acceleration (rad/s^2), jerk (rad/s^3).
DEFAULT_TURN_LIMITS = MotionLimits(speed=1.0, acceleration=2.0, jerk=20.0)
#: Default limits of every joint in a change of arm configuration (UR's movej defaults v = 1.05, a = 1.4).
DEFAULT_JOINT_LIMITS = MotionLimits(speed=1.05, acceleration=1.4, jerk=14.0)

#: Spin modes about the tool axis (see ``PlanSettings.spin``).
SPIN_MODES = ("rmm", "reach")
#: Default bounds of the spin chosen for the arm (``spin="reach"``): 90 deg/s and 360 deg/s^2.
DEFAULT_SPIN_RATE = math.pi / 2.0
DEFAULT_SPIN_ACCELERATION = 2.0 * math.pi

#: Kinds of setting (what :meth:`Setting.check` does, and how a front end types the value).
SETTING_KINDS = ("number", "choice", "limits", "robot", "pose", "output", "passes")


@dataclass(frozen=True)
class Setting:
    """One :class:`PlanSettings` field, declared once: what the Python API checks, the command-line option and the
    REST field are derived from this (:data:`SETTINGS` holds them all, in field order).

    Attributes
    ----------
    name : str
        The field name (also the REST JSON field and the command line's ``argparse`` dest).
    kind : str
        One of :data:`SETTING_KINDS`: "number" (a float in a range), "choice" (one of ``choices``), "limits"
        (a :class:`~planner.motion.MotionLimits`), "robot" (a UR model name or None), "pose" (6 numbers or a 4x4
        transform; ``choices`` lists words also taken, e.g. "auto"), "output" ((kind, pin)), "passes".
    doc : str
        What it sets, one line without units (the command line's help and the REST description add theirs).
    default : object
        The field's default (filled in from the dataclass).
    unit : str
        SI unit of the value ("m", "m/s", "deg", "Hz"; "" for a plain number or none).
    lo, hi : float or None
        "number": the range, ``lo`` exclusive unless ``lo_closed``, ``hi`` inclusive.
    lo_closed : bool
        Whether ``lo`` itself is allowed.
    optional : bool
        None is allowed (and means the documented default).
    choices : tuple of str
        "choice": the values allowed; "pose": the words allowed besides a pose.
    flag : str or None
        The command-line option (``planner plan`` / ``planner run``), or None when it has none.
    typed : str
        The unit people type on the command line ("mm", "mm/s", "deg", "Hz"); "" when it is ``unit``.
    per_si : float
        Typed units per SI unit: typed value = SI value * ``per_si`` (1e3 for m -> mm).
    usual : tuple of float or None
        "number": the range (SI) real jobs lie in. A value inside ``lo, hi`` but outside this is planned, and the
        command line warns, naming the likely unit mistake (``--feed 0.05``: 0.05 mm/s, or 0.05 m/s meant?).
    """

    name: str
    kind: str
    doc: str
    default: Any = None
    unit: str = ""
    lo: float | None = None
    hi: float | None = None
    lo_closed: bool = False
    optional: bool = False
    choices: tuple[str, ...] = ()
    flag: str | None = None
    typed: str = ""
    per_si: float = 1.0
    usual: tuple[float, float] | None = None

    @property
    def typed_unit(self) -> str:
        """The unit of the command-line value."""
        return self.typed or self.unit

    def range_text(self, scale: float = 1.0) -> str:
        """``(0, 1]`` or ``[0.001, 10000]``: the range of a "number", times ``scale`` (``per_si`` for typed)."""
        assert self.lo is not None and self.hi is not None
        return f"{'[' if self.lo_closed else '('}{self.lo * scale:g}, {self.hi * scale:g}]"

    def check(self, value) -> Any:
        """``value`` checked and normalized (floats as float, poses as 6 floats, passes sorted), or
        :class:`PlannerError` whose ``field`` is this setting's name."""
        if value is None and self.optional:
            return None
        with blame(self.name, value):
            return _CHECKS[self.kind](self, value)


def _setting(default, kind: str, doc: str, **declared) -> Any:
    """A PlanSettings field with its :class:`Setting` declaration (name and default filled in by :data:`SETTINGS`)."""
    return field(default=default, metadata={"setting": Setting("", kind, doc, **declared)})


@contextlib.contextmanager
def blame(name: str, value=None) -> Iterator[None]:
    """A :class:`PlannerError` raised inside that names no field yet is made to name ``name`` (and ``value``)."""
    try:
        yield
    except PlannerError as exc:
        if exc.field is None:
            exc.field, exc.value = name, value
        raise


@dataclass(frozen=True)
class PlanSettings:
    """What the user sets for a job (SI units: m, s, rad; ``corner_deg`` and ``axis_jump_deg`` in degrees).

    Each field is declared once, with its type, range, unit, the unit people type and its command-line option:
    :data:`SETTINGS` lists them (``print(describe_settings())`` shows them as a table), :meth:`checked` validates
    from them, and the command line and the REST schema are derived from them. See the module docstring for
    ``path``, ``axes`` and ``frame``.

    Examples
    --------
    A CAM polyline followed within 0.02 mm at 20 mm/s (SI units: m, m/s); ``checked`` fills in the arc tolerance.

    >>> from planner import PlanSettings
    >>> s = PlanSettings(path="cam", tolerance=2e-5, feed=0.02).checked()
    >>> f"{s.arc_tolerance:g} m"  # tolerance / 10
    '2e-06 m'

    A refused value names its field in the error itself (the REST 422 ``loc``), and its declaration says how the
    command line types it:

    >>> try:
    ...     PlanSettings(feed=-5.0).checked()
    ... except ValueError as exc:
    ...     print(exc.field, "|", exc)
    feed | feed must be in [1e-06, 10], got -5.0
    >>> from planner.settings import SETTING
    >>> d = SETTING["feed"]
    >>> d.unit, d.flag, d.typed, d.range_text(d.per_si)
    ('m/s', '--feed', 'mm/s', '[0.001, 10000]')
    """

    path: str = _setting("auto", "choice", "path model: interpolate (C2 PH spline through the points), cam (within "
                         "the tolerance of the polyline), auto (interpolate CSV/JSON, cam for APT/CLSF/G-code)",
                         choices=PATH_MODELS, flag="--path")
    tolerance: float = _setting(1e-5, "number", "cam model: largest distance from the polyline", unit="m", lo=0.0,
                                hi=1.0, flag="--tolerance", typed="mm", per_si=1e3)
    corner_deg: float = _setting(60.0, "number", "corners sharper than this (between consecutive chords) split "
                                 "passes", unit="deg", lo=0.0, hi=180.0, flag="--corner")
    axis_jump_deg: float = _setting(90.0, "number", "tool-axis jumps larger than this between two points turn in "
                                    "place", unit="deg", lo=0.0, hi=90.0, flag="--axis-jump")
    arc_tolerance: float | None = _setting(None, "number", "sagitta of the linearisation of CIRCLE / G02 / G03 arcs "
                                           "(none: tolerance / 10)", unit="m", lo=1e-9, hi=1.0, optional=True)
    axes: str = _setting("auto", "choice", "tool axis: file (the file's CAM axes, tip to spindle), approach (the "
                         "file's vectors are the approach axis), fixed (CAM default +Z), path (tool normal to the "
                         "path, spin by the frame method), auto (file if it has axes, else path for interpolate and "
                         "fixed for cam)", choices=AXIS_SOURCES, flag="--axes")
    frame: str = _setting("rmf", "choice", "spin method about the tool axis (methods other than rmf need the axes "
                          "path)", choices=FRAME_METHODS, flag="--frame")
    feed: float = _setting(0.05, "number", "feed where the file gives none", unit="m/s", lo=MIN_FEED, hi=MAX_FEED,
                           lo_closed=True, flag="--feed", typed="mm/s", per_si=1e3, usual=(1e-3, 2.0))
    feed_override: float = _setting(1.0, "number", "factor on every cutting feed (the file's and the feed), like a "
                                    "CNC feed override", lo=0.0, hi=10.0, flag="--feed-override")
    rapid_speed: float = _setting(0.25, "number", "speed of rapid moves between passes", unit="m/s", lo=MIN_FEED,
                                  hi=MAX_FEED, lo_closed=True, flag="--rapid-speed", typed="mm/s", per_si=1e3,
                                  usual=(5e-3, 5.0))
    limits: MotionLimits = _setting(DEFAULT_LIMITS, "limits", "limits of the cutting motion: speed, acceleration, "
                                    "jerk of the TCP, angular speed of the tool", unit="m/s, m/s^2, m/s^3, rad/s")
    turn_limits: MotionLimits = _setting(DEFAULT_TURN_LIMITS, "limits", "angular speed, acceleration and jerk of "
                                         "turns in place", unit="rad/s, rad/s^2, rad/s^3")
    joint_limits: MotionLimits = _setting(DEFAULT_JOINT_LIMITS, "limits", "with a robot: speed, acceleration and "
                                          "jerk of every joint in a change of the arm configuration",
                                          unit="rad/s, rad/s^2, rad/s^3")
    rate: float = _setting(500.0, "number", "controller rate of the trajectory (500 e-Series, 125 CB)", unit="Hz",
                           lo=0.0, hi=10_000.0, flag="--rate")
    robot: str | None = _setting(None, "robot", "UR model (ur3e, ur5e, ur10e, ur16e, ur20) for inverse kinematics, "
                                 "joint limits and programs; none plans without a robot", optional=True,
                                 flag="--robot")
    part_frame: tuple | str | None = _setting(None, "pose", "part (CAM) frame in the robot base: x,y,z,rx,ry,rz, or "
                                              "auto (with a robot: the part placed with the largest joint-limit and "
                                              "singularity margins; the planned job carries the frame found)",
                                              unit="m, rad", optional=True, choices=("auto",), flag="--part-frame")
    tcp: tuple | None = _setting(None, "pose", "tool centre point in the flange frame: x,y,z,rx,ry,rz", unit="m, rad",
                                 optional=True, flag="--tcp")
    feed_floor: float = _setting(DEFAULT_FLOOR, "number", "with a robot: the lowest fraction of the commanded feed to "
                                 "which the feed is lowered locally where a joint would exceed its speed limit",
                                 lo=0.0, hi=1.0)
    reach_step: float = _setting(2e-3, "number", "with a robot: spacing of the reachability check along each move "
                                 "(the CAM points are always checked)", unit="m", lo=0.0, hi=1.0)
    spin: str = _setting("rmm", "choice", "spin about the tool axis: rmm (the exact rotation-minimizing spin; for a "
                         "tool that is not symmetric) or reach (an axisymmetric tool: with a robot, the spin along "
                         "each run of passes chosen for the arm's singularity and joint-limit margins, joint speeds "
                         "and wrist travel, within spin_rate and spin_acceleration, otherwise as little as it can)",
                         choices=SPIN_MODES, flag="--spin")
    spin_rate: float = _setting(DEFAULT_SPIN_RATE, "number", "spin reach: largest rate of the spin about the tool axis",
                                unit="rad/s", lo=0.0, hi=20.0 * math.pi, flag="--spin-rate", typed="deg/s",
                                per_si=180.0 / math.pi)
    spin_acceleration: float = _setting(DEFAULT_SPIN_ACCELERATION, "number", "spin reach: largest acceleration of "
                                        "the spin about the tool axis", unit="rad/s^2", lo=0.0, hi=200.0 * math.pi,
                                        flag="--spin-acceleration", typed="deg/s^2", per_si=180.0 / math.pi)
    cut_output: tuple | None = _setting(None, "output", "digital output on exactly during every cut (spray valve, "
                                        "glue gun, torch): KIND:PIN with standard:0..7, configurable:0..7 or "
                                        "tool:0..1", optional=True, flag="--cut-output")
    passes: tuple | str | None = _setting(None, "passes", "plan only these cutting passes (numbers as the whole "
                                          "input splits them) or 'longest'; none plans all", optional=True,
                                          flag="--pass")
    max_poses: float = _setting(2e8, "number", "work budget: refuse jobs whose trajectory would exceed this many "
                                "poses (estimated before planning)", lo=0.0, hi=1e12, flag="--max-poses")
    max_points: float = _setting(2e7, "number", "work budget: the most points the fit may see after arcs are "
                                 "linearised", lo=0.0, hi=1e10)

    def checked(self) -> PlanSettings:
        """These settings validated (each from its :class:`Setting` declaration, in field order) and normalized
        (poses as 6 floats, ``arc_tolerance`` filled in).

        Raises PlannerError naming the first bad field (its ``field`` attribute, and the text)."""
        values = {s.name: s.check(getattr(self, s.name)) for s in SETTINGS}
        if values["part_frame"] == "auto" and values["robot"] is None:
            raise PlannerError("part_frame='auto' places the part for a robot: set robot (e.g. robot='ur5e')",
                               field="part_frame", value="auto")
        if values["spin"] == "reach" and values["robot"] is None:
            raise PlannerError("spin='reach' chooses the spin about the tool axis for a robot's arm: set robot "
                               "(e.g. robot='ur5e')", field="spin", value="reach")
        if values["arc_tolerance"] is None:
            values["arc_tolerance"] = values["tolerance"] / 10.0
        return replace(self, **values)

    def to_dict(self) -> dict:
        """The settings as plain JSON values (limits as dicts), for job files, exports and REST (every field; see
        :meth:`record` for what the files write)."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, MotionLimits):
                v = {g.name: getattr(v, g.name) for g in fields(v)}
            elif isinstance(v, tuple):
                v = list(v)
            out[f.name] = v
        return out

    def record(self) -> dict:
        """:meth:`to_dict` as a job's files and exports write it: the spin settings left out while all three are at
        their defaults (the RMM spin), so that such a job's saved file and exports are byte for byte those of the
        planner before the setting existed (:meth:`from_dict` fills them in)."""
        out = self.to_dict()
        if all(out[k] == SETTING[k].default for k in _SPIN_FIELDS):
            for k in _SPIN_FIELDS:
                del out[k]
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
                    with blame(name, kw[name]):
                        kw[name] = MotionLimits(**kw[name])
                except TypeError as exc:
                    raise PlannerError(f"{name}: {exc}", field=name, value=kw[name]) from None
        for name in ("part_frame", "tcp", "cut_output", "passes"):
            if isinstance(kw.get(name), list):
                kw[name] = tuple(kw[name])
        return cls(**kw)


#: Every PlanSettings field's declaration, in field order.
SETTINGS: tuple[Setting, ...] = tuple(replace(f.metadata["setting"], name=f.name, default=f.default)
                                      for f in fields(PlanSettings))
#: The declarations by field name.
SETTING: dict[str, Setting] = {s.name: s for s in SETTINGS}
#: The settings of the spin about the tool axis (left out of :meth:`PlanSettings.to_dict` at their defaults).
_SPIN_FIELDS = ("spin", "spin_rate", "spin_acceleration")


def _attributes_doc() -> str:
    """The "Attributes" section of PlanSettings' docstring, written from the declarations."""
    types = {f.name: f.type for f in fields(PlanSettings)}
    lines = ["", "    Attributes", "    ----------"]
    for s in SETTINGS:
        facts = [f"unit {s.unit}"] if s.unit else []
        facts += [f"in {s.range_text()}"] if s.kind == "number" else []
        facts += [f"default {s.default!r}"]
        facts += [f"option {s.flag}" + (f" in {s.typed}" if s.typed else "")] if s.flag else []
        lines += [f"    {s.name} : {types[s.name]}", f"        {s.doc[:1].upper()}{s.doc[1:]} ({'; '.join(facts)})."]
    return "\n".join(lines) + "\n"


_head, _examples = (PlanSettings.__doc__ or "").split("    Examples\n")
PlanSettings.__doc__ = _head.rstrip() + "\n" + _attributes_doc() + "\n    Examples\n" + _examples


def describe_settings() -> str:
    """The declaration table as text: field, kind, SI unit, range, command-line option and typed unit."""
    rows = [("field", "kind", "unit", "range", "option", "typed")]
    for s in SETTINGS:
        rows.append((s.name, s.kind, s.unit, s.range_text() if s.kind == "number" else ",".join(s.choices),
                     s.flag or "", s.typed_unit if s.flag else ""))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows)


def _check_number(s: Setting, value) -> float:
    assert s.lo is not None and s.hi is not None
    return check_in_range(value, s.name, s.lo, s.hi, lo_closed=s.lo_closed)


def _check_choice(s: Setting, value) -> str:
    if value not in s.choices:
        raise PlannerError(f"{s.name} must be one of {', '.join(s.choices)}; got {value!r}")
    return value


def _check_limits(s: Setting, value) -> MotionLimits:
    if not isinstance(value, MotionLimits):
        raise PlannerError(f"{s.name} must be a planner.motion.MotionLimits, got {type(value).__name__}")
    return value


def _check_robot(s: Setting, value) -> str:
    from planner.kinematics import get_model

    get_model(value)  # UnknownModelError names the model and the known ones
    return value


def _check_pose(s: Setting, value) -> tuple | str:
    if isinstance(value, str):
        if value in s.choices:
            return value
        words = "".join(f", {w!r}" for w in s.choices)
        raise PlannerError(f"{s.name} must be 6 numbers (x, y, z, rx, ry, rz in m, rad), a 4x4 transform{words} "
                           f"or None; got {value!r}")
    from planner.kinematics.poses import matrix_to_pose
    from planner.motion.stream import as_transform

    return tuple(float(x) for x in matrix_to_pose(as_transform(value, s.name)))


def _check_output(s: Setting, out) -> tuple:
    if (not isinstance(out, tuple | list) or len(out) != 2 or out[0] not in OUTPUT_KINDS
            or isinstance(out[1], bool) or not isinstance(out[1], int | np.integer)
            or not 0 <= int(out[1]) < OUTPUT_KINDS[out[0]]):
        raise PlannerError(f"{s.name} must be (kind, pin) with kind one of {sorted(OUTPUT_KINDS)} and a pin "
                           f"of that kind (standard/configurable 0..7, tool 0..1), got {out!r}")
    return (str(out[0]), int(out[1]))


def _check_passes(s: Setting, passes) -> tuple | str:
    if passes == "longest":
        return passes
    if (not isinstance(passes, tuple | list) or not passes
            or any(isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 0 for k in passes)):
        raise PlannerError(f"{s.name} must be pass numbers (>= 0), 'longest' or None, got {passes!r}")
    return tuple(sorted({int(k) for k in passes}))


_CHECKS = {"number": _check_number, "choice": _check_choice, "limits": _check_limits, "robot": _check_robot,
           "pose": _check_pose, "output": _check_output, "passes": _check_passes}
