"""Reader of APT / CL data as CAM post-processors write it (NX CLSF, SOLIDWORKS CAM, Pro/CLfile, ...).

Records and how they are read
-----------------------------
``GOTO/x,y,z[,i,j,k]``
    A point; with six values also the tool axis (unit vector from the tip towards the spindle).
    The axis is modal: a three-value GOTO inherits the last one (``Toolpath.axis_given`` tells which
    points gave it). ``GOTO / x, y, z`` with spaces and compact numbers (``6.``, ``.9625``) are read.
``RAPID`` or ``RAPID/``
    The next motion only is a rapid (APT semantics: the last FEDRAT resumes afterwards).
``FEDRAT/f``, ``FEDRAT/f,MMPM|IPM|MMPR|IPR``, ``FEDRAT/MMPM,f``
    Feed, value first or unit first; without a unit word it is file units per minute. Per-revolution
    feeds use the last SPINDL speed. Feeds are modal and hold per span (``Toolpath.feeds``).
``UNITS/MM|INCH`` or ``UNIT/MM``
    Length unit of what follows (before any: the ``units`` option, default mm).
``MSYS/x0,y0,z0,xi,xj,xk,yi,yj,yk``
    NX: the following CL data are in the MCS whose origin and X, Y axes are given in the absolute
    frame. The reader maps points and axes to the absolute (part) frame: ``p = O + [X Y Z] p_mcs``.
``CSYS/r11,r12,r13,t1,r21,...,t3``
    A 3x4 matrix ``[R | t]`` (row by row) placing a local work-plane frame in the part frame. After
    ``TRNTYP/WORLD`` (SOLIDWORKS CAM) the CL data are already in the part frame: the matrix is kept as
    an event, is not applied, and only resets the modal tool axis to its local z axis ``R[:, 2]``
    (the data bear this out: the file's six-value GOTOs and CIRCLE axes are in world axes and equal
    that column). Without TRNTYP/WORLD the matrix is applied: ``p = R p_local + t``.
    At every MSYS/CSYS the modal tool axis resets to the local +Z (APT's default tool axis).
``CIRCLE/xc,yc,zc,i,j,k[,r,...]``
    The following motion is an arc about the axis (right-hand rule) ending at the next GOTO; kept
    as an :class:`~planner.io.toolpath.Arc` (or linearised when ``arc_tolerance`` is given).
``CYCLE/type,keyword,value,...`` ... ``CYCLE/OFF``
    A canned cycle (types DRILL, DEEP, DEEP2, BRKCHP, TAP, BORE, REAM, qualified by DEEP, BRKCHP, DWELL,
    DRAG): each GOTO that follows is a hole, expanded into its moves along the hole's tool axis by
    :func:`planner.io.cycles.hole_moves`. ``RAPTO r`` clearance above the hole point (default 0),
    ``FEDTO d`` depth below it (NX writes it as a negative offset, other systems as a positive depth:
    both mean ``|d|`` into the part), ``RTRCTO h`` retract level (``AUTO``: back to the level the tool
    came from; default the RAPTO level), ``STEP s`` (or ``INCR``) peck depth, ``1STPECK s1`` and
    ``SUBPECK s2`` (SOLIDWORKS CAM) the first peck's depth and that of each later one, ``DWELL t`` seconds
    at the bottom (a ``dwell`` event after the bottom point), ``MMPM|IPM|MMPR|IPR|MMPS|IPS f`` the cycle's
    feed (default the modal FEDRAT, which resumes after CYCLE/OFF). Lengths are in file units; pecks are
    measured from the RAPTO level. DEEP/DEEP2 retract fully between pecks, BRKCHP backs off by
    ``peck_clearance``; TAP, BORE and REAM feed out, DRILL and BORE,DRAG rapid out. BORE with BACK,
    MANUAL or NODRAG, an unknown type or keyword, and a cycle without FEDTO are refused naming the line,
    the word and the words the reader knows. ``CYCLE/ON`` resumes the last cycle. ``CYCLE/INIT`` (and
    ``CYCLE/CLEAR``), which SOLIDWORKS CAM writes before each cycle, sets up: it ends a cycle in effect
    and is kept as an event.
``NURBS/`` with ``KNOT/k1,...`` and ``CNTRL/x,y,z[,i,j,k][,w]`` records (NX)
    A NURBS move from the current point (its first control point, weight 1) through the CNTRL points
    (optional tool axes and weights); the KNOT values are the interior knots and the end value (the
    start value 0 and the clamped end multiplicities are implied), so the degree is the number of
    control points minus the number of knot values. Kept as a :class:`~planner.io.toolpath.Nurbs`
    event ending at a point at the last control point, sampled within the linearisation tolerance by
    :func:`~planner.io.toolpath.linearize_arcs`.
``FROM/x,y,z`` (start point, read as a rapid point), ``GODLTA/dx,dy,dz`` or ``GODLTA/d`` (along
the tool axis)
    Points relative to the current one.
Events (kept, see :data:`~planner.io.toolpath.EVENT_KINDS`)
    ``TOOL PATH/`` (operation), ``END-OF-PATH``, ``LOAD/TOOL``, ``LOADTL``, ``SELECT/TOOL``,
    ``TLDATA``, ``CUTTER``, ``SPINDL``, ``COOLNT``, ``CUTCOM``, ``INSERT``, ``PPRINT``, ``PARTNO``,
    ``MACHIN``, ``MULTAX``, ``TRNTYP``, ``CYCLE`` (its holes expanded), ``GOHOME``, ``CSI_SET_*`` and other ``CSI_*``
    vendor records, ``STOP``, ``OPSTOP``, ``FINI`` (reading stops there); ``DELAY/t`` or ``DWELL/t`` (seconds),
    ``DELAY/n,REV`` (spindle revolutions at the last SPINDL speed): a ``dwell`` event, the tool waits in place
    (a bare ``DELAY`` is an operator pause: a ``machine`` event).
Ignored by design
    ``PAINT/`` (display only), ``$$`` comments (to the end of the line; a comment ending in ``$``
    swallows the numeric continuation lines after it, as Pro/CLfile writes commented-out records),
    blank lines, a UTF-8 BOM, an NX "Information listing" header and the "Tool Path Listing has N
    lines." trailer.
Continuation
    A record whose code ends with a single ``$`` continues on the next line.
Anything else
    Skipped with an :class:`~planner.io.errors.InputFileWarning` naming the line (the first few of
    each kind, then a count).

Every malformed value raises :class:`~planner.io.errors.InputFileError` naming file, line and field.
The reader streams the file line by line; memory grows with the number of points only.
"""

from __future__ import annotations

import math
from typing import NoReturn

import numpy as np

from planner.io import options as opts
from planner.io._collect import (
    AXIS_TOLERANCE,
    PathCollector,
    check_arcs,
    open_lines,
    parse_number,
    source_name,
    unit_scale,
)
from planner.io.cycles import DEFAULT_PECK_CLEARANCE, DrillCycle, hole_moves
from planner.io.errors import InputFileError, WarningLimiter
from planner.io.toolpath import Event, Toolpath, linearize_arcs

_FEED_UNITS = {  # feed word -> (length unit, per: "min", "s" or "rev")
    "MMPM": ("mm", "min"),
    "IPM": ("inch", "min"),
    "MMPS": ("mm", "s"),
    "IPS": ("inch", "s"),
    "MMPR": ("mm", "rev"),
    "IPR": ("inch", "rev"),
}
_LENGTH = {"mm": 1e-3, "inch": 0.0254}
_UNIT_WORDS = {"MM": "mm", "INCH": "inch", "INCHES": "inch", "IN": "inch", "CM": "cm", "M": "m"}
_MACHINE_WORDS = frozenset(
    {"STOP", "OPSTOP", "OPSKIP", "CLRSRF", "AUTOPS", "CLAMP", "SEQNO", "END", "ORIGIN", "ROTABL",
     "RETRCT", "PREFUN", "AUXFUN", "PITCH", "HEAD", "MODE", "SELCTL", "TOOLNO", "OPERATION"}
)  # fmt: skip
_NUMERIC_START = frozenset("0123456789+-.")
#: CYCLE types whose holes the reader expands (DEEP2: a second deep-drilling form, read like DEEP).
_CYCLE_KINDS = frozenset({"DRILL", "DEEP", "DEEP2", "BRKCHP", "TAP", "BORE", "REAM"})
#: Words that qualify a CYCLE type (BACK, MANUAL and NODRAG are refused by name).
_CYCLE_MODIFIERS = frozenset({"DEEP", "DEEP2", "BRKCHP", "DRAG", "NODRAG", "BACK", "MANUAL"})
#: CYCLE keywords that take values: levels, peck depths (STEP/INCR each peck, SOLIDWORKS CAM's 1STPECK the
#: first and SUBPECK each later one), DWELL.
_CYCLE_VALUE_WORDS = ("FEDTO", "RAPTO", "RTRCTO", "STEP", "INCR", "1STPECK", "SUBPECK", "DWELL")
#: Records of the form CYCLE/word that set no cycle: OFF ends one, ON resumes the last one, INIT (SOLIDWORKS CAM,
#: before each cycle) and CLEAR set up (a cycle in effect ends).
_CYCLE_CONTROLS = ("OFF", "ON", "INIT", "CLEAR")
#: Every word a CYCLE record may hold after its type.
_CYCLE_WORDS = frozenset(_CYCLE_VALUE_WORDS) | _CYCLE_MODIFIERS | frozenset(_FEED_UNITS) | {"AUTO"}
#: A pending CIRCLE record: (line, centre, axis, radius), metres, CL frame.
_Circle = tuple[int, tuple[float, float, float], tuple[float, float, float], float]


def _cycle_value(token: str) -> bool:
    """Whether a CYCLE field is a value (a number, ``6.``, ``-1.5E-3``, ``1.5D+02``), not a word (``1STPECK``)."""
    t = token.strip()
    if not t or t[0] not in _NUMERIC_START:
        return False
    try:
        float(t.replace("D", "E").replace("d", "e"))
    except ValueError:
        return False
    return True


class _Reader:
    """State of one APT read; :meth:`run` is the streaming loop."""

    def __init__(self, source: str, units: str, frames: str, axis_tolerance: float):
        opts.choice(frames, "frames", ("auto", "none"))
        self.source = source
        self.units, self.scale = unit_scale(units)
        self.default_units = self.units
        self.frames = frames
        self.axis_tolerance = axis_tolerance
        self.out = PathCollector(source)
        self.warn = WarningLimiter(source)
        self.rapid_next = False
        self.circle: _Circle | None = None  # pending CIRCLE: (line, centre, axis, radius) in metres, CL frame
        self.world = False  # TRNTYP/WORLD in effect
        self.spindle_rps = math.nan  # rev/s, for per-revolution feeds
        self.pieces: list[tuple[int, str]] | None = None  # physical lines of a continued record: [(line, text)]
        self.finished = False
        self.feed = math.nan  # modal FEDRAT, m/s (restored after a cycle)
        self.drill: DrillCycle | None = None  # the canned cycle in effect (its GOTOs are holes)
        self.last_drill: DrillCycle | None = None  # for CYCLE/ON
        self.peck_clearance = DEFAULT_PECK_CLEARANCE
        self.pending_nurbs: dict | None = None  # NURBS/ being read: line, knots, rows (+ line of each)
        self.handlers = {
            "GOTO": self.goto,
            "RAPID": self.rapid,
            "FEDRAT": self.fedrat,
            "UNITS": self.units_record,
            "UNIT": self.units_record,
            "MULTAX": self.simple("multax"),
            "MSYS": self.msys,
            "CSYS": self.csys,
            "TRNTYP": self.trntyp,
            "CIRCLE": self.circle_record,
            "PAINT": None,
            "TLDATA": self.simple("tool_data"),
            "CUTTER": self.simple("tool_data"),
            "LOAD": self.tool("tool_change"),
            "LOADTL": self.tool("tool_change"),
            "SELECT": self.tool("tool_select"),
            "SPINDL": self.spindl,
            "DELAY": self.delay,
            "DWELL": self.delay,
            "COOLNT": self.simple("coolant"),
            "CUTCOM": self.simple("cutcom"),
            "INSERT": self.simple("insert", keep_body=True),
            "PPRINT": self.simple("insert", keep_body=True),
            "PARTNO": self.simple("partno", keep_body=True),
            "MACHIN": self.simple("machine"),
            "TOOL PATH": self.simple("operation"),
            "END-OF-PATH": self.simple("operation_end"),
            "CYCLE": self.cycle,
            "GOHOME": self.simple("home"),
            "FROM": self.from_record,
            "GODLTA": self.godlta,
            "FINI": self.fini,
            "NURBS": self.nurbs,
            "KNOT": self.knot,
            "CNTRL": self.cntrl,
        }

    # ------------------------------------------------------------------ helpers
    def fail(self, line: int, field: str, problem: str, field_no: int | None = None) -> NoReturn:
        """Raise InputFileError; for a continued record, name the physical line holding the field."""
        if self.pieces and field_no is not None:
            line = self._line_of_field(field_no, line)
        raise InputFileError(self.source, line, field, problem)

    def _line_of_field(self, field_no: int, default: int) -> int:
        pieces = self.pieces or []
        if not pieces:
            return default
        text = "".join(p for _, p in pieces)
        pos = text.find("/")
        if pos < 0:
            return default
        for _ in range(field_no - 1):
            pos = text.find(",", pos + 1)
            if pos < 0:
                return default
        acc = 0
        for ln, piece in pieces:
            acc += len(piece)
            if pos + 1 < acc or (pos + 1 == acc and ln == pieces[-1][0]):
                return ln
        return pieces[-1][0]

    def numbers(self, line: int, major: str, body: str, counts=None, first: int = 1) -> list[float]:
        """All comma-separated fields of ``body`` as numbers (fields numbered from ``first``)."""
        parts = body.split(",")
        if counts is not None and len(parts) not in counts:
            want = " or ".join(str(c) for c in sorted(counts))
            self.fail(line, f"{major} record", f"has {len(parts)} values, expected {want}")
        vals = []
        for k, p in enumerate(parts, first):
            field = f"field {k} of {major}"
            try:
                vals.append(parse_number(p, self.source, line, field))
            except InputFileError as exc:
                self.fail(line, field, exc.problem, k)
        return vals

    def add_point(self, line: int, x: float, y: float, z: float, rapid: bool = False) -> int:
        out = self.out
        k = out.count
        out.xyz.extend((x, y, z))
        out.lines.append(line)
        if self.rapid_next or rapid:
            out.rapid_idx.append(k)
            self.rapid_next = False
        if self.circle is not None:
            self.end_circle(k, self.circle)
        return k

    def end_circle(self, k: int, circle: _Circle) -> None:
        line, centre, axis, radius = circle
        self.circle = None
        if k == 0:
            self.fail(line, "CIRCLE record", "has no start point (no motion before it)")
        self.out.add_arc(line, k, centre, axis, radius)

    def last_point(self, line: int, major: str) -> tuple[float, float, float]:
        n = self.out.count
        if n == 0:
            self.fail(line, f"{major} record", "is relative to the current position, but no point precedes it")
        x = self.out.xyz
        return x[3 * n - 3], x[3 * n - 2], x[3 * n - 1]

    # ------------------------------------------------------------------ records
    def goto(self, line: int, major: str, body: str) -> None:
        vals = self.numbers(line, "GOTO", body)
        if len(vals) not in (3, 6):
            self.fail(line, "GOTO record", f"has {len(vals)} values, expected 3 (x,y,z) or 6 (x,y,z,i,j,k)")
        if self.drill is not None:
            self.hole(line, vals)
            return
        s = self.scale
        k = self.add_point(line, vals[0] * s, vals[1] * s, vals[2] * s)
        if len(vals) == 6:
            self.out.set_axis(k, vals[3], vals[4], vals[5], True)

    @property
    def axis(self) -> tuple[float, float, float]:
        """The modal tool axis in the CL frame (the last one set)."""
        v = self.out.axis_val
        return (v[-3], v[-2], v[-1]) if len(v) else (0.0, 0.0, 1.0)

    def rapid(self, line: int, major: str, body: str) -> None:
        if body.strip():
            self.warn.warn("RAPID arguments", line, f"RAPID/{body.strip()}: arguments ignored, next move is rapid")
        self.rapid_next = True

    def fedrat(self, line: int, major: str, body: str) -> None:
        parts = [p.strip() for p in body.split(",")]
        value, unit, per = None, None, None
        for k, p in enumerate(parts, 1):
            word = p.upper()
            if word in _FEED_UNITS:
                unit, per = _FEED_UNITS[word]
            elif word in ("INVERS", "INVERSE"):
                per = "inverse"
            elif p and (p[0] in _NUMERIC_START):
                if value is not None:
                    self.fail(line, f"field {k} of FEDRAT", f"second feed value {p!r}", k)
                value = self.numbers(line, "FEDRAT", p, first=k)[0]
            else:
                self.fail(line, f"field {k} of FEDRAT", f"{p!r} is neither a number nor a feed unit "
                          f"({', '.join(_FEED_UNITS)})", k)  # fmt: skip
        if value is None:
            self.fail(line, "FEDRAT record", "has no feed value")
        if not value > 0.0:
            self.fail(line, "FEDRAT record", f"feed rate must be positive, got {value:g}")
        length = _LENGTH[unit] if unit else self.scale
        if per == "min" or per is None:
            feed = value * length / 60.0
        elif per == "s":
            feed = value * length
        elif per == "rev":
            feed = value * length * self.spindle_rps
            if not math.isfinite(feed):
                self.warn.warn("FEDRAT per revolution", line, "feed per revolution before any spindle speed: "
                               "feed unknown")  # fmt: skip
        else:
            feed = math.nan
            self.warn.warn("FEDRAT/INVERS", line, "inverse-time feed is not converted: feed unknown")
        self.feed = feed
        self.out.set_feed(self.out.count, feed)

    def units_record(self, line: int, major: str, body: str) -> None:
        word = body.split(",")[0].strip().upper()
        if word not in _UNIT_WORDS:
            self.fail(line, f"field 1 of {major}", f"unknown unit {word!r} (expected MM or INCH)", 1)
        units = _UNIT_WORDS[word]
        if units != self.units and self.out.cutting():
            self.fail(line, major, f"switches the units from {self.units} to {units} in the middle of a pass (a "
                      f"{unit_scale(units)[1] / self.scale:g}x jump in scale): state the units before the first "
                      f"motion or between passes", 1)  # fmt: skip
        self.units, self.scale = unit_scale(units)
        self.out.units_seen.append(self.units)
        self.out.event("units", line, self.units, math.nan, f"{major}/{body.strip()}")

    def msys(self, line: int, major: str, body: str) -> None:
        v = self.numbers(line, "MSYS", body, counts=(9,))
        x, y = np.array(v[3:6]), np.array(v[6:9])
        self.check_axes(line, "MSYS", x, y, 4, 7)
        x = x / np.linalg.norm(x)
        y = y - (y @ x) * x
        y /= np.linalg.norm(y)
        rot = np.column_stack([x, y, np.cross(x, y)])
        self.out.event("frame", line, "MSYS", math.nan, f"MSYS/{body.strip()}")
        self.new_frame(rot, np.array(v[:3]) * self.scale, apply=True)

    def check_axes(self, line: int, major: str, x, y, fx: int, fy: int) -> None:
        tol = self.axis_tolerance
        for vec, f in ((x, fx), (y, fy)):
            if abs(np.linalg.norm(vec) - 1.0) > tol:
                self.fail(line, f"fields {f}-{f + 2} of {major}", f"axis {tuple(vec)} is not a unit vector", f)
        if abs(x @ y) > tol:
            self.fail(line, f"fields {fx}-{fy + 2} of {major}", "X and Y axes are not perpendicular", fx)

    def csys(self, line: int, major: str, body: str) -> None:
        v = self.numbers(line, "CSYS", body, counts=(12,))
        m = np.array(v).reshape(3, 4)
        rot, org = m[:, :3], m[:, 3]
        err = np.abs(rot.T @ rot - np.eye(3)).max()
        if err > self.axis_tolerance or np.linalg.det(rot) <= 0.0:
            self.fail(line, "CSYS matrix", "the 3x3 part is not a rotation (orthonormal, determinant +1)")
        u, _, vt = np.linalg.svd(rot)
        rot = u @ vt
        self.out.event("frame", line, "CSYS", math.nan, f"CSYS/{body.strip()}")
        self.new_frame(rot, org * self.scale, apply=not self.world)

    def new_frame(self, rot: np.ndarray, org: np.ndarray, apply: bool) -> None:
        """Start a frame at the next point; the modal tool axis resets to the frame's local +Z."""
        k = self.out.count
        if not apply:
            # TRNTYP/WORLD: the data are in part axes already; the local z axis, in part axes, is the
            # modal tool axis.
            if self.frames == "auto":
                self.out.set_frame(k, np.eye(3), np.zeros(3))
            axis = (float(rot[0, 2]), float(rot[1, 2]), float(rot[2, 2]))
        else:
            if self.frames == "auto":
                self.out.set_frame(k, rot, org)
            axis = (0.0, 0.0, 1.0)  # local +Z; the frame maps it at the end
        self.out.set_axis(k, *axis, False)

    def trntyp(self, line: int, major: str, body: str) -> None:
        word = body.split(",")[0].strip().upper()
        self.world = word == "WORLD"
        self.out.event("frame", line, "TRNTYP/" + word, math.nan, f"TRNTYP/{body.strip()}")

    def circle_record(self, line: int, major: str, body: str) -> None:
        if self.drill is not None:
            self.fail(line, "CIRCLE record", f"circular motion inside {self.drill.name} (line {self.drill.line}); "
                      "end the cycle with CYCLE/OFF first")  # fmt: skip
        v = self.numbers(line, "CIRCLE", body)
        if len(v) < 6:
            self.fail(line, "CIRCLE record", f"has {len(v)} values, expected at least 6 (xc,yc,zc,i,j,k)")
        if self.circle is not None:
            self.fail(self.circle[0], "CIRCLE record", f"has no end point (the next motion record is the "
                      f"CIRCLE at line {line})")  # fmt: skip
        norm = math.hypot(v[3], v[4], v[5])
        if abs(norm - 1.0) > self.axis_tolerance:
            self.fail(line, "fields 4-6 of CIRCLE", f"axis {tuple(v[3:6])} is not a unit vector "
                      f"(length {norm:.9g})", 4)  # fmt: skip
        radius = v[6] * self.scale if len(v) > 6 else math.nan
        if len(v) > 6 and not v[6] > 0.0:
            self.fail(line, "field 7 of CIRCLE", f"radius must be positive, got {v[6]:g}", 7)
        s = self.scale
        self.circle = (line, (v[0] * s, v[1] * s, v[2] * s), (v[3] / norm, v[4] / norm, v[5] / norm), radius)

    def simple(self, kind: str, keep_body: bool = False):
        def handler(line: int, major: str, body: str) -> None:
            b = body.strip()
            if keep_body:
                name = b
            else:
                name = b.split(",")[0].strip() if b else major
            text = f"{major}/{b}" if b else major
            self.out.event(kind, line, name, math.nan, text)

        return handler

    def tool(self, kind: str):
        def handler(line: int, major: str, body: str) -> None:
            number = math.nan
            for k, p in enumerate(body.split(","), 1):
                p = p.strip()
                if p and p[0] in _NUMERIC_START:
                    number = self.numbers(line, major, p, first=k)[0]
                    break
            self.out.event(kind, line, body.strip(), number, f"{major}/{body.strip()}")

        return handler

    def spindl(self, line: int, major: str, body: str) -> None:
        parts = [p.strip() for p in body.split(",")]
        words = [p.upper() for p in parts if p and p[0] not in _NUMERIC_START]
        nums = [(k, p) for k, p in enumerate(parts, 1) if p and p[0] in _NUMERIC_START]
        speed = math.nan
        if "OFF" in words:
            speed = 0.0
        elif nums and "SFM" not in words and "SMM" not in words:
            k, p = nums[0]
            rpm = self.numbers(line, major, p, first=k)[0]
            speed = rpm * 2.0 * math.pi / 60.0
            self.spindle_rps = rpm / 60.0
        self.out.event("spindle", line, ",".join(words), speed, f"{major}/{body.strip()}")

    def delay(self, line: int, major: str, body: str) -> None:
        """DELAY/t or DWELL/t (seconds), DELAY/n,REV (spindle revolutions): the tool waits in place (a ``dwell``
        event); a DELAY without a value is kept as a ``machine`` event (an operator pause, no time)."""
        b = body.strip()
        text = f"{major}/{b}" if b else major
        if not b:
            self.out.event("machine", line, major, math.nan, text)
            return
        parts = [p.strip() for p in b.split(",")]
        if len(parts) > 2 or (len(parts) == 2 and parts[1].upper() not in ("REV", "REVS", "SEC", "SECS")):
            self.fail(line, f"{major} record", f"expected {major}/seconds or {major}/revolutions,REV, got {text!r}")
        value = self.numbers(line, major, parts[0])[0]
        if not (math.isfinite(value) and value >= 0.0):
            self.fail(line, f"field 1 of {major}", f"the dwell must be a time >= 0, got {parts[0]!r}", 1)
        seconds = value
        if len(parts) == 2 and parts[1].upper().startswith("REV"):
            if not (self.spindle_rps > 0.0):
                self.fail(line, f"field 2 of {major}", "a dwell in spindle revolutions needs a spindle speed "
                          "(SPINDL/rpm) before it", 2)
            seconds = value / self.spindle_rps
        self.out.event("dwell", line, major, seconds, text)

    def cycle(self, line: int, major: str, body: str) -> None:
        """CYCLE/...: a canned cycle whose GOTOs are holes (see :meth:`hole`); CYCLE/OFF ends it."""
        parts = [p.strip() for p in body.split(",")]
        word = parts[0].upper() if parts else ""
        self.out.event("cycle", line, word, math.nan, f"CYCLE/{body.strip()}")
        if word == "OFF" or (word in ("INIT", "CLEAR") and len(parts) == 1):
            if self.drill is not None:
                self.drill = None
                self.out.set_feed(self.out.count, self.feed)  # the modal FEDRAT resumes
            return
        if word in ("ON", "INIT", "CLEAR") and len(parts) > 1:
            self.fail(line, "CYCLE record", f"CYCLE/{word} takes no values, got CYCLE/{body.strip()}")
        if word == "ON":
            if self.last_drill is None:
                self.fail(line, "CYCLE/ON", "no earlier CYCLE to turn back on")
            self.drill = self.last_drill
            return
        self.drill = self.last_drill = self.parse_cycle(line, parts)

    def parse_cycle(self, line: int, parts: list[str]) -> DrillCycle:
        """The DrillCycle of a CYCLE record's fields (keywords with their values, see the module notes)."""
        kind = parts[0].upper()
        name = "CYCLE/" + ",".join([kind] + [p.upper() for p in parts[1:] if p.upper() in _CYCLE_MODIFIERS])
        if kind not in _CYCLE_KINDS:
            self.fail(line, "field 1 of CYCLE", f"cycle {kind!r} ({name}) is not one the reader knows: it reads the "
                      f"cycles {', '.join(sorted(_CYCLE_KINDS))} and CYCLE/{', CYCLE/'.join(_CYCLE_CONTROLS)} (the "
                      "holes cannot be planned as a path)", 1)  # fmt: skip
        mods: set[str] = {kind}
        values: dict[str, float] = {}
        pecks: dict[str, float] = {}
        retract_auto = False
        feed_unit = None
        known = (f"the keywords it knows are {', '.join(_CYCLE_VALUE_WORDS)}, {', '.join(sorted(_CYCLE_MODIFIERS))}, "
                 f"the feed units {', '.join(_FEED_UNITS)} and RTRCTO,AUTO")
        k = 1
        while k < len(parts):
            word = parts[k].upper()
            if not word:
                self.fail(line, f"field {k + 1} of CYCLE", f"is empty ({name})", k + 1)
            if _cycle_value(parts[k]):
                self.fail(line, f"field {k + 1} of CYCLE", f"value {parts[k]!r} follows no keyword ({name}: "
                          "write FEDTO, RAPTO, RTRCTO, STEP, DWELL and the feed unit before their values)", k + 1)
            nums = []
            j = k + 1
            while j < len(parts) and _cycle_value(parts[j]):
                nums.append(self.numbers(line, "CYCLE", parts[j], first=j + 1)[0])
                j += 1
            if (not nums and j < len(parts) and word in _CYCLE_VALUE_WORDS + tuple(_FEED_UNITS) and word != "DWELL"
                    and parts[j].upper() not in _CYCLE_WORDS):
                self.fail(line, f"field {j + 1} of CYCLE", f"{parts[j]!r} is not a number ({word} needs a value; "
                          f"{name})", j + 1)
            if word in ("FEDTO", "RAPTO", "RTRCTO"):
                if word == "RTRCTO" and not nums and j < len(parts) and parts[j].upper() == "AUTO":
                    retract_auto = True
                    j += 1
                elif len(nums) != 1:
                    self.fail(line, f"field {k + 1} of CYCLE", f"{word} needs one value ({name})", k + 1)
                else:
                    values[word] = nums[0] * self.scale
            elif word in ("STEP", "INCR", "1STPECK", "SUBPECK"):
                if len(nums) != 1 and word in ("1STPECK", "SUBPECK"):
                    self.fail(line, f"field {k + 1} of CYCLE", f"{word} needs one peck depth ({name})", k + 1)
                if not nums:
                    self.fail(line, f"field {k + 1} of CYCLE", f"{word} needs a peck depth ({name})", k + 1)
                pecks["next" if word == "SUBPECK" else "first"] = nums[0] * self.scale
            elif word == "DWELL":
                if len(nums) > 1:
                    self.fail(line, f"field {k + 1} of CYCLE", f"DWELL takes one value in seconds ({name})", k + 1)
                values["DWELL"] = nums[0] if nums else 0.0
                mods.add("DWELL")
            elif word in _FEED_UNITS:
                if len(nums) != 1:
                    self.fail(line, f"field {k + 1} of CYCLE", f"{word} needs one feed value ({name})", k + 1)
                feed_unit, values["FEED"] = word, nums[0]
            elif word in _CYCLE_MODIFIERS:
                if nums:
                    self.fail(line, f"field {k + 1} of CYCLE", f"{word} takes no value ({name})", k + 1)
                mods.add(word)
            else:
                self.fail(line, f"field {k + 1} of CYCLE", f"{parts[k]!r} is neither a number nor a CYCLE keyword the "
                          f"reader knows ({name}; {known}): the holes cannot be planned without it", k + 1)  # fmt: skip
            k = j
        refused = mods & {"BACK", "MANUAL", "NODRAG"}
        if refused:
            what = {"BACK": "back boring", "MANUAL": "manual retract", "NODRAG": "spindle orient and shift"}
            w = sorted(refused)[0]
            self.fail(line, "CYCLE record", f"{name}: {what[w]} ({w}) moves the tool in ways the file does not "
                      "give; the cycle is not read")  # fmt: skip
        if "FEDTO" not in values:
            self.fail(line, "CYCLE record", f"{name} has no FEDTO depth: the holes cannot be expanded")
        feed = self.feed
        if feed_unit is not None:
            unit, per = _FEED_UNITS[feed_unit]
            f = values["FEED"] * _LENGTH[unit]
            if not values["FEED"] > 0.0:
                self.fail(line, "CYCLE record", f"{name}: feed must be positive, got {values['FEED']:g}")
            feed = f / 60.0 if per == "min" else f if per == "s" else f * self.spindle_rps
        peck_mode = "full" if mods & {"DEEP", "DEEP2"} else "chip" if "BRKCHP" in mods else ""
        if peck_mode and not pecks:
            self.warn.warn("CYCLE without STEP", line, f"{name} gives no STEP: each hole is drilled in one feed")
        first = pecks.get("first", pecks.get("next", 0.0))
        clearance = values.get("RAPTO", 0.0)
        retract = None if retract_auto else values.get("RTRCTO", clearance)
        cyc = DrillCycle(
            name=name, line=line, clearance=clearance, bottom=-abs(values["FEDTO"]), retract=retract, feed=feed,
            peck=first, peck_next=pecks.get("next", 0.0), peck_mode=peck_mode, peck_clearance=self.peck_clearance,
            dwell=values.get("DWELL", 0.0), feed_out=kind in ("TAP", "BORE", "REAM") and "DRAG" not in mods,
        )  # fmt: skip
        problem = cyc.problem()
        if problem:
            self.fail(line, "CYCLE record", f"{name}: {problem}")
        return cyc

    def hole(self, line: int, vals: list[float]) -> None:
        """A GOTO under a CYCLE: the hole at that point (and axis), expanded into its moves."""
        cyc = self.drill
        assert cyc is not None
        s = self.scale
        p = (vals[0] * s, vals[1] * s, vals[2] * s)
        given = len(vals) == 6
        a = tuple(vals[3:6]) if given else self.axis
        norm = math.hypot(*a)  # a component of 1e308 must not overflow
        if given and abs(norm - 1.0) > self.axis_tolerance:
            self.fail(line, "fields 4-6 of GOTO", f"tool axis {a} is not a unit vector (length {norm:.9g})", 4)
        a = (a[0] / norm, a[1] / norm, a[2] / norm)
        out = self.out
        n = out.count
        current = (out.xyz[3 * n - 3], out.xyz[3 * n - 2], out.xyz[3 * n - 1]) if n else None
        self.rapid_next = False
        moves, bottom = hole_moves(current, p, a, cyc)
        for j, (q, rapid) in enumerate(moves):
            k = out.add_point(line, q[0], q[1], q[2], rapid)
            if j == 0 and given:
                out.set_axis(k, a[0], a[1], a[2], True)
            if not rapid:
                out.set_feed(k, cyc.feed)
            if j == bottom and cyc.dwell > 0.0:
                out.event("dwell", line, cyc.name, cyc.dwell, f"DWELL {cyc.dwell:g} s at the bottom of the hole")

    def from_record(self, line: int, major: str, body: str) -> None:
        v = self.numbers(line, major, body)
        if len(v) not in (3, 6):
            self.fail(line, "FROM record", f"has {len(v)} values, expected 3 or 6")
        s = self.scale
        k = self.add_point(line, v[0] * s, v[1] * s, v[2] * s, rapid=True)
        if len(v) == 6:
            self.out.set_axis(k, v[3], v[4], v[5], True)

    def godlta(self, line: int, major: str, body: str) -> None:
        if self.drill is not None:
            self.fail(line, "GODLTA record", f"GODLTA inside {self.drill.name} (line {self.drill.line}) is not read "
                      "as a hole; end the cycle with CYCLE/OFF first")  # fmt: skip
        v = self.numbers(line, major, body, counts=(1, 3))
        x, y, z = self.last_point(line, major)
        s = self.scale
        if len(v) == 1:
            a = np.array(self.axis, dtype=float)
            d = a / np.linalg.norm(a) * v[0] * s
        else:
            d = np.array(v) * s
        self.add_point(line, x + d[0], y + d[1], z + d[2])

    def fini(self, line: int, major: str, body: str) -> None:
        self.out.event("end", line, "FINI", math.nan, "FINI")
        self.finished = True

    def nurbs(self, line: int, major: str, body: str) -> None:
        """NURBS/: a NURBS move from the current point; its KNOT/ and CNTRL/ records follow."""
        if body.strip():
            self.fail(line, "NURBS record", f"NURBS/{body.strip()}: arguments after NURBS/ are not supported "
                      "(NX writes NURBS/ alone, then KNOT/ and CNTRL/ records)")  # fmt: skip
        if self.drill is not None:
            self.fail(line, "NURBS record", f"NURBS motion inside {self.drill.name} (line {self.drill.line})")
        if self.out.count == 0:
            self.fail(line, "NURBS record", "has no start point (no motion before it)")
        self.pending_nurbs = {"line": line, "knots": [], "rows": [], "width": 0, "last": line}

    def knot(self, line: int, major: str, body: str) -> None:
        rec = self.pending_nurbs
        if rec is None:
            self.fail(line, "KNOT record", "outside a NURBS/ record")
        if rec["rows"]:
            self.fail(line, "KNOT record", f"after the CNTRL records of the NURBS at line {rec['line']}")
        rec["knots"].extend(self.numbers(line, "KNOT", body))
        rec["last"] = line

    def cntrl(self, line: int, major: str, body: str) -> None:
        rec = self.pending_nurbs
        if rec is None:
            self.fail(line, "CNTRL record", "outside a NURBS/ record")
        v = self.numbers(line, "CNTRL", body)
        if len(v) not in (3, 4, 6, 7):
            self.fail(line, "CNTRL record", f"has {len(v)} values, expected 3 (x,y,z), 4 (x,y,z,w), 6 (x,y,z,i,j,k) "
                      "or 7 (x,y,z,i,j,k,w)")  # fmt: skip
        if rec["rows"] and len(v) != rec["width"]:
            self.fail(line, "CNTRL record", f"has {len(v)} values, the earlier CNTRL records of this NURBS "
                      f"{rec['width']}")  # fmt: skip
        if len(v) in (4, 7) and not v[-1] > 0.0:
            self.fail(line, f"field {len(v)} of CNTRL", f"weight must be positive, got {v[-1]:g}", len(v))
        if len(v) in (6, 7):
            norm = math.hypot(v[3], v[4], v[5])
            if abs(norm - 1.0) > self.axis_tolerance:
                self.fail(line, "fields 4-6 of CNTRL", f"tool axis {tuple(v[3:6])} is not a unit vector "
                          f"(length {norm:.9g})", 4)  # fmt: skip
        rec["width"] = len(v)
        rec["rows"].append(v)
        rec["last"] = line

    def finish_nurbs(self) -> None:
        """The pending NURBS as a curve from the current point to its last control point.

        NX lists the knots after the start (the interior knots, then the end value; the start value 0
        and the end multiplicity are implied) and the control points after the start point, which is
        the current position: with ``C`` control points in all and ``K`` knot values, the degree is
        ``C - K``.
        """
        rec = self.pending_nurbs
        self.pending_nurbs = None
        assert rec is not None
        line = rec["line"]
        knots, rows = rec["knots"], rec["rows"]
        if not rows or not knots:
            self.fail(line, "NURBS record", f"has {len(knots)} KNOT values and {len(rows)} CNTRL points: a curve "
                      "needs both")  # fmt: skip
        width = rec["width"]
        n = self.out.count
        start = np.array(self.out.xyz[3 * n - 3 : 3 * n])
        s = self.scale
        ctrl = np.vstack([start[None], np.array([r[:3] for r in rows]) * s])
        c = ctrl.shape[0]
        degree = c - len(knots)
        end = knots[-1]
        interior = knots[:-1]
        bad = ""
        if not 1 <= degree <= 15:
            bad = f"degree {degree} (control points {c} including the start point, knot values {len(knots)})"
        elif not end > 0.0 or any(b < a for a, b in zip([0.0, *interior], [*interior, end], strict=True)):
            bad = "the knot values must increase from 0 (the implied start) to the last value"
        elif interior and (interior[0] <= 0.0 or interior[-1] >= end):
            bad = "an interior knot at the start or end value (the end multiplicities are implied)"
        else:
            run, longest = 1, 1
            for a, b in zip(interior, interior[1:], strict=False):
                run = run + 1 if a == b else 1
                longest = max(longest, run)
            if interior and longest > degree:
                bad = f"a knot repeated {longest} times (more than the degree {degree})"
        if bad:
            self.fail(line, "NURBS record", f"KNOT/CNTRL do not make a clamped B-spline: {bad}")
        full = np.array([0.0] * (degree + 1) + list(interior) + [end] * (degree + 1))
        weights = np.ones(c)
        if width in (4, 7):
            weights[1:] = [r[-1] for r in rows]
        axes = None
        if width in (6, 7):
            a = np.array([r[3:6] for r in rows], dtype=float)
            a /= np.linalg.norm(a, axis=1, keepdims=True)
            a0 = np.array(self.axis, dtype=float)
            axes = np.vstack([a0 / np.linalg.norm(a0), a])
        end_pt = ctrl[-1]
        k = self.add_point(line, float(end_pt[0]), float(end_pt[1]), float(end_pt[2]))
        if axes is not None:
            self.out.set_axis(k, float(axes[-1, 0]), float(axes[-1, 1]), float(axes[-1, 2]), True)
        self.out.add_nurbs(line, k, degree, full, ctrl, weights, axes)

    def other(self, line: int, major: str, body: str) -> None:
        b = body.strip()
        text = f"{major}/{b}" if b else major
        if major.startswith("CSI_") or major in _MACHINE_WORDS:
            self.out.event("machine", line, major, math.nan, text)
            return
        shown = text if len(text) <= 60 else text[:57] + "..."
        self.warn.warn(f"'{major}' records", line, f"unknown record {shown!r} skipped")

    # ------------------------------------------------------------------ dispatch
    def record(self, line: int, text: str) -> None:
        head, sep, body = text.partition("/")
        major = " ".join(head.split()).upper() if sep else " ".join(text.split()).upper()
        if not major:
            if text.strip():
                self.fail(line, "record", f"{text.strip()!r} has no major word before '/'")
            return
        if not sep:
            body = ""
        if self.pending_nurbs is not None and major not in ("KNOT", "CNTRL"):
            self.finish_nurbs()
        handler = self.handlers.get(major, self.other)
        if handler is not None:
            handler(line, major, body)

    def run(self, lines) -> None:
        out = self.out
        xyz_extend = out.xyz.extend
        lines_obj = out.lines
        lines_append = lines_obj.append
        aidx_append = out.axis_idx.append
        aval_extend = out.axis_val.extend
        agiven_append = out.axis_given.append
        comment_cont = False
        pending: list[tuple[int, str]] | None = None
        s = self.scale
        simple = True  # no rapid, circle, continuation or comment continuation pending
        it = enumerate(lines, 1)
        for lineno, raw in it:
            # Hot path: a single-line "GOTO/x,y,z[,i,j,k]" with nothing pending (most lines of a file).
            if simple and raw.startswith("GOTO/") and "$" not in raw and "_" not in raw:
                parts = raw[5:].split(",")
                n = len(parts)
                if n == 3:
                    try:
                        xyz = (float(parts[0]) * s, float(parts[1]) * s, float(parts[2]) * s)
                    except ValueError:
                        pass
                    else:
                        xyz_extend(xyz)
                        lines_append(lineno)
                        continue
                elif n == 6:
                    try:
                        x, y, z, i, j, k = map(float, parts)
                    except ValueError:
                        pass
                    else:
                        aidx_append(len(lines_obj))
                        xyz_extend((x * s, y * s, z * s))
                        lines_append(lineno)
                        aval_extend((i, j, k))
                        agiven_append(1)
                        continue
                # Not a clean GOTO: the general path below names the bad field.
            text = raw.rstrip("\r\n")
            if lineno == 1 and text.startswith("Information listing created by"):
                self.skip_listing_header(it, text)
                continue
            if comment_cont:
                t = text.lstrip()
                if t and t[0] in _NUMERIC_START:
                    comment_cont = text.rstrip().endswith("$")
                    continue
                comment_cont = False
            if "$" in text:
                cut = text.find("$$")
                code = text if cut < 0 else text[:cut]
                c = code.rstrip()
                if c.endswith("$"):
                    if pending is None:
                        pending = []
                    pending.append((lineno, c[:-1]))
                    simple = False
                    continue
                if cut >= 0 and not code.strip() and pending is None:
                    comment_cont = text.rstrip().endswith("$")
                    simple = not (comment_cont or self.rapid_next or self.circle is not None or self.busy)
                    continue
                text = code
            if pending is not None:
                pending.append((lineno, text))
                self.pieces = pending
                start = pending[0][0]
                joined = "".join(p for _, p in pending)
                pending = None
                self.record(start, joined.strip())
                self.pieces = None
            else:
                stripped = text.strip()
                if stripped.startswith("Tool Path Listing has "):
                    self.out.event("listing", lineno, "trailer", math.nan, stripped)
                elif stripped:
                    self.record(lineno, stripped)
            if self.finished:
                self.after_fini(it)
                break
            s = self.scale
            simple = not (comment_cont or self.rapid_next or self.circle is not None or self.busy)
        if pending is not None:
            self.fail(pending[0][0], "record", "continuation ('$') at the end of the file: record incomplete")
        if self.pending_nurbs is not None:
            self.finish_nurbs()
        if self.circle is not None:
            self.fail(self.circle[0], "CIRCLE record", "has no end point (no GOTO follows it)")

    @property
    def busy(self) -> bool:
        """A cycle or a NURBS is being read: every GOTO goes through the handlers."""
        return self.drill is not None or self.pending_nurbs is not None

    def skip_listing_header(self, it, first: str) -> None:
        """Skip an NX 'Information listing' header: its lines up to the first blank line."""
        header = [first]
        for _, raw in it:
            if not raw.strip():
                break
            header.append(raw.strip())
        self.out.events.append(Event("listing", 1, 0, "header", math.nan, " | ".join(header)))

    def after_fini(self, it) -> None:
        extra = [n for n, raw in it if raw.strip()]
        if extra:
            self.warn.warn("records after FINI", extra[0], f"{len(extra)} non-blank line(s) after FINI ignored")


def read_apt(
    src,
    *,
    units: str = "mm",
    frames: str = "auto",
    arc_tolerance: float | None = None,
    axis_tolerance: float = AXIS_TOLERANCE,
    source: str | None = None,
    peck_clearance: float = DEFAULT_PECK_CLEARANCE,
) -> Toolpath:
    """Read APT / CL data (``.apt``, ``.cls``, ``.cl``, ``.ncl``) into a :class:`Toolpath`.

    Parameters
    ----------
    src : str, os.PathLike or text stream
        The file, or an open text stream.
    units : {"mm", "inch", "m"}, default "mm"
        Length unit before the file's first UNITS record.
    frames : {"auto", "none"}, default "auto"
        "auto" applies MSYS, and CSYS unless TRNTYP/WORLD (see the module notes), so points and axes
        are in the part frame; "none" keeps the coordinates exactly as written (frames stay events).
    arc_tolerance : float or None, default None
        None keeps each CIRCLE as an :class:`~planner.io.toolpath.Arc` event between its start point
        and its end GOTO; a length in metres inserts chord points within that tolerance instead
        (see :func:`~planner.io.toolpath.linearize_arcs`, whose documented default is 1e-5 m).
    axis_tolerance : float, default 1e-3
        Largest accepted ``| |(i,j,k)| - 1 |`` of a tool axis before it is renormalised.
    source : str, optional
        Name used in messages (default: the file's base name).
    peck_clearance : float, default 0.5e-3
        Peck drilling: the distance, metres, a chip-breaking cycle backs off and a deep cycle stops above
        the last depth before feeding again (a machine parameter the program does not give).

    Returns
    -------
    Toolpath
        Points in metres in the part frame, modal tool axes, per-span feeds (m/s), rapid flags, source
        lines and events.

    Raises
    ------
    ReaderArgumentError
        A bad argument, named (before the file is opened).
    InputFileError
        A malformed record: the message names the file, the line and the field.

    Warns
    -----
    InputFileWarning
        An unknown record skipped (naming its line) or a value read under an assumption.
    """
    opts.check_src(src)
    name = source_name(src, opts.source_label(source))
    opts.choice(frames, "frames", ("auto", "none"))
    unit_scale(units)
    arc_tolerance = opts.arc_tolerance(arc_tolerance)
    axis_tolerance = opts.axis_tolerance(axis_tolerance)
    reader = _Reader(name, units, frames, axis_tolerance)
    reader.peck_clearance = opts.peck_clearance(peck_clearance)
    with open_lines(src, name) as lines:
        reader.run(lines)
    if reader.out.count == 0:
        raise InputFileError(name, None, "", "holds no motion (no GOTO or FROM record)")
    tp = reader.out.finish(reader.default_units, axis_tolerance=axis_tolerance)
    check_arcs(tp, reader.warn)
    reader.warn.flush()
    if arc_tolerance is not None:
        tp = linearize_arcs(tp, arc_tolerance)
    return tp
