"""What the command line shares between its commands: the planning options of ``planner plan`` and ``planner run``
(the :class:`planner.PlanSettings` fields in the units people type), their checks, the one-line usage errors and the
progress bars.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass

import numpy as np

from planner.errors import PlannerError
from planner.settings import AXIS_SOURCES, FRAME_METHODS, PATH_MODELS, PlanSettings

#: Largest rotation vector of --part-frame / --tcp, rad (any angle is reachable below 2 pi; beyond this it is a
#: typing mistake, and beyond ~1e16 rad no angle is left in the float at all).
MAX_ROTVEC = 100.0


def _pose(text: str | None, name: str):
    """``--part-frame`` / ``--tcp`` text -> 6 floats (m, rad), or PlannerError naming the option."""
    if text is None:
        return None
    if name == "--part-frame" and text.strip().lower() == "auto":
        return "auto"  # placed for the robot by the planner (PlanSettings.part_frame = "auto")
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        raise PlannerError(f"{name} {text}: must be six numbers x,y,z,rx,ry,rz (m, rad)") from None
    if len(v) != 6:
        raise PlannerError(f"{name} {text}: must be six numbers x,y,z,rx,ry,rz (m, rad), got {len(v)}")
    from planner.budget import MAX_COORDINATE

    for i, (x, what) in enumerate(zip(v, ("x", "y", "z", "rx", "ry", "rz"), strict=True)):
        if not np.isfinite(x):
            raise PlannerError(f"{name} {text}: {what} (number {i + 1}) must be finite")
        if i < 3 and abs(x) > MAX_COORDINATE:
            raise PlannerError(f"{name} {text}: {what} = {x:g} m is beyond any robot cell (at most "
                               f"{MAX_COORDINATE:g} m; the pose is in metres)")
    if math.hypot(*v[3:]) > MAX_ROTVEC:
        raise PlannerError(f"{name} {text}: the rotation vector rx,ry,rz is longer than {MAX_ROTVEC:g} rad "
                           "(it is in radians: an angle of at most pi is enough)")
    return tuple(v)


def _output(text: str | None):
    """``--cut-output KIND:PIN`` -> (kind, pin), or PlannerError naming the option."""
    if text is None:
        return None
    from planner.settings import OUTPUT_KINDS

    kind, _, pin = text.partition(":")
    usage = "KIND:PIN with standard:0..7, configurable:0..7 or tool:0..1"
    try:
        k = int(pin)
    except ValueError:
        raise PlannerError(f"--cut-output {text}: must be {usage}") from None
    if kind not in OUTPUT_KINDS:
        raise PlannerError(f"--cut-output {text}: unknown output kind {kind!r} (must be {usage})")
    if not 0 <= k < OUTPUT_KINDS[kind]:
        raise PlannerError(f"--cut-output {text}: {kind} outputs have pins 0..{OUTPUT_KINDS[kind] - 1}")
    return (kind, k)


class Number(float):
    """A float option's value that remembers the text the user typed (for messages that quote it)."""

    text: str

    def __new__(cls, text: str):
        x = super().__new__(cls, text)
        x.text = text.strip()
        return x

    def __reduce__(self):  # pickled (a saved job's settings) as the plain float it is
        return (float, (float(self),))


Number.__name__ = "number"  # argparse: "invalid number value: 'abc'"


@dataclass(frozen=True)
class NumericOption:
    """A numeric command-line option and its range in the user's units (the PlanSettings range, converted).

    ``lo`` is exclusive unless ``lo_closed``; ``hi`` is inclusive (None: no upper bound, only finite)."""

    flag: str
    dest: str
    unit: str
    lo: float
    hi: float | None
    lo_closed: bool = False

    def check(self, value) -> None:
        """PlannerError ``--flag TEXT: must be ...`` unless ``value`` is in range."""
        if value is None:
            return
        x = float(value)
        if math.isfinite(x) and (x >= self.lo if self.lo_closed else x > self.lo) and (
                self.hi is None or x <= self.hi):
            return
        unit = f" {self.unit}" if self.unit else ""
        rule = f"{'at least' if self.lo_closed else '>'} {self.lo:g}{unit}"
        rule += f" and at most {self.hi:g}{unit}" if self.hi is not None else " and finite"
        text = getattr(value, "text", None) or f"{x:g}"
        raise PlannerError(f"{self.flag} {text}: must be {rule}")


def _numeric_options() -> tuple[NumericOption, ...]:
    from planner.budget import MAX_FEED, MIN_FEED

    mm_s = (MIN_FEED * 1e3, MAX_FEED * 1e3)  # the budget's plausible feeds (settings: (0, 10] m/s)
    return (
        NumericOption("--tolerance", "tolerance", "mm", 0.0, 1000.0),
        NumericOption("--corner", "corner", "deg", 0.0, 180.0),
        NumericOption("--axis-jump", "axis_jump", "deg", 0.0, 90.0),
        NumericOption("--feed", "feed", "mm/s", *mm_s, lo_closed=True),
        NumericOption("--feed-override", "feed_override", "", 0.0, 10.0),
        NumericOption("--rapid-speed", "rapid_speed", "mm/s", *mm_s, lo_closed=True),
        NumericOption("--rate", "rate", "Hz", 0.0, 10_000.0),
        NumericOption("--max-poses", "max_poses", "", 0.0, 1e12),
        # planner run's own (planner.frontends.cli.run): URDriver's servoJ ranges, the simulator's speed, a TCP port
        NumericOption("--lookahead", "lookahead", "s", 0.03, 0.2, lo_closed=True),
        NumericOption("--gain", "gain", "", 100.0, 2000.0, lo_closed=True),
        NumericOption("--sim-speed", "sim_speed", "", 0.0, None),
        NumericOption("--modbus-port", "modbus_port", "", 1.0, 65535.0, lo_closed=True),
    )


def check_numeric_options(args: argparse.Namespace) -> None:
    """Every numeric option of ``planner plan`` / ``run`` that ``args`` has, in the user's units, before any file
    is read: PlannerError ``--feed -5: must be at least 0.001 mm/s and at most 10000 mm/s``."""
    for opt in _numeric_options():
        if hasattr(args, opt.dest):
            opt.check(getattr(args, opt.dest))


def settings_from_args(args: argparse.Namespace) -> PlanSettings:
    """The PlanSettings of ``planner plan``'s options (mm and mm/s on the command line, SI in the settings).

    Every option is checked first in the user's units and named as typed (:func:`check_numeric_options`)."""
    check_numeric_options(args)
    _check_machine(getattr(args, "machine", None))
    d = PlanSettings()
    return PlanSettings(
        path=args.path, tolerance=args.tolerance / 1e3, corner_deg=float(args.corner),
        axis_jump_deg=float(args.axis_jump), axes=args.axes, frame=args.frame, feed=args.feed / 1e3,
        feed_override=float(args.feed_override), rapid_speed=args.rapid_speed / 1e3, rate=float(args.rate),
        robot=None if args.robot in (None, "none") else args.robot,
        part_frame=_pose(args.part_frame, "--part-frame"), tcp=_pose(args.tcp, "--tcp"),
        feed_floor=d.feed_floor, cut_output=_output(args.cut_output), passes=_passes(args.pass_index),
        max_poses=float(args.max_poses),
    ).checked()


def _check_machine(name: str | None) -> None:
    """``--machine NAME`` names a known machine preset (checked before the file is read)."""
    if name is None:
        return
    from planner.io.machines import machine_kinematics

    try:
        machine_kinematics(name)
    except (ValueError, TypeError):
        raise PlannerError(f"--machine {name}: unknown machine (known: haas-umc-750)") from None


def _passes(text: str | None):
    if text is None or text == "all":
        return None
    if text == "longest":
        return "longest"
    try:
        passes = tuple(int(x) for x in text.split(","))
    except ValueError:
        raise PlannerError(f"--pass {text}: must be pass numbers K[,K...], 'longest' or 'all'") from None
    if any(k < 0 for k in passes):
        raise PlannerError(f"--pass {text}: pass numbers start at 0")
    return passes


class Progress:
    """tqdm bars on stderr, one per stage (the callback the service uses too): (stage, done, total)."""

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.bars: dict = {}

    def __call__(self, stage: str, done: int, total: int) -> None:
        if not self.enabled:
            return
        from tqdm import tqdm

        bar = self.bars.get(stage)
        if bar is None:
            bar = self.bars[stage] = tqdm(total=total, desc=f"  {stage}", unit=" poses" if stage == "samples" else "",
                                          file=sys.stderr, leave=False, dynamic_ncols=True)
        bar.total = total
        bar.n = done
        bar.refresh()

    def close(self) -> None:
        for bar in self.bars.values():
            bar.close()
        self.bars.clear()


def add_plan_options(p: argparse.ArgumentParser, *, outputs: bool = True) -> None:
    """The options of ``planner plan`` (the PlanSettings fields in mm and mm/s, reader options, and with
    ``outputs`` -o/--plot/--progress) on a parser: ``planner run`` takes the same ones."""
    D = PlanSettings()
    p.add_argument("input", help="toolpath: APT/CL data, CSV, JSON or 5-axis G-code")
    p.add_argument("--path", choices=list(PATH_MODELS), default=D.path,
                   help="path model: interpolate (C2 PH spline through the points), cam (within --tolerance of the "
                        "polyline), auto (default: interpolate CSV/JSON, cam for APT/CLSF/G-code)")
    p.add_argument("--axes", choices=list(AXIS_SOURCES), default=D.axes,
                   help="tool axis: file (the file's CAM axes, tip to spindle), approach (the file's vectors are the "
                        "approach axis), fixed (CAM default +Z), path (tool normal to the path, spin by --frame), "
                        "auto (default: file if it has axes, else path for interpolate and fixed for cam)")
    p.add_argument("--frame", choices=list(FRAME_METHODS), default=D.frame,
                   help="spin method about the tool axis (methods other than rmf need --axes path)")
    p.add_argument("--tolerance", type=Number, default=D.tolerance * 1e3,
                   help=f"cam model: largest distance from the polyline, mm (default {D.tolerance * 1e3:g})")
    p.add_argument("--corner", type=Number, default=D.corner_deg,
                   help=f"corners sharper than this (deg) split passes (default {D.corner_deg:g})")
    p.add_argument("--axis-jump", type=Number, default=D.axis_jump_deg,
                   help=f"tool-axis jumps larger than this (deg) turn in place (default {D.axis_jump_deg:g})")
    p.add_argument("--feed", type=Number, default=D.feed * 1e3,
                   help=f"feed where the file gives none, mm/s (default {D.feed * 1e3:g})")
    p.add_argument("--feed-override", type=Number, default=D.feed_override, help="factor on every cutting feed")
    p.add_argument("--rapid-speed", type=Number, default=D.rapid_speed * 1e3,
                   help=f"speed of rapid moves, mm/s (default {D.rapid_speed * 1e3:g})")
    p.add_argument("--rate", type=Number, default=D.rate, help="controller rate in Hz (500 e-Series, 125 CB)")
    p.add_argument("--robot", default="none", help="ur3e, ur5e, ur10e, ur16e, ur20, or none (default)")
    p.add_argument("--part-frame", help="part frame in the robot base: x,y,z,rx,ry,rz (m, rad), or auto (the part "
                                        "placed for the robot with the largest joint-limit and singularity margins)")
    p.add_argument("--tcp", help="tool centre point in the flange frame: x,y,z,rx,ry,rz (m, rad)")
    p.add_argument("--cut-output", help="digital output on during every cut, KIND:PIN (standard:0, tool:1, ...)")
    p.add_argument("--pass", dest="pass_index", help="plan only passes K[,K...] or 'longest' (default: all)")
    p.add_argument("--max-poses", type=Number, default=D.max_poses,
                   help=f"refuse jobs whose trajectory would exceed this many poses (default {D.max_poses:g})")
    p.add_argument("--units", choices=["mm", "m", "inch"], help="units of a CSV/JSON file (default mm)")
    p.add_argument("--machine", help="machine kinematics for 5-axis G-code (e.g. haas-umc-750)")
    if outputs:
        p.add_argument("--progress", action="store_true", help="show progress bars even when not on a terminal")
        p.add_argument("-o", "--output", help="write the job: .csv / .json trajectory, .script URScript program "
                       "(movep along the passes within --tolerance, movel between), .job saved plan")
        p.add_argument("--plot", help="write a picture (.png, .svg, .pdf): paths and tool axes, frames, speed, "
                       "joints, fit")


class Parser(argparse.ArgumentParser):
    """argparse with one line on stderr for a usage error (``planner plan: error: argument --feed: ...``, exit 2),
    not the usage block; ``--help`` is unchanged. Subcommand parsers (``plan``, ``run``, ...) inherit it."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")
