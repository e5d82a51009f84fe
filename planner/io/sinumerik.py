"""The Sinumerik 840D dialect of the G-code reader: blocks translated into the ISO words the reader plans.

Selected by the file name (``.mpf``, ``.spf``), by ``read_gcode(..., dialect="sinumerik")``, or, with
``dialect="auto"`` and another name, by Sinumerik constructs in the first lines (``DEF``, assignments,
``MSG(``, ``CYCLE800(``/``CYCLE832(``, ``TRAORI``, ``FNORM``, ``SUPA``). Each block is read left to right:

Read
    ``;`` comments (parentheses group expressions, they are not comments); ``N``/``:`` block numbers;
    ``DEF REAL|INT|BOOL|CHAR|STRING[n] name[=expr], ...`` declarations; assignments ``name=expr`` to
    declared variables, R parameters (``R1``, 0 until assigned) and names starting with ``_`` (a global user variable
    without DEF draws a warning); expressions with ``+ - * /``, ``DIV``, ``MOD``, parentheses and
    ``SIN COS TAN ASIN ACOS ATAN2 SQRT ABS POT TRUNC ROUND LN EXP MINVAL MAXVAL`` (degrees, as the
    control); address words written ``X10``, ``X=expr``, ``X=IC(expr)`` (incremental in a G90 block),
    ``X=AC(expr)``, rotary ``C=DC|ACP|ACN(expr)`` (absolute angle), ``I=AC(expr)`` (absolute arc
    centre), ``CR=expr`` (arc radius, as ISO ``R``), ``F=``, ``S=``/``S1=``, ``M=``, ``T=n``,
    ``T="name"`` (a ``tool_select`` event; M6 changes to it), ``D``; under ``TRAORI`` the tool vector
    ``A3= B3= C3=`` (all three in the block, normalised; the tool axis from the tip towards the spindle
    at the block's end point, modal; a block with a vector and no position turns the tool in place);
    ``G70``/``G700`` inch and ``G71``/``G710`` metric (the Sinumerik meaning); ``G4 F<s>`` /
    ``G4 S<rev>`` dwell (a ``dwell`` event; F is not the feed there).
Swivel planes and drilling cycles
    ``CYCLE800(_FR, _TC, _ST, _MODE, _X0, _Y0, _Z0, _A, _B, _C, _X1, _Y1, _Z1, ...)`` axis by axis (``_MODE`` bits
    7-6 = 0; bits 1-0, 3-2, 5-4 name the axes of the rotations by _A, _B, _C: 01 X, 10 Y, 11 Z, e.g. 57 X-Y-Z,
    27 Z-Y-X), new (``_ST`` units digit 0) or additive (1): the following blocks are in the swivelled frame,
    p_part = X0 + R (X1 + p) with R the rotations each about the axis already turned, and the tool along its z,
    until ``CYCLE800()`` (or every offset and angle 0) resets it; ``_FR`` != 0 retracts to a machine position (the
    next point is a rapid once X, Y and Z are known), ``_FR=0`` keeps the tool where it is. ``CYCLE81(RTP, RFP,
    SDIS, DP, DPR)`` and ``CYCLE82(..., DTB)`` at the current position, or after every block that moves under
    ``MCALL CYCLE8x(...)`` until ``MCALL``: expanded like G81/G82 (rapid to RFP + SDIS, feed to DP or RFP - DPR
    at the modal F, DTB dwell, rapid out to RFP + SDIS, then to RTP), along the plane's drilling axis.
Kept as events (no motion)
    ``MSG("text")`` (``insert``); ``CYCLE832(tol, ...)`` (``setting``, value = tolerance in metres);
    ``CYCLE800`` frames (``frame``); ``TRAORI``,
    ``TRAFOOF`` (``frame``); ``SUPA``/``G53``/``G153`` blocks (``home``: the named axes are in machine
    coordinates, unknown in the part frame, as ISO ``G53``; their values are not evaluated);
    ``G500``, ``G505..G599`` (``frame``); settings without geometry (``setting``): ``FNORM FLIN FCUB
    COMPOF COMPCAD COMPCURV COMPSURF SOFT BRISK DRIVE FFWON FFWOF G60 G601 G602 G603 G64 G641 G642 G643
    G644 G645 G9 G450 G451 UPATH SPATH ORIWKS ORIMKS ORIAXES ORIVECT ORICONO ORISON ORISOF CUT2D
    CUT2DF CUT3DC CUT3DF CUT3DFF CFC CFTCP CFIN STOPRE WORKPIECE(...) FGROUP(...) G25 G26 TURN=0``
    and ``TRANS``/``ROT``/``SCALE``/``MIRROR`` without values (frame resets); ``PROC name``
    (``partno``); ``M17``/``RET`` (``end``).
Refused, naming the line and the construct (they change the geometry in ways not read here)
    ``CYCLE800`` by solid angle, projection angle or rotary axis positions (direct: needs the machine's
    kinematics data), with another ``_ST`` units digit or an ``_MODE`` naming no axis sequence (the parameter
    named); ``CYCLE83``-``CYCLE89`` (by name) and other ``CYCLExxx(...)`` technology cycles, called or with
    ``MCALL``; a rotary axis word under a swivel plane; ``TURN=n`` with n != 0, ``TRANS/ATRANS/ROT/AROT/SCALE/
    ASCALE/MIRROR/AMIRROR`` with values, ``G58/G59`` (programmable offsets), ``CIP CT AR= AP= RP=
    POLAR I1= J1= K1=``, tool orientation words ``A2 B2 C2 A4 B4 C4 A5 B5 C5 LEAD TILT THETA``, ``ORIRESET(angles)``,
    a vector without TRAORI or with a component missing, vectors mixed with rotary angles in one program,
    program flow (``IF ELSE ENDIF WHILE FOR LOOP REPEAT GOTOF GOTOB GOTO CASE`` and labels), system
    variables ``$...``, indexed variables, ``G33 G331 G332 G110 G111 G112``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from typing import NoReturn

import numpy as np

from planner.io.cycles import DrillCycle
from planner.io.errors import InputFileError

#: Sinumerik markers that select the dialect in a file whose name does not (``dialect="auto"``).
SNIFF = re.compile(
    r"^\s*(?:N\d+\s+)?(?:DEF\s|MSG\s*\(|CYCLE8\d\d\s*\(|TRAORI\b|TRAFOOF\b|FNORM\b|SUPA\b|_\w+\s*=|R\d+\s*=)",
    re.IGNORECASE,
)

_SETTINGS = frozenset(
    "FNORM FLIN FCUB COMPOF COMPCAD COMPCURV COMPSURF SOFT BRISK DRIVE FFWON FFWOF G60 G601 G602 G603 G64 G641 "
    "G642 G643 G644 G645 G9 G450 G451 UPATH SPATH ORIWKS ORIMKS ORIAXES ORIVECT ORICONO ORISON ORISOF CUT2D "
    "CUT2DF CUT3DC CUT3DF CUT3DFF CFC CFTCP CFIN STOPRE WAITM G25 G26 DIAMOF ORIEULER ORIRPY".split()
)
#: Drilling cycles read (called alone: at the current position; with MCALL: after every block that moves).
_DRILL_CYCLES = frozenset({"CYCLE81", "CYCLE82"})
#: Drilling cycles refused by name (their moves depend on parameters the reader does not model).
_REFUSED_DRILL_CYCLES = {"CYCLE83": "deep-hole drilling with degression", "CYCLE84": "rigid tapping",
                         "CYCLE840": "tapping with compensating chuck", "CYCLE85": "boring with a retract feed",
                         "CYCLE86": "boring with spindle orientation", "CYCLE87": "boring with a stop",
                         "CYCLE88": "boring with a stop", "CYCLE89": "boring with a dwell"}
_FRAME_RESETS = frozenset("TRANS ATRANS ROT AROT SCALE ASCALE MIRROR AMIRROR".split())
_FRAME_WORDS = frozenset({"TRAORI", "TRAFOOF", "G500"})
_FLOW = frozenset("IF ELSE ENDIF WHILE ENDWHILE FOR ENDFOR LOOP ENDLOOP REPEAT UNTIL GOTOF GOTOB GOTO GOTOC "
                  "CASE DEFAULT CALL PCALL EXTCALL".split())  # fmt: skip
_REFUSED_WORDS = {
    "CIP": "circle through an intermediate point",
    "CT": "tangential circle",
    "POLAR": "polar coordinates",
    "G58": "programmable axial offset",
    "G59": "programmable axial offset",
    "G33": "thread cutting",
    "G331": "rigid tapping",
    "G332": "rigid tapping retract",
    "G110": "polar pole",
    "G111": "polar pole",
    "G112": "polar pole",
    "LEAD": "tool lead angle",
    "TILT": "tool tilt angle",
    "THETA": "tool rotation angle",
}
_REFUSED_ADDRESSES = {
    "AR": "arc opening angle",
    "AP": "polar angle",
    "RP": "polar radius",
    "I1": "intermediate point of CIP",
    "J1": "intermediate point of CIP",
    "K1": "intermediate point of CIP",
    "A2": "tool orientation (Euler/RPY angle)",
    "B2": "tool orientation (Euler/RPY angle)",
    "C2": "tool orientation (Euler/RPY angle)",
    "A4": "surface normal",
    "B4": "surface normal",
    "C4": "surface normal",
    "A5": "surface normal",
    "B5": "surface normal",
    "C5": "surface normal",
}
_SINGLE = frozenset("XYZABCIJKFSTDMHGNLPQRUVWE")
_FUNCS: dict[str, Callable[..., float]] = {
    "SIN": lambda a: math.sin(math.radians(a)),
    "COS": lambda a: math.cos(math.radians(a)),
    "TAN": lambda a: math.tan(math.radians(a)),
    "ASIN": lambda a: math.degrees(math.asin(a)),
    "ACOS": lambda a: math.degrees(math.acos(a)),
    "ATAN2": lambda a, b: math.degrees(math.atan2(a, b)),
    "SQRT": math.sqrt,
    "ABS": abs,
    "POT": lambda a: a * a,
    "TRUNC": lambda a: float(math.trunc(a)),
    "ROUND": lambda a: float(math.floor(a + 0.5)),
    "LN": math.log,
    "EXP": math.exp,
    "MINVAL": min,
    "MAXVAL": max,
}
_NUM = re.compile(r"(?:\d+\.?\d*|\.\d+)(?:EX[-+]?\d+)?")
_IDENT = re.compile(r"[A-Z_$][A-Z0-9_]*")
_R_PARAM = re.compile(r"R\d+")
_LABEL = re.compile(r"([A-Z_][A-Z0-9_]*):")
_CALL = re.compile(r"([A-Z_][A-Z0-9_]*)\s*\((.*)\)", re.DOTALL)
_SPINDLE_M = re.compile(r"([SM])\d*")
_SETTABLE_FRAME = re.compile(r"G5(?:0[5-9]|[1-9]\d)")
_DWELL_WORD = re.compile(r"[FS][-+]?(?:\d+\.?\d*|\.\d+)")
_MODE_CALL = re.compile(r"(IC|AC|DC|ACP|ACN)\s*\((.*)\)", re.IGNORECASE | re.DOTALL)
_BLOCK_NUMBER = re.compile(r"^(?:[N:]\d+\s*)+", re.IGNORECASE)
_COMPACT = re.compile(r"([A-Z]+)([-+]?(?:\d+\.?\d*|\.\d+))")


class ExpressionError(ValueError):
    """An expression the reader cannot evaluate (the message says why)."""


_TOKENS = re.compile(r"\s*(?:((?:\d+\.?\d*|\.\d+)(?:EX[-+]?\d+)?)|([A-Z_$][A-Z0-9_]*)|(\S))")


class Expression:
    """Recursive-descent evaluator of Sinumerik arithmetic over a variable table (upper-case names).

    Grammar: ``sum := product (("+" | "-") product)*``, ``product := unary (("*" | "/" | DIV | MOD)
    unary)*``, ``unary := ("+" | "-") unary | atom``, ``atom := number | name | name "(" sum ("," sum)*
    ")" | "(" sum ")"``; trigonometry in degrees, as on the control.
    """

    def __init__(self, text: str, variables: dict[str, float | str | None]):
        self.toks: list[tuple[str, str]] = []  # (kind, text): kind "n" number, "i" name, "o" other
        for num, name, other in _TOKENS.findall(text.upper()):
            self.toks.append(("n", num) if num else ("i", name) if name else ("o", other))
        self.k = 0
        self.vars = variables

    def value(self) -> float:
        v = self.sum()
        if self.k != len(self.toks):
            raise ExpressionError(f"unexpected {''.join(t for _, t in self.toks[self.k:])!r}")
        return v

    def peek(self) -> str:
        return self.toks[self.k][1] if self.k < len(self.toks) else ""

    def sum(self) -> float:
        v = self.product()
        while True:
            c = self.peek()
            if c == "+" or c == "-":
                self.k += 1
                w = self.product()
                v = v + w if c == "+" else v - w
            else:
                return v

    def product(self) -> float:
        v = self.unary()
        while True:
            c = self.peek()
            if c == "*" or c == "/":
                self.k += 1
                w = self.unary()
                if c == "/" and w == 0.0:
                    raise ExpressionError("division by zero")
                v = v * w if c == "*" else v / w
            elif c == "DIV" or c == "MOD":
                self.k += 1
                w = self.unary()
                if w == 0.0:
                    raise ExpressionError(f"{c} by zero")
                v = float(math.trunc(v / w)) if c == "DIV" else math.fmod(v, w)
            else:
                return v

    def unary(self) -> float:
        c = self.peek()
        if c == "-" or c == "+":
            self.k += 1
            v = self.unary()
            return -v if c == "-" else v
        return self.atom()

    def atom(self) -> float:
        if self.k >= len(self.toks):
            raise ExpressionError("expression ends early")
        kind, tok = self.toks[self.k]
        self.k += 1
        if kind == "n":
            return float(tok.replace("EX", "E"))
        if tok == "(":
            v = self.sum()
            if self.peek() != ")":
                raise ExpressionError("missing ')'")
            self.k += 1
            return v
        if kind != "i":
            raise ExpressionError(f"unexpected {tok!r}")
        name = tok
        nxt = self.peek()
        if nxt == "[":
            raise ExpressionError(f"indexed variable {name}[...] is not read")
        if name.startswith("$"):
            raise ExpressionError(f"system variable {name} (machine state) is not read")
        if nxt == "(":
            if name not in _FUNCS:
                raise ExpressionError(f"function {name}() is not known")
            self.k += 1
            args = [self.sum()]
            while self.peek() == ",":
                self.k += 1
                args.append(self.sum())
            if self.peek() != ")":
                raise ExpressionError(f"missing ')' after the arguments of {name}")
            self.k += 1
            try:
                return float(_FUNCS[name](*args))
            except (TypeError, ValueError, OverflowError) as exc:
                raise ExpressionError(f"{name}{tuple(args)}: {exc}") from None
        if name not in self.vars and _R_PARAM.fullmatch(name):
            return 0.0  # R parameters exist on every control (0 until assigned)
        if name not in self.vars:
            raise ExpressionError(f"variable {name} is not defined (no DEF or assignment before)")
        value = self.vars[name]
        if not isinstance(value, float):
            raise ExpressionError(f"variable {name} has no numeric value")
        return value


def split_words(text: str) -> list[str]:
    """The block's words: split at blanks outside parentheses and strings."""
    if "(" in text or '"' in text or "[" in text:
        words = [w for w in _split_top_level(text, " \t") if w]
    else:
        words = text.split()
    # an expression may hold blanks around its operators: "R2=7 DIV 2", "X=_X0 + 5"
    if len(words) < 2 or not any(w[0] in "+-*/" or w.upper() in ("DIV", "MOD") or w[-1] in "+-*/=" for w in words):
        return words
    merged: list[str] = []
    for w in words:
        u = w.upper()
        if merged and "=" in merged[-1]:
            prev = merged[-1].upper()
            if u in ("DIV", "MOD") or w[0] in "+-*/" or prev[-1] in "+-*/=(" or prev.endswith((" DIV", " MOD")):
                merged[-1] += " " + w
                continue
        merged.append(w)
    return merged


def _split_top_level(text: str, seps: str = ",") -> list[str]:
    """Parts of ``text`` between the characters of ``seps`` that stand outside parentheses, brackets and strings.

    Every separator ends a part, so parts may be empty (``"a,,b"`` -> ``["a", "", "b"]``, ``""`` -> ``[""]``):
    argument lists keep their positions; word splitting at blanks and tabs drops the empty ones.
    """
    parts: list[str] = []
    cur: list[str] = []
    depth, quote = 0, False
    for ch in text:
        if ch == '"':
            quote = not quote
        elif not quote:
            if ch in "([":
                depth += 1
            elif ch in ")]":
                depth -= 1
            elif ch in seps and depth == 0:
                parts.append("".join(cur))
                cur = []
                continue
        cur.append(ch)
    parts.append("".join(cur))
    return parts


def strip_comment(text: str) -> str:
    """The block without its ``;`` comment (a ``;`` inside a string is kept)."""
    if '"' not in text:
        k = text.find(";")
        return text if k < 0 else text[:k]
    quote = False
    for k, ch in enumerate(text):
        if ch == '"':
            quote = not quote
        elif ch == ";" and not quote:
            return text[:k]
    return text


def fmt(v: float) -> str:
    """A number as a positional decimal the ISO word parser reads (no exponent)."""
    if not math.isfinite(v):
        raise ExpressionError(f"value {v!r} is not finite")
    s = f"{v:.12f}".rstrip("0")
    return s + "0" if s.endswith(".") else s


class Sinumerik:
    """Translator of Sinumerik blocks for one :class:`planner.io.gcode._Reader` (see the module notes)."""

    def __init__(self, reader):
        self.r = reader
        self.vars: dict[str, float | str | None] = {}
        self.declared: set[str] = set()
        self.tool_name = ""
        self.traori = False
        self.vector: dict[str, float] = {}
        #: The CYCLE800 swivel frame (rotation (3, 3), origin (3,) in metres): program -> part frame; None: none.
        self.frame: tuple[np.ndarray, np.ndarray] | None = None
        #: The modal cycle of MCALL (name, DrillCycle), run after every block that moves; None: none.
        self.mcall: tuple[str, DrillCycle] | None = None
        #: Drilling cycles called in this block (run at the position the block reaches).
        self.run_now: list[tuple[str, DrillCycle]] = []

    def fail(self, line: int, construct: str, problem: str) -> NoReturn:
        """Refuse ``construct`` at ``line``: the message reads ``"<file> line <n>, <construct>: <problem>"``."""
        raise InputFileError(self.r.source, line, construct, problem)

    def eval(self, line: int, construct: str, expr: str) -> float:
        e = expr.strip()
        if e and (e[0].isdigit() or e[0] in ".+-") and "_" not in e:
            try:
                return float(e)  # a plain number (the common case)
            except ValueError:
                pass
        try:
            return Expression(expr, self.vars).value()
        except ExpressionError as exc:
            self.fail(line, construct, str(exc))

    # ------------------------------------------------------------------ one block
    def translate(self, line: int, raw: str) -> str:
        """The ISO words of a Sinumerik block ("" when nothing is left for the ISO reader)."""
        text = strip_comment(raw).strip()
        if not text:
            return ""
        if text.startswith("/"):
            text = text[1:].lstrip()
        text = _BLOCK_NUMBER.sub("", text)
        words = split_words(text)
        if not words:
            return ""
        head = words[0].upper()
        label = _LABEL.fullmatch(head) if head.endswith(":") else None
        if label:
            self.fail(line, head, f"label {label.group(1)}: program flow (jumps, labels) is not read")
        if head in _FLOW:
            self.fail(line, head, f"{head}: program flow (IF, loops, jumps) is not read; post without it")
        if head in _FRAME_RESETS and len(words) > 1:
            self.fail(line, head, f"{head} {' '.join(words[1:])}: a programmable frame (shift, rotation, scale or "
                      "mirror) is not read")  # fmt: skip
        if head == "DEF":
            self.define(line, text)
            return ""
        if head == "MCALL":
            self.modal_call(line, words, text)
            return ""
        if head == "PROC":
            self.r.out.event("partno", line, " ".join(words[1:2]), math.nan, text)
            return ""
        if head in ("EXTERN", "GUD", "LUD"):
            self.r.out.event("machine", line, head, math.nan, text)
            return ""
        supa = any(w.upper() in ("SUPA", "G53", "G153") for w in words)
        iso: list[str] = []
        block_abs = self.r.absolute
        for w in words:
            u = w.upper()
            if u in ("G90", "G91"):
                block_abs = u == "G90"
        for w in words:
            iso.extend(self.word(line, w, text, supa, block_abs))
        if supa:
            iso.insert(0, "G53")
        if self.vector:
            got = self.vector
            self.vector = {}
            missing = [w for w in ("A3", "B3", "C3") if w not in got]
            if missing:
                self.fail(line, missing[0], f"tool vector: {', '.join(missing)} missing (give A3, B3 and C3 together)")
            if not self.traori:
                self.fail(line, "A3", "tool vector A3/B3/C3 without TRAORI (the orientation transformation)")
            i, j, k = got["A3"], got["B3"], got["C3"]
            n = math.hypot(i, j, k)
            if not n > 0.0:
                self.fail(line, "A3", "tool vector A3/B3/C3 is zero")
            self.r.vector = (i / n, j / n, k / n)
        return "".join(iso)

    # ------------------------------------------------------------------ CYCLE800, drilling cycles
    def swivel(self, line: int, args: str, text: str) -> None:
        """CYCLE800(_FR, _TC, _ST, _MODE, _X0, _Y0, _Z0, _A, _B, _C, _X1, _Y1, _Z1, _DIR, _FR_I, ...): the swivel
        frame p_part = X0 + R (X1 + p) for the following blocks (R: rotations axis by axis, each about the axis
        already turned, sequence from _MODE); CYCLE800() or one with every offset and angle 0 resets it."""
        out = self.r.out
        parts = [p.strip() for p in _split_top_level(args)] if args.strip() else []

        def value(k: int, pname: str) -> float:
            return 0.0 if k >= len(parts) or not parts[k] else self.eval(line, f"CYCLE800 {pname}", parts[k])

        geo = [value(4 + k, n) for k, n in enumerate(("_X0", "_Y0", "_Z0", "_A", "_B", "_C", "_X1", "_Y1", "_Z1"))]
        fr = value(0, "_FR")
        if fr not in (0.0, 1.0, 2.0, 4.0, 5.0) and parts:
            self.fail(line, "CYCLE800 _FR", f"CYCLE800 _FR={fr:g}: not a retract mode (0, 1, 2, 4, 5)")
        reset = not any(v != 0.0 for v in geo)
        rot, org = np.eye(3), np.zeros(3)
        if not reset:
            st = value(2, "_ST")
            mode = value(3, "_MODE")
            if st != int(st) or int(st) % 10 not in (0, 1):
                self.fail(line, "CYCLE800 _ST", f"CYCLE800 _ST={st:g}: only a new (units digit 0) or additive (1) "
                          "swivel plane is read")  # fmt: skip
            m = int(mode) if mode == int(mode) and 0 <= mode < 256 else -1
            kind = m >> 6 if m >= 0 else -1
            if kind != 0:
                what = {1: "by solid angle", 2: "by projection angle", 3: "direct (rotary axis positions: the plane "
                        "depends on the machine's kinematics data)"}.get(kind, "of an unknown mode")  # fmt: skip
                self.fail(line, "CYCLE800 _MODE", f"CYCLE800 _MODE={mode:g}: a swivel {what} is not read; only axis "
                          "by axis (_MODE bits 7-6 = 0, e.g. 57: X, Y, Z or 27: Z, Y, X) is")  # fmt: skip
            seq = [(m >> (2 * j)) & 3 for j in range(3)]
            if 0 in seq or len(set(seq)) != 3:
                self.fail(line, "CYCLE800 _MODE", f"CYCLE800 _MODE={mode:g}: bits 0-5 name no axis sequence (each pair "
                          "01 X, 10 Y, 11 Z, all three different)")  # fmt: skip
            s = self.r.scale
            rot = np.eye(3)
            for axis, angle in zip(seq, geo[3:6], strict=True):
                rot = rot @ _axis_rotation(axis - 1, math.radians(angle))
            org = s * np.array(geo[0:3]) + rot @ (s * np.array(geo[6:9]))
            if int(st) % 10 == 1 and self.frame is not None:  # additive: in the plane already swivelled
                r0, o0 = self.frame
                rot, org = r0 @ rot, o0 + r0 @ org
        if self.frame is None and reset:
            out.event("frame", line, "CYCLE800", math.nan, text)
            return
        # the tool stays where it is (or was retracted by the cycle: _FR != 0, a machine position): its
        # coordinates in the new frame
        r0, o0 = self.frame if self.frame is not None else (np.eye(3), np.zeros(3))
        pos = self.r.pos
        if fr != 0.0 or any(v != v for v in pos):
            pos[:] = [math.nan] * 3
            self.r.pending_rapid = True
        else:
            pos[:] = (rot.T @ (r0 @ np.array(pos) + o0 - org)).tolist()
        k = out.count
        out.set_frame(k, rot, org)
        out.set_axis(k, 0.0, 0.0, 1.0, False)  # the tool along the plane's z (the cycle aligns it)
        self.frame = None if reset else (rot, org)
        out.event("frame", line, "CYCLE800", math.nan, text)

    def drill_cycle(self, line: int, name: str, args: str) -> DrillCycle:
        """CYCLE81(RTP, RFP, SDIS, DP, DPR) / CYCLE82(RTP, RFP, SDIS, DP, DPR, DTB): absolute levels along the drilling
        axis of the plane (retract plane, reference plane, its safety distance, depth DP or DPR below RFP)."""
        parts = [p.strip() for p in _split_top_level(args)]
        names = ("RTP", "RFP", "SDIS", "DP", "DPR", "DTB")[: 6 if name == "CYCLE82" else 5]
        if len(parts) > len(names):
            self.fail(line, name, f"{name} takes {len(names)} parameters ({', '.join(names)}), got {len(parts)}")
        v: dict[str, float] = {}
        for k, pname in enumerate(names):
            if k < len(parts) and parts[k]:
                v[pname] = self.eval(line, f"{name} {pname}", parts[k])
        for pname in ("RTP", "RFP"):
            if pname not in v:
                self.fail(line, f"{name} {pname}", f"{name}: {pname} is not given")
        s = self.r.scale
        clear = v["RFP"] + abs(v.get("SDIS", 0.0))
        if "DPR" in v:  # the relative depth wins over DP, as on the control
            bottom = v["RFP"] - abs(v["DPR"])
        elif "DP" in v:
            bottom = v["DP"]
        else:
            self.fail(line, f"{name} DP", f"{name}: neither the depth DP nor DPR is given")
        if v["RTP"] < clear:
            self.fail(line, f"{name} RTP", f"{name}: the retract plane RTP={v['RTP']:g} is below the reference plane "
                      f"plus the safety distance ({clear:g})")  # fmt: skip
        dwell = v.get("DTB", 0.0)
        if dwell < 0.0:
            self.fail(line, f"{name} DTB", f"{name}: DTB={dwell:g}: a dwell in spindle revolutions is not read")
        cyc = DrillCycle(name=name, line=line, clearance=clear * s, bottom=bottom * s, retract=v["RTP"] * s,
                         dwell=dwell)
        problem = cyc.problem()
        if problem:
            self.fail(line, name, f"{name}: {problem}")
        return cyc

    def modal_call(self, line: int, words: list[str], text: str) -> None:
        """``MCALL CYCLE81(...)``: the cycle runs after every following block that moves; ``MCALL`` alone ends it."""
        out = self.r.out
        if len(words) == 1:
            self.mcall = None
            out.event("cycle", line, "MCALL", math.nan, text)
            return
        call = _CALL.fullmatch(words[1].upper()) if len(words) == 2 else None
        if call is None:
            self.fail(line, "MCALL", f"MCALL {' '.join(words[1:])}: expected MCALL and one cycle call, e.g. MCALL "
                      "CYCLE81(RTP, RFP, SDIS, DP, DPR)")  # fmt: skip
        cname = call.group(1)
        if cname not in _DRILL_CYCLES:
            what = _REFUSED_DRILL_CYCLES.get(cname, "a cycle whose moves are not in the program")
            self.fail(line, cname, f"MCALL {cname}(...) ({what}) is not read: post the holes as G81-G89 or explicit "
                      "moves (CYCLE81 and CYCLE82 are read)")  # fmt: skip
        w = words[1]
        self.mcall = (cname, self.drill_cycle(line, cname, w[w.index("(") + 1 : w.rindex(")")]))
        out.event("cycle", line, cname, math.nan, text)

    def cycles_after(self, moved: bool) -> list[tuple[str, DrillCycle]]:
        """The drilling cycles to run at the position the block reached: those it called, and the modal one
        if the block moved."""
        run, self.run_now = self.run_now, []
        if moved and self.mcall is not None:
            run.append(self.mcall)
        return run

    def define(self, line: int, text: str) -> None:
        m = re.match(r"\s*DEF\s+(REAL|INT|BOOL|CHAR|STRING\s*\[\s*\d+\s*\]|AXIS|FRAME)\s+(.*)$", text, re.IGNORECASE)
        if not m:
            self.fail(line, "DEF", f"DEF: cannot read the declaration {text.strip()!r} (type REAL, INT, BOOL, CHAR, "
                      "STRING[n], AXIS or FRAME, then names)")  # fmt: skip
        kind = m.group(1).upper()
        for part in _split_top_level(m.group(2)):
            name, eq, expr = part.partition("=")
            name = name.strip().upper()
            if not _IDENT.fullmatch(name) or "[" in part.split("=")[0]:
                self.fail(line, "DEF", f"DEF {kind}: {name!r} is not a variable name the reader reads (no arrays)")
            self.declared.add(name)
            if not eq:
                self.vars[name] = 0.0 if kind in ("REAL", "INT", "BOOL") else None
            elif kind in ("REAL", "INT", "BOOL"):
                self.vars[name] = self.eval(line, f"DEF {kind} {name}", expr)
            else:
                self.vars[name] = expr.strip().strip('"')
        self.r.out.event("machine", line, "DEF", math.nan, text.strip())

    def word(self, line: int, w: str, text: str, supa: bool, block_abs: bool) -> list[str]:
        """ISO words for one Sinumerik word (events and assignments are handled here)."""
        out = self.r.out
        u = w.upper()
        call = _CALL.fullmatch(u) if u.endswith(")") else None
        if call:
            return self.call(line, call.group(1), w[w.index("(") + 1 : w.rindex(")")], text)
        name, eq, expr = w.partition("=")
        name_u = name.strip().upper()
        if eq:
            if name_u in _REFUSED_ADDRESSES:
                self.fail(line, name_u, f"{name_u}= ({_REFUSED_ADDRESSES[name_u]}) is not read")
            if name_u.startswith("$"):
                self.fail(line, name_u, f"{name_u}= writes a system variable (machine state): not read")
            if "[" in name_u:
                self.fail(line, name_u, f"{name_u}= writes an indexed variable: not read")
            if name_u == "T":
                label = expr.strip().strip('"')
                self.tool_name = label
                self.r.tool_next = math.nan
                self.r.tool_label = label
                out.event("tool_select", line, label, math.nan, text)
                return []
            if name_u == "TURN":
                turns = self.eval(line, "TURN", expr)
                if turns != 0.0:
                    self.fail(line, "TURN", f"TURN={turns:g}: full helical turns of G2/G3 are not read")
                out.event("setting", line, "TURN", 0.0, text)
                return []
            if name_u in ("F", "S") and self.r.sinumerik_dwell:
                self.r.sinumerik_dwell = False
                value = self.eval(line, f"G4 {name_u}=", expr)
                seconds = value if name_u == "F" else value * 60.0 / self.r.rpm
                out.event("dwell", line, "G4", seconds, text)
                return []
            if name_u in ("A3", "B3", "C3"):
                self.vector[name_u] = self.eval(line, f"{name_u}=", expr)
                return []
            if name_u == "CR":
                return ["R" + fmt(self.eval(line, "CR", expr))]
            if name_u in ("D", "H"):
                return []
            base = _SPINDLE_M.fullmatch(name_u)
            if base:
                return [base.group(1) + fmt(self.eval(line, name_u, expr))]
            if len(name_u) == 1 and name_u in _SINGLE:
                if supa and name_u in "XYZABC":
                    return [name_u + "0"]  # machine coordinates: the value is not used
                return [name_u + self.address_value(line, name_u, expr, block_abs)]
            self.assign(line, name_u, expr)
            return []
        if u in _REFUSED_WORDS:
            self.fail(line, u, f"{u} ({_REFUSED_WORDS[u]}) is not read")
        if u in _SETTINGS:
            out.event("setting", line, u, math.nan, text)
            return []
        if u in _FRAME_WORDS or _SETTABLE_FRAME.fullmatch(u):
            if u in ("TRAORI", "TRAFOOF"):
                self.traori = u == "TRAORI"
            out.event("frame", line, u, math.nan, text)
            return []
        if u in _FRAME_RESETS:
            out.event("frame", line, u, math.nan, text)
            return []
        if u == "ORIRESET":
            if not self.traori:
                self.fail(line, "ORIRESET", "ORIRESET without TRAORI (the orientation transformation)")
            self.vector = {"A3": 0.0, "B3": 0.0, "C3": 1.0}  # the rotary axes at zero: the tool along +Z
            return []
        if u in ("SUPA", "G153"):
            return []
        if u in ("RET", "M17"):
            out.event("end", line, u, math.nan, text)
            return []
        if u in ("G70", "G700"):
            return ["G20"]
        if u in ("G71", "G710"):
            return ["G21"]
        if u in ("G4", "G04"):
            self.r.sinumerik_dwell = True
            return []
        if self.r.sinumerik_dwell and _DWELL_WORD.fullmatch(u):
            self.r.sinumerik_dwell = False
            value = float(u[1:])
            seconds = value if u[0] == "F" else value * 60.0 / self.r.rpm
            out.event("dwell", line, "G4", seconds, text)
            return []
        parts = _COMPACT.findall(u)
        if parts and "".join(a + b for a, b in parts) == u:
            return [self.compact(line, a, b, text) for a, b in parts]
        if _IDENT.fullmatch(u):
            self.fail(line, u, f"{u}: a Sinumerik instruction the reader does not know; the program cannot be "
                      "planned without knowing what it does")  # fmt: skip
        self.fail(line, u[:20], f"cannot read {w!r}")
        return []

    def compact(self, line: int, letters: str, number: str, text: str) -> str:
        """A word written ``LETTERS<number>`` (``G1``, ``X10``, ``S1000``)."""
        if letters in _REFUSED_ADDRESSES or letters + number in _REFUSED_WORDS:
            key = letters if letters in _REFUSED_ADDRESSES else letters + number
            what = _REFUSED_ADDRESSES.get(key) or _REFUSED_WORDS[key]
            self.fail(line, key, f"{key} ({what}) is not read")
        if letters == "G" and f"G{number}" in _SETTINGS:
            self.r.out.event("setting", line, f"G{number}", math.nan, text)
            return ""
        if letters == "G" and (f"G{number}" in _FRAME_WORDS or _SETTABLE_FRAME.fullmatch("G" + number)):
            self.r.out.event("frame", line, f"G{number}", math.nan, text)
            return ""
        if letters in ("G", "M", "T", "D", "H", "N"):
            if letters == "G" and number in ("70", "700"):
                return "G20"
            if letters == "G" and number in ("71", "710"):
                return "G21"
            if letters == "G" and number in ("4", "04"):
                self.r.sinumerik_dwell = True
                return ""
            if letters in ("T",):
                self.r.tool_label = ""
            return letters + number
        if letters in ("F", "S") and self.r.sinumerik_dwell:
            self.r.sinumerik_dwell = False
            value = float(number)
            seconds = value if letters == "F" else value * 60.0 / self.r.rpm
            self.r.out.event("dwell", line, "G4", seconds, text)
            return ""
        if letters == "CR":
            return "R" + number
        if letters == "R" and self.r.motion not in (2, 3):
            self.fail(line, f"R{number}", f"R{number}: an R parameter needs an assignment (R{number}=...)")
        if len(letters) == 1:
            return letters + number
        if letters[0] in "SM" and letters[1:].isdigit():
            return letters[0] + number
        self.fail(line, letters, f"{letters}{number}: address {letters} is not read")
        return ""

    def address_value(self, line: int, name: str, expr: str, block_abs: bool) -> str:
        """The ISO number for ``NAME=expr`` (IC/AC/DC/ACP/ACN resolved against the reader's position)."""
        e = expr.strip()
        m = _MODE_CALL.fullmatch(e) if e.endswith(")") else None
        mode = None
        if m:
            mode, e = m.group(1).upper(), m.group(2)
        v = self.eval(line, f"{name}=", e)
        r = self.r
        if mode is None or (mode == "AC" and block_abs and name in "XYZABC") or (mode == "IC" and not block_abs):
            return fmt(v)
        if name in "IJK":
            if mode != "AC":
                self.fail(line, name, f"{name}={mode}(...): only AC (absolute centre) is read for arc centres")
            k = "IJK".index(name)
            cur = r.pos[k]
            if cur != cur:
                self.fail(line, name, f"{name}=AC(...): the start of the arc is not known")
            return fmt(v - cur / r.scale)
        if name in "XYZ":
            k = "XYZ".index(name)
            cur = r.pos[k] / r.scale
        elif name in r.rot_words:
            if mode in ("DC", "ACP", "ACN"):
                if not block_abs:
                    self.fail(line, name, f"{name}={mode}(...) in a G91 block is not read")
                return fmt(v)
            cur = math.degrees(r.angles[r.rot_words.index(name)])
        else:
            if v != 0.0:
                self.fail(line, name, f"{name}={mode}(...): {name} is not an axis of the machine")
            return fmt(v)
        if cur != cur:
            self.fail(line, name, f"{name}={mode}(...): the current {name} is not known")
        if mode == "IC":
            return fmt(cur + v)  # absolute value in this G90 block
        if mode in ("DC", "ACP", "ACN"):
            self.fail(line, name, f"{name}={mode}(...) is for rotary axes")
        return fmt(v - cur)  # AC in a G91 block: the increment

    def assign(self, line: int, name: str, expr: str) -> None:
        if not _IDENT.fullmatch(name):
            self.fail(line, name[:20], f"{name}=: not an address or a variable name")
        if name not in self.declared and not _R_PARAM.fullmatch(name):
            if not name.startswith("_"):
                self.fail(line, name, f"{name}=: {name} is neither an address the reader knows nor a declared "
                          "variable (DEF)")  # fmt: skip
            if name not in self.vars:
                self.r.warn.warn("undeclared variables", line, f"variable {name} assigned without DEF (a global user "
                                 "variable?): read as a REAL")  # fmt: skip
        value = expr.strip()
        if value.startswith('"'):
            self.vars[name] = value.strip('"')
        else:
            self.vars[name] = self.eval(line, f"{name}=", value)

    def call(self, line: int, name: str, args: str, text: str) -> list[str]:
        out = self.r.out
        if name == "MSG":
            msg = args.strip()
            out.event("insert", line, msg.strip('"'), math.nan, text)
            return []
        if name == "CYCLE832":
            parts = _split_top_level(args)
            tol = math.nan
            if parts and parts[0].strip():
                try:
                    tol = Expression(parts[0], self.vars).value() * self.r.scale
                except ExpressionError:
                    tol = math.nan
            out.event("setting", line, "CYCLE832", tol, text)
            return []
        if name == "CYCLE800":
            self.swivel(line, args, text)
            return []
        if name in _DRILL_CYCLES:
            self.run_now.append((name, self.drill_cycle(line, name, args)))
            out.event("cycle", line, name, math.nan, text)
            return []
        if name in ("WORKPIECE", "FGROUP", "FGREF", "SOFTA", "BRISKA"):
            out.event("setting", line, name, math.nan, text)
            return []
        if name == "ORIRESET":
            if args.strip():
                self.fail(line, "ORIRESET", f"ORIRESET({args.strip()}) turns the rotary axes to given angles: not "
                          "read (the tool axis they mean depends on the machine)")  # fmt: skip
            return self.word(line, "ORIRESET", text, False, True)
        if name == "TRAORI":
            self.traori = True
            out.event("frame", line, "TRAORI", math.nan, text)
            return []
        if name in _FRAME_RESETS:
            if args.strip():
                self.fail(line, name, f"{name}({args.strip()}) moves the frame: not read")
            out.event("frame", line, name, math.nan, text)
            return []
        if name in _REFUSED_DRILL_CYCLES:
            self.fail(line, name, f"{name}(...) ({_REFUSED_DRILL_CYCLES[name]}) is not read: post the holes as G81-G89 "
                      "or explicit moves (CYCLE81 and CYCLE82 are read)")  # fmt: skip
        if name.startswith("CYCLE") or name.startswith("POCKET") or name.startswith("SLOT") or name == "MCALL":
            self.fail(line, name, f"{name}(...): a Sinumerik technology cycle whose moves are not in the program; "
                      "post it as explicit moves")  # fmt: skip
        self.fail(line, name, f"{name}(...): a call the reader does not know; its moves are not in the program")
        return []


def _axis_rotation(axis: int, angle: float) -> np.ndarray:
    """Rotation (3, 3) by ``angle`` (rad) about coordinate axis 0 (X), 1 (Y) or 2 (Z), right-handed."""
    c, s = math.cos(angle), math.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R
