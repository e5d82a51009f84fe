"""What the command line shares between its commands: the planning options of ``planner plan`` and ``planner run``
(the :class:`planner.PlanSettings` fields in the units people type), their checks, the one-line usage errors and the
progress bars.

The planning options are derived from the settings' declaration (:data:`planner.settings.SETTINGS`): each field with
a ``flag`` is an option of that name, typed in its ``typed`` unit, with its help, default and range converted;
a new setting with a flag is on the command line with nothing written here.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from dataclasses import dataclass
from typing import Any

from drivers.servo import GAIN_RANGE, LOOKAHEAD_RANGE
from planner.errors import PlannerError
from planner.export.job_script import MAX_PROGRAM_BYTES
from planner.settings import OUTPUT_KINDS, SETTING, SETTINGS, PlanSettings, Setting, blame
from planner.wording import quantity

#: Largest rotation vector of --part-frame / --tcp, rad (any angle is reachable below 2 pi; beyond this it is a
#: typing mistake, and beyond ~1e16 rad no angle is left in the float at all).
MAX_ROTVEC = 100.0


#: Units a --part-frame / --tcp value may carry: per SI unit (m, rad). The command line types poses in mm and deg.
LENGTH_UNITS = {"mm": 1e3, "cm": 1e2, "m": 1.0, "in": 1.0 / 0.0254}
ANGLE_UNITS = {"deg": 180.0 / math.pi, "rad": 1.0}
POSE_USAGE = "six values x,y,z,rx,ry,rz, each with its unit (400mm or 0.4m, 90deg or 1.5708rad; 0 needs none)"
_QUANTITY = re.compile(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?(?:inf|nan))\s*([a-zA-Z]*)\s*\Z",
                       re.IGNORECASE)


def _pose(s: Setting, text: str):
    """``--part-frame`` / ``--tcp`` text -> 6 floats (m, rad) or one of the setting's words ("auto": placed for
    the robot by the planner), or PlannerError naming the option.

    Each value carries its unit (``400mm``, ``0.4m``, ``90deg``, ``1.5708rad``); a bare 0 is 0 in any unit. A bare
    number otherwise is refused: these options took metres and radians before 0.2 (they are typed in mm and deg
    now, like every other length and angle of the command line), so an old command line must not change meaning.
    """
    name = s.flag
    if text.strip().lower() in s.choices:
        return text.strip().lower()
    parts = text.split(",")
    if len(parts) != 6:
        raise PlannerError(f"{name} {text}: must be {POSE_USAGE}, got {len(parts)} values", field=s.name, value=text)
    from planner.budget import MAX_COORDINATE

    v = []
    for i, (part, what) in enumerate(zip(parts, ("x", "y", "z", "rx", "ry", "rz"), strict=True)):
        units, kind = (LENGTH_UNITS, "mm") if i < 3 else (ANGLE_UNITS, "deg")
        m = _QUANTITY.match(part)
        if m is None:
            raise PlannerError(f"{name} {text}: {what} = {part.strip()!r} is not a number with a unit (must be "
                               f"{POSE_USAGE})", field=s.name, value=text)  # fmt: skip
        x, unit = float(m.group(1)), m.group(2).lower()
        if not math.isfinite(x):
            raise PlannerError(f"{name} {text}: {what} (number {i + 1}) must be finite", field=s.name, value=text)
        if unit == "" and x != 0.0:
            si, typed = ("m", x * 1e3) if i < 3 else ("rad", math.degrees(x))
            raise PlannerError(f"{name} {text}: {what} = {part.strip()} has no unit: a bare number meant {si} before "
                               f"0.2, and {name} is typed in {kind} now; write {m.group(1)}{si} for what it meant "
                               f"({quantity(typed, kind)}), or the value in {kind} with its unit",
                               field=s.name, value=text)  # fmt: skip
        if unit and unit not in units:
            raise PlannerError(f"{name} {text}: {what} = {part.strip()}: unknown unit {unit!r} ("
                               f"{'a length' if i < 3 else 'an angle'} takes {', '.join(units)})",
                               field=s.name, value=text)  # fmt: skip
        v.append(x / units[unit] if unit else 0.0)
        if i < 3 and abs(v[-1]) > MAX_COORDINATE:
            hint = (f"; did you mean {m.group(1)}mm?" if unit == "m" and abs(x) / 1e3 <= MAX_COORDINATE else "")
            raise PlannerError(f"{name} {text}: {what} = {part.strip()} is beyond any robot cell (at most "
                               f"{MAX_COORDINATE:g} m){hint}", field=s.name, value=text)  # fmt: skip
    if math.hypot(*v[3:]) > MAX_ROTVEC:
        raise PlannerError(f"{name} {text}: the rotation vector rx,ry,rz is longer than {math.degrees(MAX_ROTVEC):.0f} "
                           "deg (an angle of at most 180 deg is enough)", field=s.name, value=text)
    return tuple(v)


def parse_pose(text: str, name: str = "part_frame"):
    """A ``--part-frame`` (or, with ``name="tcp"``, ``--tcp``) value as typed -> 6 floats (m, rad) or its word
    ("auto"); the inverse of :func:`planner.wording.pose_option`. PlannerError naming the option."""
    return _pose(SETTING[name], text)


def _output(s: Setting, text: str):
    """``--cut-output KIND:PIN`` -> (kind, pin), or PlannerError naming the option."""
    kind, _, pin = text.partition(":")
    usage = "KIND:PIN with standard:0..7, configurable:0..7 or tool:0..1"
    try:
        k = int(pin)
    except ValueError:
        raise PlannerError(f"{s.flag} {text}: must be {usage}") from None
    if kind not in OUTPUT_KINDS:
        raise PlannerError(f"{s.flag} {text}: unknown output kind {kind!r} (must be {usage})")
    if not 0 <= k < OUTPUT_KINDS[kind]:
        raise PlannerError(f"{s.flag} {text}: {kind} outputs have pins 0..{OUTPUT_KINDS[kind] - 1}")
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
        raise PlannerError(f"{self.flag} {text}: must be {rule}", field=self.dest, value=value)

    @classmethod
    def of(cls, s: Setting) -> NumericOption:
        """The option of a "number" setting with a flag: its range in the typed unit."""
        assert s.flag is not None and s.lo is not None and s.hi is not None
        return cls(s.flag, s.name, s.typed_unit, s.lo * s.per_si, s.hi * s.per_si, s.lo_closed)


#: The settings that are options of ``planner plan`` and ``planner run``, in declaration order.
PLAN_SETTINGS = tuple(s for s in SETTINGS if s.flag is not None)


def _numeric_options() -> tuple[NumericOption, ...]:
    return (
        *(NumericOption.of(s) for s in PLAN_SETTINGS if s.kind == "number"),
        # planner run's own (planner.frontends.cli.run): URDriver's servoJ ranges, the simulator's speed, a TCP port
        NumericOption("--lookahead", "lookahead", "s", *LOOKAHEAD_RANGE, lo_closed=True),
        NumericOption("--gain", "gain", "", *GAIN_RANGE, lo_closed=True),
        NumericOption("--sim-speed", "sim_speed", "", 0.0, None),
        NumericOption("--modbus-port", "modbus_port", "", 1.0, 65535.0, lo_closed=True),
    )


def check_numeric_options(args: argparse.Namespace) -> None:
    """Every numeric option of ``planner plan`` / ``run`` that ``args`` has, in the user's units, before any file
    is read: PlannerError ``--feed -5: must be at least 0.001 mm/s and at most 10000 mm/s``."""
    for opt in _numeric_options():
        if hasattr(args, opt.dest):
            opt.check(getattr(args, opt.dest))


#: The likely mistake behind a typed value below / above its usual range: (unit meant, typed units per that unit).
_LIKELY_UNIT = {"mm/s": (("m/s", 1e3), ("mm/min", 1.0 / 60.0))}


def unusual_values(args: argparse.Namespace) -> list[str]:
    """A line for each option whose value is valid but outside the range real jobs lie in (``Setting.usual``),
    naming the likely unit mistake: ``--feed 0.05 mm/s is below the usual 1 to 2000 mm/s: did you type m/s ...``."""
    lines = []
    for s in PLAN_SETTINGS:
        value = getattr(args, s.name, None)
        if s.usual is None or value is None:
            continue
        lo, hi = (x * s.per_si for x in s.usual)
        x = float(value)
        if lo <= x <= hi:
            continue
        text = getattr(value, "text", None) or f"{x:g}"
        line = f"{s.flag} {text} {s.typed_unit} is {'below' if x < lo else 'above'} the usual {lo:g} to {hi:g} " \
               f"{s.typed_unit}"
        likely = _LIKELY_UNIT.get(s.typed_unit)
        if likely is not None:
            meant, factor = likely[0 if x < lo else 1]
            line += f": did you mean {text} {meant} ({x * factor:g} {s.typed_unit})?"
        lines.append(line)
    return lines


def settings_from_args(args: argparse.Namespace) -> PlanSettings:
    """The PlanSettings of ``planner plan``'s options (mm and mm/s on the command line, SI in the settings).

    Every option is checked first in the user's units and named as typed (:func:`check_numeric_options`); a refusal
    is a PlannerError whose ``field`` is the setting's name."""
    check_numeric_options(args)
    _check_machine(getattr(args, "machine", None))
    values: dict[str, Any] = {}
    for s in PLAN_SETTINGS:
        text = getattr(args, s.name)
        with blame(s.name, text):
            values[s.name] = _PARSERS[s.kind](s, text) if text is not None else None
    try:
        return PlanSettings(**values).checked()
    except PlannerError as exc:  # a value the option's parser let through: named by its option, as typed
        failed = SETTING.get(exc.field or "")
        if failed is None or failed.flag is None or str(exc).startswith(failed.flag):
            raise
        text = getattr(args, failed.name)
        typed = getattr(text, "text", text)
        raise PlannerError(f"{failed.flag} {typed}: {exc}", field=failed.name, value=text) from None


_PARSERS = {
    "number": lambda s, x: float(x) / s.per_si,  # typed -> SI (a plain float, not the Number)
    "choice": lambda s, x: x,
    "robot": lambda s, x: None if x == "none" else x,
    "pose": _pose,
    "output": _output,
    "passes": lambda s, x: _passes(s, x),
}


def _check_machine(name: str | None) -> None:
    """``--machine NAME`` names a known machine preset (checked before the file is read)."""
    if name is None:
        return
    from planner.io.machines import machine_kinematics

    try:
        machine_kinematics(name)
    except (ValueError, TypeError):
        raise PlannerError(f"--machine {name}: unknown machine (known: haas-umc-750)") from None


def _passes(s: Setting, text: str):
    if text == "all":
        return None
    if text == "longest":
        return "longest"
    try:
        passes = tuple(int(x) for x in text.split(","))
    except ValueError:
        raise PlannerError(f"{s.flag} {text}: must be pass numbers K[,K...], 'longest' or 'all'") from None
    if any(k < 0 for k in passes):
        raise PlannerError(f"{s.flag} {text}: pass numbers start at 0")
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
    """The options of ``planner plan`` (the PlanSettings fields with a flag, in the units people type; reader
    options; with ``outputs`` -o/--plot/--progress) on a parser: ``planner run`` takes the same ones."""
    p.add_argument("input", help="toolpath: APT/CL data, CSV, JSON or 5-axis G-code")
    for s in PLAN_SETTINGS:
        assert s.flag is not None
        metavar = None if s.kind == "choice" else s.flag[2:].upper().replace("-", "_")
        p.add_argument(s.flag, dest=s.name, metavar=metavar, **_ARGUMENT[s.kind](s))
    _reader_and_output_options(p, outputs)


def _number_argument(s: Setting) -> dict:
    unit = f" {s.typed_unit}" if s.typed_unit else ""
    default = s.default * s.per_si
    return {"type": Number, "default": default,
            "help": f"{s.doc},{unit} in {s.range_text(s.per_si)} (default {default:g})"}


_ARGUMENT = {
    "number": _number_argument,
    "choice": lambda s: {"choices": list(s.choices), "default": s.default, "help": f"{s.doc} (default {s.default})"},
    "robot": lambda s: {"default": "none", "help": f"{s.doc} (default none)"},
    "pose": lambda s: {"help": f"{s.doc}: {POSE_USAGE}"},
    "output": lambda s: {"help": s.doc},
    "passes": lambda s: {"help": f"{s.doc}: K[,K...], longest or all (default all)"},
}


def _reader_and_output_options(p: argparse.ArgumentParser, outputs: bool) -> None:
    p.add_argument("--units", choices=["mm", "m", "inch"], help="units of a CSV/JSON file (default mm)")
    p.add_argument("--machine", help="machine kinematics for 5-axis G-code (e.g. haas-umc-750)")
    p.add_argument("--max-program-bytes", type=_program_bytes, default=MAX_PROGRAM_BYTES, metavar="N",
                   help="largest URScript program a controller takes, bytes (default "
                        f"{MAX_PROGRAM_BYTES}; UR documents none; 100000 for a CB-Series controller; 0: no limit): a "
                        "larger .script is refused; planner run --mode program sends pieces of at most this size")
    if outputs:
        p.add_argument("--progress", action="store_true", help="show progress bars even when not on a terminal")
        p.add_argument("-o", "--output", help="write the job: .csv / .json trajectory, .script URScript program "
                       "(movep along the passes within --tolerance, movel between), .job saved plan")
        p.add_argument("--plot", help="write a picture (.png, .svg, .pdf): paths and tool axes, frames, speed, "
                       "joints, fit")


def _program_bytes(text: str) -> int | None:
    """``--max-program-bytes``' value: a whole number of bytes, 0 (no limit: None) or at least 4096."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number of bytes, got {text!r}") from None
    if n == 0:
        return None
    if not 4096 <= n <= 10**9:
        raise argparse.ArgumentTypeError(f"must be 0 (no limit) or within 4096..1000000000 bytes, got {text!r}")
    return n


class Parser(argparse.ArgumentParser):
    """argparse with one line on stderr for a usage error (``planner plan: error: argument --feed: ...``, exit 2),
    not the usage block; ``--help`` is unchanged. Subcommand parsers (``plan``, ``run``, ...) inherit it."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")
