"""Splitting a CAM toolpath into passes, rapid moves and in-place reorientations.

A CAM job is not one smooth curve: it is a sequence of cutting passes joined by rapid (positioning)
moves, with sharp corners the CAM system meant and tool-axis jumps between operations. This module
walks a :class:`~planner.io.Toolpath` once, in file order, and returns the moves the robot makes:

- :class:`CutPass`: a run of cutting moves between two stops. A pass ends at every rapid, tool
  change and operation boundary, at every corner sharper than ``corner_deg`` between consecutive
  chords (the path stops there: the two passes share the corner point), and before a tool-axis jump
  larger than ``axis_jump_deg`` along a chord or at a point.
- :class:`RapidMove`: one rapid record of the file as an explicit straight move (retract, traverse or
  approach), planned at rapid speed, never smoothed into a cut.
- :class:`Reorientation`: the tool turns in place from one axis to another (an axis jump or flip at a
  pass boundary, or a zero-length move that only changes the axis).
- :class:`Dwell`: the tool waits at rest where it is (APT ``DELAY``/``DWELL``, G-code ``G04``, the dwell of a
  drilling cycle at the hole bottom) for the record's seconds; a pass ends before it and the next starts
  after it, at the same point.
- :class:`Skipped`: a move with nothing to do (a pass whose points all coincide, a zero-length rapid),
  kept with the reason and its source lines so that nothing is dropped silently.

Consecutive duplicate points inside a pass (same position, same axis) are merged; each pass counts
how many it merged. Arcs (APT ``CIRCLE``, G-code ``G02/G03``) are linearised first with
:func:`planner.io.linearize_arcs`, so every move is a chord of the CAM polyline.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from planner.errors import PlannerError
from planner.validation import check_in_range

#: Default corner threshold: consecutive chords turning more than this (degrees) end a pass.
DEFAULT_CORNER_DEG = 60.0
#: Default axis-jump threshold (degrees): a larger tool-axis change is made by turning in place.
#: It cannot exceed 90 degrees, the flip limit of :func:`planner.frames.tool_frames`.
DEFAULT_AXIS_JUMP_DEG = 90.0
#: Two consecutive points closer than this (metres) are the same point.
DEFAULT_DUPLICATE_TOL = 1e-9
#: Two unit axes closer than this angle (radians) are the same axis.
AXIS_SAME_RAD = 1e-9


class CamInputError(PlannerError):
    """Bad CAM planning input: the message names the parameter, or the file and line of the data."""


@dataclass(frozen=True, eq=False)
class CutPass:
    """A run of cutting moves the robot makes without stopping.

    Attributes
    ----------
    index : int
        Number of the pass in the job (0-based, cutting passes only).
    points : ndarray (m, 3)
        CAM points of the pass in the part frame, metres (consecutive duplicates merged), m >= 2.
    axes : ndarray (m, 3) or None
        CAM tool axis at each point (unit, from the tool tip towards the spindle, the CAM
        convention), or None when the file has no axes. After an axis jump the first point carries
        the new axis (the jump is a :class:`Reorientation` before the pass).
    axis_given : ndarray (m,) of bool or None
        True where the file gave the axis at that point, False where it was inherited (modal).
    feeds : ndarray (m,)
        Feed of the motion into each point, m/s (NaN: unknown; ``feeds[0]`` is not used).
    lines : ndarray (m,) of int
        1-based source line of each point.
    source_index : ndarray (m,) of int
        Index of each point in the (arc-linearised) toolpath.
    operation : str
        Name of the CAM operation the pass belongs to ("" if the file names none).
    tool : float
        Tool number in use (NaN if the file names none).
    start_reason, end_reason : str
        Why the pass starts and ends: "start", "rapid", "corner", "tool change", "operation",
        "axis jump", "reorientation", "dwell", "end".
    start_corner_deg, end_corner_deg : float
        Turning angle (degrees) of the corner the pass starts or ends at (NaN if not a corner).
    merged : int
        Consecutive duplicate points merged into one.
    """

    index: int
    points: np.ndarray
    axes: np.ndarray | None
    axis_given: np.ndarray | None
    feeds: np.ndarray
    lines: np.ndarray
    source_index: np.ndarray
    operation: str = ""
    tool: float = math.nan
    start_reason: str = "start"
    end_reason: str = "end"
    start_corner_deg: float = math.nan
    end_corner_deg: float = math.nan
    merged: int = 0

    kind = "cut"

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"index": self.index, "points": self.points, "axes": self.axes, "axis_given": self.axis_given,
                "feeds": self.feeds, "lines": self.lines, "source_index": self.source_index,
                "operation": self.operation, "tool": self.tool, "start_reason": self.start_reason,
                "end_reason": self.end_reason, "start_corner_deg": self.start_corner_deg,
                "end_corner_deg": self.end_corner_deg, "merged": self.merged}

    @classmethod
    def from_state(cls, state: dict) -> CutPass:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)

    def __len__(self) -> int:
        return self.points.shape[0]

    @property
    def first_line(self) -> int:
        """Source line of the first point."""
        return int(self.lines[0])

    @property
    def last_line(self) -> int:
        """Source line of the last point."""
        return int(self.lines[-1])

    @property
    def polyline_length(self) -> float:
        """Length of the CAM polyline, metres."""
        return float(np.linalg.norm(np.diff(self.points, axis=0), axis=1).sum())

    def describe(self) -> str:
        """One line for a person: pass number, source lines, operation."""
        op = f" ({self.operation})" if self.operation else ""
        return f"pass {self.index}{op}, lines {self.first_line}-{self.last_line}"


@dataclass(frozen=True, eq=False)
class RapidMove:
    """A straight positioning move at rapid speed (one rapid record of the file).

    Attributes
    ----------
    start, end : ndarray (3,)
        End points in the part frame, metres.
    start_axis, end_axis : ndarray (3,) or None
        CAM tool axes at the ends (tip towards spindle); the axis turns along the great circle
        between them during the move. None when the file has no axes.
    line : int
        Source line of the rapid's target record.
    source_index : int
        Index of the target point in the (arc-linearised) toolpath.
    reason : str
        "rapid" (the file says so) or why a cutting record became a positioning move.
    """

    start: np.ndarray
    end: np.ndarray
    start_axis: np.ndarray | None
    end_axis: np.ndarray | None
    line: int
    source_index: int
    reason: str = "rapid"

    kind = "rapid"

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"start": self.start, "end": self.end, "start_axis": self.start_axis, "end_axis": self.end_axis,
                "line": self.line, "source_index": self.source_index, "reason": self.reason}

    @classmethod
    def from_state(cls, state: dict) -> RapidMove:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)

    @property
    def length(self) -> float:
        return float(np.linalg.norm(self.end - self.start))


@dataclass(frozen=True, eq=False)
class Reorientation:
    """The tool turns in place about the tool tip from one axis to another.

    Attributes
    ----------
    point : ndarray (3,)
        Where (part frame, metres).
    axis_from, axis_to : ndarray (3,)
        CAM tool axes before and after (tip towards spindle).
    line : int
        Source line of the record that asks for the new axis.
    reason : str
        "axis jump" (a jump larger than the threshold along a chord or at a rapid) or "turn in place"
        (a zero-length move that only changes the axis).
    """

    point: np.ndarray
    axis_from: np.ndarray
    axis_to: np.ndarray
    line: int
    reason: str = "axis jump"

    kind = "reorientation"

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"point": self.point, "axis_from": self.axis_from, "axis_to": self.axis_to, "line": self.line,
                "reason": self.reason}

    @classmethod
    def from_state(cls, state: dict) -> Reorientation:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)

    @property
    def angle(self) -> float:
        """Angle turned, radians."""
        return float(math.acos(min(1.0, max(-1.0, float(self.axis_from @ self.axis_to)))))


@dataclass(frozen=True, eq=False)
class Dwell:
    """The tool waits at rest where it is, for ``seconds`` (a dwell record of the file).

    Attributes
    ----------
    point : ndarray (3,)
        Where (part frame, metres): the point the tool reached before the record.
    seconds : float
        How long, s (> 0).
    line : int
        Source line of the dwell record.
    name : str
        How the file names it ("G04", "G82", "CYCLE/DRILL,DWELL", ...).
    """

    point: np.ndarray
    seconds: float
    line: int
    name: str = ""

    kind = "dwell"

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"point": self.point, "seconds": self.seconds, "line": self.line, "name": self.name}

    @classmethod
    def from_state(cls, state: dict) -> Dwell:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)


@dataclass(frozen=True, eq=False)
class Skipped:
    """A move of the file that asks for no motion, kept with the reason.

    Attributes
    ----------
    point : ndarray (3,)
        Where the tool is.
    first_line, last_line : int
        Source lines of the records.
    reason : str
        What was skipped and why.
    """

    point: np.ndarray
    first_line: int
    last_line: int
    reason: str

    kind = "skipped"

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"point": self.point, "first_line": self.first_line, "last_line": self.last_line, "reason": self.reason}

    @classmethod
    def from_state(cls, state: dict) -> Skipped:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)


@dataclass(frozen=True, eq=False)
class Segmentation:
    """The moves of a toolpath in order, and the splitting figures.

    Attributes
    ----------
    moves : tuple
        :class:`CutPass`, :class:`RapidMove`, :class:`Reorientation`, :class:`Dwell` and :class:`Skipped` in
        order.
    corners : int
        Corners sharper than the threshold found inside cutting runs (each one split a pass).
    corner_deg, axis_jump_deg : float
        The thresholds used, degrees.
    source : str
        Name of the file.
    """

    moves: tuple
    corners: int
    corner_deg: float
    axis_jump_deg: float
    source: str = "<toolpath>"
    counts: dict = field(default_factory=dict)

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"moves": self.moves, "corners": self.corners, "corner_deg": self.corner_deg,
                "axis_jump_deg": self.axis_jump_deg, "source": self.source, "counts": self.counts}

    @classmethod
    def from_state(cls, state: dict) -> Segmentation:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)

    @property
    def passes(self) -> tuple[CutPass, ...]:
        """The cutting passes, in order."""
        return tuple(m for m in self.moves if isinstance(m, CutPass))


def check_threshold(value, name: str, lo: float, hi: float) -> float:
    """A float in (lo, hi], or CamInputError naming ``name``."""
    return check_in_range(value, name, lo, hi, CamInputError)


class _Builder:
    """Open pass state while walking the toolpath."""

    def __init__(self, tp, op_at, tool_at):
        self.tp = tp
        self.op_at = op_at
        self.tool_at = tool_at
        self.moves: list = []
        self.idx: list[int] = []  # toolpath indices of the open pass
        self.first_axis: np.ndarray | None = None
        self.start_reason = "start"
        self.start_corner = math.nan
        self.merged = 0
        self.merged_line = 0  # source line of the last merged record
        self.n_pass = 0
        self.degenerate = 0

    def open(self, i: int, reason: str, corner: float = math.nan, first_axis=None) -> None:
        self.idx = [i]
        self.start_reason, self.start_corner, self.merged = reason, corner, 0
        self.first_axis = first_axis

    def merge(self, i: int) -> None:
        """Point i coincides with the open pass's last point (same axis): merge it."""
        self.merged += 1
        self.merged_line = int(self.tp.lines[i])

    def close(self, reason: str, corner: float = math.nan) -> None:
        idx = self.idx
        self.idx = []
        if len(idx) < 2:
            if idx and self.merged:  # cutting moves that all end where they start
                self.degenerate += 1
                first = int(self.tp.lines[idx[0]])
                self.moves.append(Skipped(self.tp.points[idx[0]].copy(), first, self.merged_line,
                                          f"{self.merged} cutting move(s) of zero length (lines {first}-"
                                          f"{self.merged_line}): all points coincide, nothing to cut"))
            return  # a lone point between two stops: no cutting move
        tp = self.tp
        ix = np.asarray(idx)
        axes = given = None
        if tp.axes is not None:
            axes = tp.axes[ix].copy()
            given = tp.axis_given[ix].copy()
            if self.first_axis is not None:
                axes[0] = self.first_axis
        self.moves.append(
            CutPass(
                index=self.n_pass,
                points=tp.points[ix],
                axes=axes,
                axis_given=given,
                feeds=tp.feeds[ix],
                lines=tp.lines[ix],
                source_index=ix,
                operation=self.op_at[ix[-1]],
                tool=float(self.tool_at[ix[-1]]),
                start_reason=self.start_reason,
                end_reason=reason,
                start_corner_deg=self.start_corner,
                end_corner_deg=corner,
                merged=self.merged,
            )
        )
        self.n_pass += 1


def _modal_labels(tp) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """Per point: operation name, tool number; per move into i: starts an operation / a tool change."""
    n = len(tp)
    op_at = [""] * n
    tool_at = np.full(n, math.nan)
    op_start = np.zeros(n + 1, dtype=bool)
    tool_start = np.zeros(n + 1, dtype=bool)
    cur_op, cur_tool, k = "", math.nan, 0
    events = sorted((e for e in tp.events if e.kind in ("operation", "tool_change")), key=lambda e: e.index)
    for e in events:
        while k < min(e.index, n):
            op_at[k], tool_at[k] = cur_op, cur_tool
            k += 1
        if e.kind == "operation":
            cur_op = e.name
            op_start[e.index] = True
        else:
            cur_tool = e.value
            tool_start[e.index] = True
    while k < n:
        op_at[k], tool_at[k] = cur_op, cur_tool
        k += 1
    return op_at, tool_at, op_start[:n], tool_start[:n]


def _dwells(tp) -> dict[int, list]:
    """{event index: dwell events there} for the dwells of positive, finite length (a dwell of 0 s is no wait)."""
    out: dict[int, list] = {}
    for e in tp.events:
        if e.kind == "dwell" and math.isfinite(e.value) and e.value > 0.0:
            out.setdefault(max(int(e.index), 0), []).append(e)
    return out


def split_passes(
    toolpath,
    *,
    corner_deg: float = DEFAULT_CORNER_DEG,
    axis_jump_deg: float = DEFAULT_AXIS_JUMP_DEG,
    duplicate_tol: float = DEFAULT_DUPLICATE_TOL,
) -> Segmentation:
    """Split a toolpath into cutting passes, rapid moves and reorientations.

    Parameters
    ----------
    toolpath : planner.io.Toolpath
        A reader's output with its arcs linearised (:func:`planner.io.linearize_arcs`; an arc left as
        one chord is planned as that chord).
    corner_deg : float, default 60
        A pass ends at a vertex where consecutive chords turn by more than this (degrees, in (0, 180]).
    axis_jump_deg : float, default 90
        A tool-axis change larger than this (degrees, in (0, 90]) along a cutting chord, at a rapid
        or at a point is made by turning in place (:class:`Reorientation`) at the pass start.
    duplicate_tol : float, default 1e-9
        Consecutive points closer than this (metres) are one point.

    Returns
    -------
    Segmentation

    Raises
    ------
    CamInputError
        A threshold out of range (naming it), an empty toolpath.
    """
    corner_deg = check_threshold(corner_deg, "corner_deg", 0.0, 180.0)
    axis_jump_deg = check_threshold(axis_jump_deg, "axis_jump_deg", 0.0, 90.0)
    duplicate_tol = check_threshold(duplicate_tol, "duplicate_tol", 0.0, math.inf)
    tp = toolpath
    n = len(tp)
    if n == 0:
        raise CamInputError(f"{tp.source}: the toolpath has no points")
    P = tp.points
    A = tp.axes
    d = np.diff(P, axis=0)
    h = np.linalg.norm(d, axis=1)
    unit = d / np.where(h > 0, h, 1.0)[:, None]
    if A is not None:
        ax_step = 2.0 * np.arctan2(np.linalg.norm(A[1:] - A[:-1], axis=1), np.linalg.norm(A[1:] + A[:-1], axis=1))
    else:
        ax_step = np.zeros(max(n - 1, 0))
    # turn[i]: angle between chord i - 1 -> i and the last nonzero chord before it (0 if none)
    nz = h > duplicate_tol
    last_nz = np.maximum.accumulate(np.where(nz, np.arange(n - 1), -1)) if n > 1 else np.zeros(0, int)
    prev = np.concatenate(([-1], last_nz[:-1])) if n > 1 else last_nz
    up = unit[np.maximum(prev, 0)]
    turn_at = 2.0 * np.arctan2(np.linalg.norm(unit - up, axis=1), np.linalg.norm(unit + up, axis=1))
    turn_at = np.concatenate(([0.0], np.where(prev >= 0, turn_at, 0.0))).tolist()
    ax_step = np.concatenate(([0.0], ax_step)).tolist()
    h_list = np.concatenate(([0.0], h)).tolist()
    rapid = tp.rapid.tolist()
    jump = math.radians(axis_jump_deg)
    corner = math.radians(corner_deg)
    op_at, tool_at, op_start, tool_start = _modal_labels(tp)
    b = _Builder(tp, op_at, tool_at)
    corners = 0
    counts = {"merged": 0, "axis_jumps": 0, "zero_rapids": 0, "degenerate": 0}
    dwells = _dwells(tp)
    for e in dwells.pop(0, ()):  # before any motion: where the tool starts
        b.moves.append(Dwell(P[0].copy(), e.value, e.line, e.name))
    b.open(0, "start")
    has_dir = False  # the open pass has a nonzero chord (so a corner can be measured)
    lines = tp.lines.tolist()
    tool_start, op_start = tool_start.tolist(), op_start.tolist()
    for i in range(1, n):
        step = ax_step[i]
        line = lines[i]
        if i in dwells:  # the tool waits at the point it has reached: the pass stops there and goes on after
            k = b.idx[-1]
            b.close("dwell")
            b.moves += [Dwell(P[k].copy(), e.value, e.line, e.name) for e in dwells.pop(i)]
            b.open(k, "dwell")
            has_dir = False
        if rapid[i] or tool_start[i]:
            reason = "rapid" if rapid[i] else "tool change"
            b.close(reason)
            has_dir = False
            if h_list[i] <= duplicate_tol:
                if A is not None and step > AXIS_SAME_RAD:
                    b.moves.append(Reorientation(P[i].copy(), A[i - 1].copy(), A[i].copy(), line, "turn in place"))
                else:
                    counts["zero_rapids"] += 1
                    b.moves.append(Skipped(P[i].copy(), lines[i - 1], line,
                                           f"{reason} move of zero length to line {line}: nothing to do"))
            elif A is not None and step > jump:
                counts["axis_jumps"] += 1
                b.moves.append(RapidMove(P[i - 1].copy(), P[i].copy(), A[i - 1].copy(), A[i - 1].copy(), line, i,
                                         reason))
                b.moves.append(Reorientation(P[i].copy(), A[i - 1].copy(), A[i].copy(), line, "axis jump"))
            else:
                b.moves.append(RapidMove(P[i - 1].copy(), P[i].copy(), None if A is None else A[i - 1].copy(),
                                         None if A is None else A[i].copy(), line, i, reason))
            b.open(i, reason)
            continue
        # a cutting move from the open pass's last point (i - 1, or the point i - 1 was merged into) to i
        if op_start[i] and len(b.idx) > 1:
            k = b.idx[-1]
            b.close("operation")
            b.open(k, "operation")
            has_dir = False
        if h_list[i] <= duplicate_tol:
            if A is not None and step > AXIS_SAME_RAD:
                b.close("reorientation")
                b.moves.append(Reorientation(P[i].copy(), A[i - 1].copy(), A[i].copy(), line, "turn in place"))
                b.open(i, "reorientation")
                has_dir = False
            else:
                b.merge(i)
                counts["merged"] += 1
            continue
        if A is not None and step > jump:
            counts["axis_jumps"] += 1
            k = b.idx[-1]
            b.close("axis jump")
            b.moves.append(Reorientation(P[k].copy(), A[i - 1].copy(), A[i].copy(), line, "axis jump"))
            b.open(k, "axis jump", first_axis=A[i].copy())
        elif has_dir:
            turn = turn_at[i]
            if turn > corner:
                corners += 1
                deg = math.degrees(turn)
                k = b.idx[-1]
                b.close("corner", deg)
                b.open(k, "corner", deg)
        b.idx.append(i)
        has_dir = True
    b.close("end")
    b.moves += [Dwell(P[-1].copy(), e.value, e.line, e.name) for k in sorted(dwells) for e in dwells[k]]
    counts["degenerate"] = b.degenerate
    counts["dwells"] = sum(1 for m in b.moves if isinstance(m, Dwell))
    return Segmentation(tuple(b.moves), corners, corner_deg, axis_jump_deg, tp.source, counts)

