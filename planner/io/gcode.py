"""Reader of 3- and 5-axis G-code (ISO 6983 / Fanuc / Haas dialect) into a toolpath.

The Sinumerik 840D dialect (``.mpf``/``.spf``, ``dialect="sinumerik"``) is translated block by block
into these words by :mod:`planner.io.sinumerik` (see there for what it reads, keeps and refuses).

What is read
------------
* Blocks: optional ``N`` number, words ``letter + number``; spaces ignored (as controls do);
  comments ``( ... )`` and ``; ...``. ``( OPER: NAME )`` comments become ``operation`` events.
* ``%`` starts and ends the program; what follows the closing ``%`` is ignored (an NX "Tool Path
  Listing has N lines." trailer is kept as a ``listing`` event). A UTF-8 BOM and an NX "Information
  listing" header (up to the first blank line) are skipped. ``O`` lines name the program.
* Modal state: motion ``G00/G01/G02/G03``, plane ``G17/G18/G19``, ``G20/G21`` (inch/mm), ``G90/G91``,
  ``G93/G94/G95`` feed modes, ``F``, ``S``, axis words ``X Y Z`` and the rotary words of the machine.
  Words left out keep their last value.
* Feeds: ``G94`` F in units per minute; ``G95`` F per revolution times the last S; ``G93`` (inverse
  time) is kept as unknown (NaN) with a warning. Rapids (``G00``) have NaN feed and ``rapid`` True.
* Arcs ``G02``/``G03`` with ``I J K`` (incremental from the start, the Fanuc/Haas default) or ``R``
  (R > 0 the short way, R < 0 the long way): the end point is a point, and the circle is kept as an
  :class:`~planner.io.toolpath.Arc` whose axis is ``+normal`` for G03 and ``-normal`` for G02 (normal
  = Z, Y, X for G17, G18, G19), or linearised when ``arc_tolerance`` is given.
* Machine moves: ``G53`` (machine coordinates) and ``G28`` (reference return) make the named linear
  axes unknown (a rotary axis named in G28 returns to 0); no point is emitted until X, Y and Z are
  known again, and the next point is flagged rapid. Both are kept as ``home`` events.
* Rotary words (e.g. ``B``, ``C``) are converted to tool axes with the machine kinematics the user
  names (:class:`~planner.io.machines.TableTableKinematics`, preset ``"haas-umc-750"``; the
  derivation and its check on the real program are in :mod:`planner.io.machines`). Under ``G234``
  (Haas TCPC; also ``G43.4``/``G43.5``; cancelled by ``G49``) XYZ is taken as the tool tip in the
  part frame; under ``G254`` (DWO) as the tip in machine-aligned axes about the turned part origin
  (converted with ``p = Q^T p_prog``); with neither,
  at non-zero angles, as machine positions about the axes' points given in the kinematics (or like
  DWO, with a warning, when the kinematics gives none). Before any rotary word the angles are 0.
  Without a machine, a non-zero rotary angle is an error (the axis cannot be guessed); a program that
  never tilts has ``axes`` None.
* Events: ``M06`` tool change (``T`` alone is a pre-selection), ``M03/M04/M05`` spindle,
  ``M07/M08/M09`` coolant, ``G40/G41/G42`` cutter compensation, ``G234/G49``, ``G254/G255`` and
  ``G54..G59``/``G154`` frames, ``G04`` dwell (a ``dwell`` event in seconds: ``P`` with a decimal
  point in seconds, without in milliseconds, or ``X``), ``M00/M01`` stops, ``M02/M30`` end, other M
  codes as ``machine`` events.
* Canned cycles ``G73 G74 G81 G82 G83 G84 G84.2 G84.3 G85 G86 G89`` (a ``cycle`` event, ``G80`` ends
  them, as does ``G00..G03``): every block that names a position (X, Y, the drilling-axis word or R)
  is a hole, expanded into its moves along the drilling axis (Z for G17, Y for G18, X for G19) by
  :func:`planner.io.cycles.hole_moves`: ``R`` clearance level (G91: from the initial level), ``Z`` the
  bottom (G91: from R), ``Q`` peck depth (G83 full retract, G73 chip break by ``peck_clearance``),
  ``P`` dwell at the bottom (G82, G89, tapping; the same seconds/milliseconds rule as G04; a ``dwell``
  event), ``L``/``K`` repeats (G91 repeats the X/Y increment), ``G98`` retract to the initial level
  (the tool's level when the cycle started), ``G99`` to R. Plunges are fed at the modal F; G74/G84/
  G85/G89 feed out, the others rapid out. Every other G70..G89 (G76, G87, G88, Haas bolt patterns
  G70-G72, ...) is refused naming the line.

Anything else (an unknown G code, a word the reader does not know) is skipped with an
:class:`~planner.io.errors.InputFileWarning`; a malformed number raises
:class:`~planner.io.errors.InputFileError` naming the file, line and word.
"""

from __future__ import annotations

import itertools
import math
import re
from array import array
from typing import NoReturn

import numpy as np

from planner.io import options as opts
from planner.io._collect import PathCollector, check_arcs, open_lines, source_name, unit_scale
from planner.io.cycles import DEFAULT_PECK_CLEARANCE, DrillCycle, hole_moves
from planner.io.errors import InputFileError, WarningLimiter
from planner.io.machines import TableTableKinematics, machine_kinematics
from planner.io.sinumerik import SNIFF, Sinumerik
from planner.io.toolpath import Arc, Event, Toolpath, linearize_arcs, vec3

_TOKEN = re.compile(r"([A-Z])([^A-Z]*)")
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)\Z")
#: longest number word read (sign, digits, point, spaces): posts write at most ~20 (a 400-digit word reads as inf)
_MAX_DIGITS = 40
_BLOCK = re.compile(r"(?:[A-Z][-+]?(?:\d+\.?\d*|\.\d+))+\Z")
_EXPONENT = re.compile(r"([A-Za-z])\s*[-+]?(?:\d+\.?\d*|\.\d+)[eE][-+]?\d+")
_OPER = re.compile(r"^\s*OPER\s*:\s*(.*?)\s*$", re.IGNORECASE)
_PLANE_NORMAL = {17: (0.0, 0.0, 1.0), 18: (0.0, 1.0, 0.0), 19: (1.0, 0.0, 0.0)}
_PLANE_WORDS = {17: ("I", "J"), 18: ("I", "K"), 19: ("J", "K")}
_IGNORED_G = frozenset({43.0, 44.0, 61.0, 64.0, 187.0, 69.0, 15.0, 90.1, 91.1, 50.0})
_IGNORED_WORDS = frozenset("NHDE")
#: Canned cycles expanded into moves: code -> (peck mode, tool leaves at the feed, dwell read from P).
_CYCLES = {
    73.0: ("chip", False, False),  # high-speed peck drilling
    81.0: ("", False, False),  # drilling
    82.0: ("", False, True),  # spot drilling / counterboring with dwell
    83.0: ("full", False, False),  # deep-hole peck drilling
    74.0: ("", True, True),  # left-hand tapping
    84.0: ("", True, True),  # tapping
    84.2: ("", True, True),  # rigid tapping
    84.3: ("", True, True),  # rigid tapping, left-hand
    85.0: ("", True, False),  # boring, feed out
    86.0: ("", False, False),  # boring, spindle stop, rapid out
    89.0: ("", True, True),  # boring with dwell, feed out
}
#: Canned cycles and hole patterns refused by name: they move in ways the block does not give.
_REFUSED_CYCLES = {
    76.0: "fine boring (spindle orient and shift)",
    87.0: "back boring",
    88.0: "boring with manual retract",
    70.0: "bolt hole circle",
    71.0: "bolt hole arc",
    72.0: "bolt holes along an angle",
    77.0: "back bore / special cycle",
}
#: The drilling axis word and its index for the planes G17, G18, G19.
_DRILL_WORD = {17: ("Z", 2), 18: ("Y", 1), 19: ("X", 0)}
_MODE = {"tcpc": 0, "dwo": 1, "machine": 2}
#: A linear axis word in an ISO block (a block that moves the tool, for Sinumerik's MCALL).
_MOVES_AXES = re.compile(r"[XYZ][-+.\d]")


class _Reader:
    def __init__(self, source: str, units: str, machine: TableTableKinematics | None, dialect: str = "iso"):
        self.ended: tuple[int, str] | None = None  # (line, "M30"/"M02") once the program has ended
        self.source = source
        self.units, self.scale = unit_scale(units)
        self.default_units = self.units
        self.machine = machine
        self.rot_words: tuple[str, ...] = machine.words if machine is not None else ()
        self.out = PathCollector(source)
        self.warn = WarningLimiter(source)
        self.bc = array("d")  # commanded (tilt, rotary) angles per point, radians
        self.mode = bytearray()  # _MODE per point
        self.given = bytearray()  # the block gave a rotary word
        self.pos = [math.nan, math.nan, math.nan]  # program frame, metres
        self.angles = [0.0, 0.0]  # (tilt, rotary), radians
        self.rotary_used = False
        self.absolute = True
        self.motion: int | None = None
        self.plane = 17
        self.feed_mode = 94
        self.f_word = math.nan
        self.rpm = math.nan
        self.tcpc = False
        self.dwo = False
        self.cycle: float | None = None  # canned cycle code in effect (G73, G81, ...)
        self.cycle_line = 0
        self.cycle_r = math.nan  # R level (drilling coordinate, metres)
        self.cycle_z = math.nan  # hole bottom (drilling coordinate, metres)
        self.cycle_q = 0.0  # peck depth, metres
        self.cycle_p = 0.0  # dwell, seconds
        self.initial_level = math.nan  # drilling coordinate of the tool when the cycle started (G98)
        self.retract_r = False  # G99: retract to R; G98 (default): to the initial level
        self.peck_clearance = DEFAULT_PECK_CLEARANCE
        self.tool_next = math.nan
        self.tool_label = ""  # Sinumerik T="name"
        self.sinumerik_dwell = False  # a Sinumerik G4 block: its F/S word is the dwell
        self.vector: tuple[float, float, float] | None = None  # Sinumerik A3/B3/C3 of the current block
        self.vectors_used = False
        self.sinumerik = Sinumerik(self) if dialect == "sinumerik" else None
        self.pending_rapid = False
        self.last_feed: float | None = None
        self.started = False
        self.finished = False

    def fail(self, line: int, word: str, problem: str) -> NoReturn:
        raise InputFileError(self.source, line, f"word {word}" if word else "block", problem)

    # ------------------------------------------------------------------ tokenising
    def words(self, line: int, code: str) -> list[tuple[str, float, str]]:
        if not code[0].isalpha():
            self.fail(line, "", f"unexpected text {code[:20]!r} (a block is a sequence of letter+number words)")
        out = []
        for letter, value in _TOKEN.findall(code):
            if not value:
                self.fail(line, letter, "has no value")
            if not _NUMBER.match(value):
                self.fail(line, letter, f"{value!r} is not a number")
            if len(value) > _MAX_DIGITS:
                self.fail(line, letter, f"a number of {len(value)} characters ({value[:12]}...)")
            out.append((letter, float(value), value))
        return out

    def strip_comments(self, line: int, text: str) -> str:
        parts = []
        i = 0
        while True:
            j = text.find("(", i)
            k = text.find(";", i)
            if k >= 0 and (j < 0 or k < j):
                parts.append(text[i:k])
                break
            if j < 0:
                parts.append(text[i:])
                break
            parts.append(text[i:j])
            e = text.find(")", j + 1)
            comment = text[j + 1 : e] if e >= 0 else text[j + 1 :]
            m = _OPER.match(comment)
            if m:
                self.out.event("operation", line, m.group(1), math.nan, f"({comment.strip()})")
            if e < 0:
                break
            i = e + 1
        return "".join(parts)

    # ------------------------------------------------------------------ blocks
    def block(self, line: int, text: str) -> None:
        if self.sinumerik is not None:
            self.sinumerik_dwell = False
            raw = text
            text = self.sinumerik.translate(line, text)
            n0 = self.out.count
            if text:
                self.iso_block(line, text)
            if self.vector is not None:
                self.apply_vector(line, n0)
            for name, cyc in self.sinumerik.cycles_after(_MOVES_AXES.search(text) is not None):
                self.drill_here(line, raw, name, cyc)
            return
        self.iso_block(line, text)

    def apply_vector(self, line: int, n0: int) -> None:
        """The tool vector of a Sinumerik block (A3/B3/C3 under TRAORI) at the point the block reached."""
        v = self.vector
        assert v is not None
        self.vector = None
        self.vectors_used = True
        out = self.out
        if out.count == n0:  # the orientation alone changes: the tool turns where it is
            if any(c != c for c in self.pos):
                out.set_axis(out.count, v[0], v[1], v[2], True)
                return
            self.emit(line, tuple(self.pos), self.motion == 0)
        out.set_axis(out.count - 1, v[0], v[1], v[2], True)

    def iso_block(self, line: int, text: str) -> None:
        if "(" in text or ";" in text:
            text = self.strip_comments(line, text)
        code = text.replace(" ", "").replace("\t", "").upper()
        if not code:
            return
        exponent = _EXPONENT.search(text)
        if exponent:  # X1e3 would read as X1 and an E word: refuse what G-code cannot mean
            self.fail(line, exponent.group(1).upper(), f"{exponent.group(0)!r} is in exponent notation, which G-code "
                      "does not have: write the number in full")
        if code[0] == "/":
            self.warn.warn("block-delete blocks", line, "block delete '/' ignored: the block is executed")
            code = code[1:]
            if not code:
                return
        if code[0] == "O" and not _NUMBER.match(code[1:]):
            self.out.event("partno", line, text.strip()[1:].strip(), math.nan, text.strip())
            return
        if code[0] == ":":  # Fanuc program number
            self.out.event("partno", line, code[1:], math.nan, text.strip())
            return
        if not _BLOCK.match(code):
            self.words(line, code)  # names the bad word
            self.fail(line, "", f"cannot read {code!r}")
        gs: list[tuple[float, str]] | None = None
        ms: list[float] | None = None
        axes: dict[str, tuple[float, str]] = {}
        other: dict[str, float] = {}
        raws: dict[str, str] = {}
        rot_words = self.rot_words
        for letter, raw in _TOKEN.findall(code):
            if len(raw) > _MAX_DIGITS:
                self.fail(line, letter, f"a number of {len(raw)} characters ({raw[:12]}...): not a coordinate, feed "
                          f"or code a post-processor writes")  # fmt: skip
            if letter in "XYZ" or letter in rot_words or letter in "ABC":
                if letter in axes:
                    self.fail(line, letter, "appears twice in the block")
                axes[letter] = (float(raw), raw)
            elif letter == "N":
                continue
            elif letter == "G":
                if gs is None:
                    gs = []
                gs.append((float(raw), raw))
            elif letter == "M":
                if ms is None:
                    ms = []
                ms.append(float(raw))
            elif letter in "IJKRFSTPQL":
                other[letter] = float(raw)
                raws[letter] = raw
            elif letter in _IGNORED_WORDS:
                continue
            else:
                self.warn.warn(f"'{letter}' words", line, f"word {letter}{raw} not understood, ignored")
        home = None
        if gs is not None:
            for g, raw in gs:
                home = self.g_code(line, g, raw, text) or home
        if other:
            if "F" in other:
                if not other["F"] > 0.0:
                    self.fail(line, "F", f"feed rate must be positive, got {other['F']:g}")
                self.f_word = other["F"]
            if "S" in other:
                self.rpm = other["S"]
            if "T" in other:
                self.tool_next = other["T"]
                if ms is None or 6.0 not in ms:
                    self.out.event("tool_select", line, f"T{other['T']:g}", other["T"], text.strip())
        if ms is not None:
            for m in ms:
                self.m_code(line, m, text)
            if 2.0 in ms or 30.0 in ms:
                self.ended = (line, "M30" if 30.0 in ms else "M02")
        if gs is not None or other:
            self.update_feed()
        if self.cycle is not None and home is None:
            self.cycle_block(line, axes, other, raws, gs, text)
            return
        if axes:
            self.move(line, axes, other, home, text)

    def g_code(self, line: int, g: float, raw: str, text: str):
        out = self.out
        if g in (0.0, 1.0, 2.0, 3.0):
            self.motion = int(g)
            self.cycle = None
        elif g in (17.0, 18.0, 19.0):
            self.plane = int(g)
        elif g in (20.0, 21.0):
            units = "inch" if g == 20.0 else "mm"
            if units != self.units and out.cutting():
                self.fail(line, "G", f"G{raw} switches the units from {self.units} to {units} in the middle of a "
                          f"pass: state the units before the first motion or between passes")  # fmt: skip
            self.units, self.scale = unit_scale(units)
            out.units_seen.append(self.units)
            out.event("units", line, self.units, math.nan, text.strip())
        elif g in (90.0, 91.0):
            self.absolute = g == 90.0
        elif g in (93.0, 94.0, 95.0):
            self.feed_mode = int(g)
            if g == 93.0:
                self.warn.warn("G93", line, "inverse-time feed (G93) is not converted: feeds unknown")
        elif g in (40.0, 41.0, 42.0):
            out.event("cutcom", line, {40.0: "OFF", 41.0: "LEFT", 42.0: "RIGHT"}[g], math.nan, text.strip())
        elif g in (234.0, 43.4, 43.5):
            self.tcpc = True
            out.event("frame", line, "TCPC on", math.nan, text.strip())
        elif g == 49.0:
            if self.tcpc:
                out.event("frame", line, "TCPC off", math.nan, text.strip())
            self.tcpc = False
        elif g == 254.0:
            self.dwo = True
            out.event("frame", line, "DWO on", math.nan, text.strip())
        elif g == 255.0:
            self.dwo = False
            out.event("frame", line, "DWO off", math.nan, text.strip())
        elif 54.0 <= g <= 59.0 or g == 154.0 or g == 54.1:
            out.event("frame", line, f"G{raw}", math.nan, text.strip())
        elif g in (28.0, 53.0, 30.0):
            return int(g)
        elif g == 4.0:
            out.event("dwell", line, "G04", self.dwell_seconds(line, text), text.strip())
        elif g in _CYCLES:
            if self.cycle is None:
                k = _DRILL_WORD[self.plane][1]
                self.initial_level = self.pos[k]
            self.cycle = g
            self.cycle_line = line
            out.event("cycle", line, f"G{raw}", math.nan, text.strip())
        elif g in _REFUSED_CYCLES or (70.0 <= g < 90.0 and g != 80.0):
            what = _REFUSED_CYCLES.get(g, "a canned cycle")
            self.fail(line, "G", f"G{raw} ({what}) is a canned cycle the reader does not expand: "
                      "its holes cannot be planned")  # fmt: skip
        elif g == 80.0:
            if self.cycle is not None:
                out.event("cycle", line, "G80", math.nan, text.strip())
            self.cycle = None
            self.cycle_r = self.cycle_z = math.nan
            self.cycle_q = self.cycle_p = 0.0
        elif g in (98.0, 99.0):
            self.retract_r = g == 99.0
        elif g in _IGNORED_G:
            pass
        elif g == 68.0 or g == 68.2:
            self.fail(line, "G", f"G{raw} (coordinate rotation) is not supported: post without it")
        else:
            self.warn.warn(f"G{raw}", line, f"G{raw} not understood, ignored")
        return None

    def dwell_seconds(self, line: int, text: str) -> float:
        """Seconds of a G04 block: P with a decimal point in seconds, without in milliseconds; or X seconds."""
        code = text.upper().replace(" ", "")
        for letter in ("P", "X", "U"):
            for m in re.finditer(letter + r"([-+]?(?:\d+\.?\d*|\.\d+))", code):
                raw = m.group(1)
                v = float(raw)
                return v if (letter != "P" or "." in raw) else v / 1000.0
        return math.nan

    def cycle_block(self, line: int, axes: dict, other: dict, raws: dict, gs, text: str) -> None:
        """A block in canned-cycle mode: new cycle values and, when it names a position, the holes."""
        word, k = _DRILL_WORD[self.plane]
        s = self.scale
        for w, (v, _) in axes.items():
            if w in "XYZ":
                continue
            same = w in self.rot_words and abs(math.radians(v) - self.angles[self.rot_words.index(w)]) < 1e-12
            if not (same or (w not in self.rot_words and v == 0.0)):
                self.fail(line, w, f"rotary word {w} turns the part inside canned cycle G{self.cycle:g} (line "
                          f"{self.cycle_line}); end the cycle with G80 first")  # fmt: skip
        if "R" in other:
            r = other["R"] * s
            base = self.initial_level if not self.absolute else 0.0
            self.cycle_r = r + (base if base == base else 0.0)
        if word in axes:
            z = axes[word][0] * s
            self.cycle_z = z if self.absolute else self.cycle_r + z
        if "Q" in other:
            self.cycle_q = abs(other["Q"]) * s
        if "P" in other:
            self.cycle_p = other["P"] if "." in raws["P"] else other["P"] / 1000.0
        repeats = int(other.get("L", other.get("K", 1.0)))
        defining = gs is not None and any(g in _CYCLES for g, _ in gs)
        in_plane = [(i, w) for i, w in enumerate("XYZ") if i != k]
        if not (defining or any(w in axes for _, w in in_plane) or word in axes or "R" in other):
            return
        code = self.cycle
        assert code is not None
        name = f"G{code:g}"
        for what, v in (("Z" if word == "Z" else word, self.cycle_z), ("R", self.cycle_r)):
            if v != v:
                self.fail(line, "", f"canned cycle {name} (line {self.cycle_line}) has no {what} level yet")
        peck_mode, feed_out, dwell = _CYCLES[code]
        if peck_mode and not self.cycle_q > 0.0:
            self.fail(line, "Q", f"{name} needs a peck depth Q > 0")
        retract = self.cycle_r if self.retract_r else self.initial_level
        if retract != retract:
            retract = self.cycle_r
        cyc = DrillCycle(name=name, line=line, clearance=self.cycle_r, bottom=self.cycle_z, retract=retract,
                         peck=self.cycle_q if peck_mode else 0.0, peck_mode=peck_mode,
                         peck_clearance=self.peck_clearance, dwell=self.cycle_p if dwell else 0.0, feed_out=feed_out)
        problem = cyc.problem()
        if problem:
            self.fail(line, "", f"{name}: {problem}")
        normal = [0.0, 0.0, 0.0]
        normal[k] = 1.0
        pos = self.pos
        for rep in range(max(repeats, 0)):
            current = None if pos[k] != pos[k] else tuple(pos)
            for i, w in in_plane:
                if w in axes and (rep == 0 or not self.absolute):
                    v = axes[w][0] * s
                    pos[i] = v if self.absolute else pos[i] + v
            if any(pos[i] != pos[i] for i, _ in in_plane):
                self.fail(line, "", f"{name}: the hole position is not known (after G28/G53 give X and Y)")
            hole = list(pos)
            hole[k] = 0.0
            if current is not None and any(v != v for v in current):
                current = None
            self.emit_hole(line, text, name, cyc, current, hole, normal)

    def drill_here(self, line: int, text: str, name: str, cyc: DrillCycle) -> None:
        """One hole of a Sinumerik drilling cycle at the tool's position (levels absolute along the plane's
        drilling axis), expanded like G81: clearance, feed to depth, dwell, retract."""
        k = _DRILL_WORD[self.plane][1]
        pos = self.pos
        if any(v != v for v in pos):
            self.fail(line, name, f"{name}: the hole position is not known (after SUPA/G53 give X, Y and Z)")
        normal = [0.0, 0.0, 0.0]
        normal[k] = 1.0
        hole = list(pos)
        hole[k] = 0.0
        self.emit_hole(line, text, name, cyc, tuple(pos), hole, normal)

    def emit_hole(self, line: int, text: str, name: str, cyc: DrillCycle, current, hole, normal) -> None:
        """The moves of one hole (:func:`hole_moves`) from ``current``, the cycle's dwell at the bottom, and the
        tool's position left at the last of them."""
        moves, bottom = hole_moves(current, hole, normal, cyc)
        for j, (q, rapid) in enumerate(moves):
            self.emit(line, q, rapid)
            if j == bottom and cyc.dwell > 0.0:
                self.out.event("dwell", line, name, cyc.dwell, text.strip())
        if moves:
            self.pos[:] = moves[-1][0]

    def emit(self, line: int, xyz, rapid: bool, rot_given: bool = False) -> None:
        """Append one point (program frame, metres) with the modal rotary state."""
        out = self.out
        k = len(out.lines)
        out.xyz.extend(xyz)
        out.lines.append(line)
        if rapid or self.pending_rapid:
            out.rapid_idx.append(k)
            self.pending_rapid = False
        self.bc.extend(self.angles)
        self.mode.append(0 if self.tcpc else 1 if self.dwo else 2)
        self.given.append(1 if rot_given else 0)

    def m_code(self, line: int, m: float, text: str) -> None:
        out = self.out
        if m == 6.0:
            label = self.tool_label or f"T{self.tool_next:g}"
            out.event("tool_change", line, label, self.tool_next, text.strip())
        elif m in (3.0, 4.0):
            speed = self.rpm * 2.0 * math.pi / 60.0
            out.event("spindle", line, "CLW" if m == 3.0 else "CCLW", speed, text.strip())
        elif m == 5.0:
            out.event("spindle", line, "OFF", 0.0, text.strip())
        elif m in (7.0, 8.0, 9.0):
            out.event("coolant", line, {7.0: "MIST", 8.0: "FLOOD", 9.0: "OFF"}[m], math.nan, text.strip())
        elif m in (2.0, 30.0):
            out.event("end", line, f"M{m:g}", math.nan, text.strip())
        else:
            out.event("machine", line, f"M{m:g}", math.nan, text.strip())

    def update_feed(self) -> None:
        if self.feed_mode == 94:
            f = self.f_word * self.scale / 60.0
        elif self.feed_mode == 95:
            f = self.f_word * self.scale * self.rpm / 60.0
        else:
            f = math.nan
        if self.last_feed is None or not (f == self.last_feed or (math.isnan(f) and math.isnan(self.last_feed))):
            self.out.set_feed(self.out.count, f)
            self.last_feed = f

    def move(self, line: int, axes: dict, other: dict, home, text: str) -> None:
        pos = self.pos
        old = None
        rot_given = False
        for w, (v, raw) in axes.items():
            if w == "X" or w == "Y" or w == "Z":
                continue
            if w not in self.rot_words:
                if v != 0.0:
                    if self.machine is None:
                        self.fail(line, w, f"the program turns rotary axis {w} ({raw}); name the machine "
                                  "kinematics, e.g. read_gcode(..., machine='haas-umc-750')")  # fmt: skip
                    self.fail(line, w, f"machine {self.machine.name!r} has no {w} axis (its rotary axes are "
                              f"{'/'.join(self.rot_words)})")  # fmt: skip
                continue
            if self.sinumerik is not None and self.sinumerik.frame is not None:
                self.fail(line, w, f"rotary word {w} ({raw}) in a CYCLE800 swivel plane: the plane already sets the "
                          "tool axis; reset the swivel (CYCLE800()) before turning rotary axes")  # fmt: skip
            k = 0 if w == self.rot_words[0] else 1
            if home == 28:
                self.angles[k] = 0.0
            elif self.absolute or home == 53:
                self.angles[k] = math.radians(v)
            else:
                self.angles[k] += math.radians(v)
            rot_given = True
            self.rotary_used = True
        if home is not None:
            for k, w in enumerate("XYZ"):
                if w in axes:
                    pos[k] = math.nan
            self.pending_rapid = True
            self.out.event("home", line, f"G{home}", math.nan, text.strip())
            return
        if self.motion is None:
            self.fail(line, "", "axis words with no motion mode (G00/G01/G02/G03) in effect")
        if self.motion >= 2:
            old = list(pos)
        s = self.scale
        absolute = self.absolute
        for k, w in ((0, "X"), (1, "Y"), (2, "Z")):
            if w in axes:
                v = axes[w][0] * s
                pos[k] = v if absolute else pos[k] + v
        x, y, z = pos
        if x != x or y != y or z != z:  # NaN: not all known yet (after G28/G53)
            self.pending_rapid = self.pending_rapid or self.motion == 0
            return
        arc = None
        if old is not None:
            if old[0] != old[0] or old[1] != old[1] or old[2] != old[2]:
                self.fail(line, "G", f"G0{self.motion} arc from an unknown position (after G28/G53)")
            arc = self.arc_centre(line, old, other)
        out = self.out
        k = len(out.lines)
        out.xyz.extend(pos)
        out.lines.append(line)
        if self.motion == 0 or self.pending_rapid:
            out.rapid_idx.append(k)
            self.pending_rapid = False
        self.bc.extend(self.angles)
        self.mode.append(0 if self.tcpc else 1 if self.dwo else 2)
        self.given.append(1 if rot_given else 0)
        if arc is not None:
            out.add_arc(line, k, arc[0], arc[1], arc[2])

    def arc_centre(self, line: int, start: list[float], other: dict):
        s = self.scale
        n = np.array(_PLANE_NORMAL[self.plane])
        axis = n if self.motion == 3 else -n
        p0, p1 = np.array(start), np.array(self.pos)
        if "R" in other:
            r = other["R"] * s
            d = (p1 - p0) - ((p1 - p0) @ n) * n
            chord = float(np.linalg.norm(d))
            if chord == 0.0 or r == 0.0:
                self.fail(line, "R", "an R arc needs distinct end points and a non-zero radius (use I, J, K)")
            half = chord / 2.0
            if half > abs(r) * (1.0 + 1e-6) + 1e-9:
                self.fail(line, "R", f"radius {abs(r) / s:g} is smaller than half the chord {half / s:g}")
            h = math.sqrt(max(r * r - half * half, 0.0))
            side = np.cross(axis, d) / chord
            centre = p0 + d / 2.0 + math.copysign(h, r) * side
            return centre, axis, abs(r)
        w1, w2 = _PLANE_WORDS[self.plane]
        if w1 not in other and w2 not in other:
            self.fail(line, "", f"G0{self.motion} arc has neither {w1}/{w2} nor R")
        off = np.zeros(3)
        for w in (w1, w2):
            off["IJK".index(w)] = other.get(w, 0.0) * s
        return p0 + off, axis, math.nan

    # ------------------------------------------------------------------ stream
    def run(self, lines) -> None:
        it = enumerate(lines, 1)
        has_percent = None
        for lineno, raw in it:
            text = raw.strip()
            if lineno == 1 and text.startswith("Information listing created by"):
                header = [text]
                for _, r in it:
                    if not r.strip():
                        break
                    header.append(r.strip())
                self.out.events.append(Event("listing", 1, 0, "header", math.nan, " | ".join(header)))
                continue
            if not text:
                continue
            if text.startswith("%"):
                if has_percent:
                    self.after_end(it)
                    return
                has_percent = True
                continue
            if text.startswith("Tool Path Listing has "):
                self.out.event("listing", lineno, "trailer", math.nan, text)
                continue
            self.block(lineno, text)
            if self.ended is not None:  # M02 / M30: the program ends here, as the controller does
                self.after_end(it, f"after {self.ended[1]} (end of program) at line {self.ended[0]}")
                return

    def after_end(self, it, where: str = "after the closing %") -> None:
        extra = []
        for lineno, raw in it:
            t = raw.strip()
            if not t:
                continue
            if t.startswith("Tool Path Listing has "):
                self.out.event("listing", lineno, "trailer", math.nan, t)
            elif self.ended is not None and (t.startswith(("%", "(", ";")) or not t.strip("%")):
                continue  # after M30 / M02: the closing % and comments are the program's normal end
            else:
                extra.append(lineno)
        if extra:
            self.warn.warn("lines after the end", extra[0], f"{len(extra)} non-blank line(s) {where} ignored")

    # ------------------------------------------------------------------ finish
    def finish(self) -> Toolpath:
        tp = self.out.finish(self.default_units, point_field="word {col}")
        n = len(tp)
        bc = np.frombuffer(self.bc, dtype=float).reshape(n, 2) if n else np.empty((0, 2))
        mode = np.frombuffer(bytes(self.mode), dtype=np.uint8)
        given = np.frombuffer(bytes(self.given), dtype=np.uint8).astype(bool)
        m = self.machine
        if self.vectors_used and self.rotary_used:
            raise InputFileError(self.source, None, "", "the program gives both tool vectors (A3/B3/C3) and rotary "
                                 "axis angles: read one or the other")  # fmt: skip
        if m is None or not self.rotary_used:
            return tp
        pts = np.array(tp.points)
        tilted = np.abs(m.table_rotation(bc[:, 0], bc[:, 1]).magnitude()) > 1e-12 if n else np.zeros(0, bool)
        unknown = (mode == _MODE["machine"]) & tilted
        if unknown.any() and (m.tilt_point is None or m.rotary_point is None):
            first = int(tp.lines[np.argmax(unknown)])
            self.warn.warn(
                "uncompensated 5-axis blocks",
                first,
                f"{int(unknown.sum())} point(s) at non-zero rotary angles without G234/G254: XYZ read as "
                "machine-aligned coordinates about the part origin (give tilt_point and rotary_point in "
                "the kinematics if the program is not compensated)",
            )
        for name, code in _MODE.items():
            sel = mode == code
            if code != _MODE["tcpc"] and sel.any():
                pts[sel] = m.part_points(pts[sel], bc[sel, 0], bc[sel, 1], name)
        axes = m.tool_axis(bc[:, 0], bc[:, 1]) if n else np.empty((0, 3))
        arcs = [e for e in tp.events if isinstance(e, Arc)]
        events = [e for e in tp.events if not isinstance(e, Arc)]
        if arcs:
            k = np.array([e.index for e in arcs])
            centre = np.array([e.centre for e in arcs])
            arc_axis = np.array([e.axis for e in arcs])
            for name, code in _MODE.items():
                sel = mode[k] == code
                if code != _MODE["tcpc"] and sel.any():
                    kk = k[sel]
                    centre[sel] = m.part_points(centre[sel], bc[kk, 0], bc[kk, 1], name)
                    arc_axis[sel] = m.table_rotation(bc[kk, 0], bc[kk, 1]).inv().apply(arc_axis[sel])
            for e, c, a in zip(arcs, centre, arc_axis, strict=True):
                events.append(Arc(e.line, e.index, e.start, vec3(c), vec3(a), e.radius))
            events.sort(key=lambda e: e.line)
        return Toolpath(
            points=pts,
            axes=axes,
            axis_given=given,
            feeds=tp.feeds,
            rapid=tp.rapid,
            lines=tp.lines,
            events=tuple(events),
            units=tp.units,
            source=tp.source,
            rotary=bc,
        )


def read_gcode(
    src,
    *,
    machine: TableTableKinematics | str | None = None,
    units: str = "mm",
    arc_tolerance: float | None = None,
    source: str | None = None,
    dialect: str = "auto",
    peck_clearance: float = DEFAULT_PECK_CLEARANCE,
) -> Toolpath:
    """Read a G-code program into a :class:`Toolpath` (see the module notes for the dialect).

    Parameters
    ----------
    src : str, os.PathLike or text stream
        The program file, or an open text stream.
    machine : TableTableKinematics or str, optional
        Kinematics converting the rotary words to tool axes, or a preset name (``"haas-umc-750"``).
        Required as soon as the program turns a rotary axis away from 0.
    units : {"mm", "inch"}, default "mm"
        Length unit before the program's first G20/G21.
    arc_tolerance : float or None, default None
        None keeps G02/G03 circles as :class:`~planner.io.toolpath.Arc` events; a length in metres
        inserts chord points within that tolerance (see :func:`~planner.io.toolpath.linearize_arcs`).
    source : str, optional
        Name used in messages (default: the file's base name).
    peck_clearance : float, default 0.5e-3
        Peck drilling: the distance, metres, a chip-breaking cycle backs off and a deep cycle stops above
        the last depth before feeding again (a machine parameter the program does not give).
    dialect : {"auto", "iso", "sinumerik"}, default "auto"
        "iso": ISO 6983 / Fanuc / Haas; "sinumerik": Siemens 840D (:mod:`planner.io.sinumerik`);
        "auto": Sinumerik for ``.mpf``/``.spf`` names or when the first 200 lines hold Sinumerik
        constructs (DEF, assignments, MSG, CYCLE800/832, TRAORI, FNORM, SUPA), else ISO.

    Returns
    -------
    Toolpath
        Tool-tip points (metres, part frame), tool axes from the rotary angles (or None for a program
        that never tilts), feeds (m/s), rapid flags, lines, events and the programmed angles
        (``rotary``, radians) of a 5-axis program.

    Raises
    ------
    ReaderArgumentError
        A bad argument, named (an unknown machine lists the presets), before the file is opened.
    InputFileError
        A malformed block, naming the file, line and word.
    """
    opts.check_src(src)
    kin = machine_kinematics(machine) if machine is not None else None
    name = source_name(src, opts.source_label(source))
    unit_scale(units)
    arc_tolerance = opts.arc_tolerance(arc_tolerance)
    peck = opts.peck_clearance(peck_clearance)
    opts.choice(dialect, "dialect", ("auto", "iso", "sinumerik"))
    with open_lines(src, name) as lines:
        if dialect == "auto":
            if name.lower().endswith((".mpf", ".spf")):
                dialect = "sinumerik"
            else:
                head = list(itertools.islice(lines, 200))
                dialect = "sinumerik" if any(SNIFF.match(t) for t in head) else "iso"
                lines = itertools.chain(head, lines)
        reader = _Reader(name, units, kin, dialect)
        reader.peck_clearance = peck
        reader.run(lines)
    if reader.out.count == 0:
        raise InputFileError(name, None, "", "holds no motion block with a known X, Y and Z")
    tp = reader.finish()
    check_arcs(tp, reader.warn)
    reader.warn.flush()
    if arc_tolerance is not None:
        tp = linearize_arcs(tp, arc_tolerance)
    return tp
