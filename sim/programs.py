"""Programs sent to the script ports: framing of the byte stream, and recognition of ur_rtde's script.

The controller reads URScript from ports 30001-30003 as a stream: a program is a top-level
``def name():`` (or ``sec name():``) block up to its closing top-level ``end``; any other top-level
line is a one-line program of its own. ur_rtde 1.6.5 (src/script_client.cpp) sends its control script
``def rtde_control(): ... end`` with the register offsets injected after ``# float register offset`` /
``# int register offset`` and, for path moves, ``signal_async_progress(i)`` and
``movel(p[...],a=..,v=..,r=..)`` / ``movej([...],...)`` / ``movep(...)`` lines after
``# inject move path`` (src/rtde_control_interface.cpp, ``PathEntry::toScriptCode``).

Program size: the simulated controller refuses a program larger than :data:`MAX_PROGRAM_BYTES` whole, as a
program that does not compile (nothing of it runs, the message names its size and the limit). UR documents no
limit for the script ports; users report CB-Series controllers that ignore programs of 1,000-2,500 moves and one
that crashed on 18 MB; RoboDK's UR post-processor cut programs into pages of 5,000 lines (about 350 kB). The
simulator takes 250,000 bytes (ur_rtde 1.6.5's control script, 42 kB and 1175 lines, runs), the limit
:data:`planner.export.job_script.MAX_PROGRAM_BYTES` keeps the exported programs to.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

CONTROL_SCRIPT_NAME = "rtde_control"
_CONTROL_MARKERS = ("# NODE_CONTROL_LOOP_BEGINS", "def signal_ready():", "def process_cmd(cmd):")
_FLOAT_OFFSET = re.compile(r"# float register offset\n\s*(\d+)")
_INT_OFFSET = re.compile(r"# int register offset\n\s*(\d+)")
_PATH_START = "# inject move path\n"
_NUM = r"[-+0-9.eEinfa]+"
_MOVE = re.compile(
    rf"^\s*(movej|movel|movep)\((p?)\[([^\]]*)\]\s*,\s*a\s*=\s*({_NUM})\s*,\s*v\s*=\s*({_NUM})\s*,\s*r\s*=\s*({_NUM})\s*\)\s*$"
)
_PROGRESS = re.compile(r"^\s*signal_async_progress\((\d+)\)\s*$")
_HEAD = re.compile(r"^(def|sec)\s+([A-Za-z_][A-Za-z_0-9]*)\s*\(\s*\)\s*:\s*$")
#: The largest program the simulated controller takes on its script ports, bytes (see the module doc).
MAX_PROGRAM_BYTES = 250_000


class ProgramError(ValueError):
    """A program the controller cannot compile; the message names the line."""


@dataclass(frozen=True)
class PathMove:
    """One injected path entry: ``kind`` movej/movel/movep, target (6,), a, v, r; ``pose`` for p[...]."""

    kind: str
    target: tuple[float, ...]
    a: float
    v: float
    r: float
    pose: bool


@dataclass
class Program:
    """A framed program: its text, name, and for ur_rtde's script the register offsets and path."""

    text: str
    name: str
    is_control_script: bool = False
    int_offset: int = 0
    float_offset: int = 0
    path: list[PathMove] = field(default_factory=list)


class ProgramFramer:
    """Cuts a script port's byte stream into whole programs (feed bytes, get programs)."""

    def __init__(self) -> None:
        self._pending = ""
        self._block: list[str] | None = None

    def feed(self, data: bytes) -> list[str]:
        """Add received bytes; return the programs completed by them (texts, in order)."""
        self._pending += data.decode("utf-8", "replace")
        *lines, self._pending = self._pending.split("\n")
        done: list[str] = []
        for line in lines:
            if self._block is not None:
                self._block.append(line)
                if line.rstrip() == "end":
                    done.append("\n".join(self._block) + "\n")
                    self._block = None
            elif _HEAD.match(line.rstrip()):
                self._block = [line]
            elif line.strip() and not line.lstrip().startswith("#"):
                done.append(line + "\n")
        return done


def _float(text: str, where: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ProgramError(f"{where}: {text!r} is not a number") from None


def _parse_path(text: str) -> list[PathMove]:
    i = text.find(_PATH_START)
    if i < 0:
        return []
    moves: list[PathMove] = []
    for n, line in enumerate(text[i + len(_PATH_START) :].split("\n")):
        if line.strip() == "end" or line.strip() == "":
            break
        if _PROGRESS.match(line):
            continue
        m = _MOVE.match(line)
        if not m:
            raise ProgramError(f"move path line {n + 1}: cannot compile {line.strip()!r}")
        kind, p, values, a, v, r = m.groups()
        where = f"move path line {n + 1}"
        target = tuple(_float(x, where) for x in values.split(","))
        if len(target) != 6:
            raise ProgramError(f"{where}: expected 6 values in the target, got {len(target)}")
        moves.append(PathMove(kind, target, _float(a, where), _float(v, where), _float(r, where), p == "p"))
    return moves


def head_of(text: str) -> str | None:
    """The name of a ``def name():`` / ``sec name():`` program, None for a one-line program."""
    head = _HEAD.match(text.split("\n", 1)[0].rstrip())
    return head.group(2) if head else None


def parse_program(text: str) -> Program:
    """Recognize a framed program; ur_rtde's control script gets its offsets and injected path. ProgramError for
    a program larger than :data:`MAX_PROGRAM_BYTES`."""
    size = len(text.encode("utf-8", "replace"))
    if size > MAX_PROGRAM_BYTES:
        raise ProgramError(f"program too large: {size} bytes, {text.count(chr(10))} lines (this controller takes at "
                           f"most {MAX_PROGRAM_BYTES} bytes per program); nothing of it runs")
    first = text.split("\n", 1)[0].rstrip()
    head = _HEAD.match(first)
    name = head.group(2) if head else "<line>"
    prog = Program(text=text, name=name)
    if head and name == CONTROL_SCRIPT_NAME and all(mark in text for mark in _CONTROL_MARKERS):
        prog.is_control_script = True
        fo, io = _FLOAT_OFFSET.search(text), _INT_OFFSET.search(text)
        prog.float_offset = int(fo.group(1)) if fo else 0
        prog.int_offset = int(io.group(1)) if io else 0
        prog.path = _parse_path(text)
    return prog
