"""What a toolpath reader returns: the CAM points in file order, their tool axes, feeds and events.

A :class:`Toolpath` keeps everything the later stages need to split a job into passes (rapid flags,
tool changes, operation names, arcs, source lines) without deciding anything about passes itself.
Units are SI: metres, metres per second, radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: Kinds of :class:`Event` the readers emit (an :class:`Arc` has kind ``"arc"``).
EVENT_KINDS = (
    "operation",  # start of a CAM operation; name = operation name (NX TOOL PATH, G-code OPER comment)
    "operation_end",  # END-OF-PATH
    "tool_change",  # LOAD/TOOL, LOADTL, M06; value = tool number
    "tool_select",  # SELECT/TOOL, T word without M06 (pre-selection, no change yet); value = tool number
    "tool_data",  # TLDATA, CUTTER: geometry of the tool, as written
    "spindle",  # SPINDL, M03/M04/M05; value = speed in rad/s (0 = off, NaN = not given)
    "coolant",  # COOLNT, M07/M08/M09; name = ON/OFF/FLOOD/MIST/...
    "cutcom",  # CUTCOM, G40/G41/G42; name = LEFT/RIGHT/OFF
    "frame",  # MSYS, CSYS, TRNTYP; G234/G49 (TCPC), G254/G255 (DWO), G54.. (work offsets)
    "units",  # UNITS/UNIT, G20/G21; name = MM/INCH
    "multax",  # MULTAX
    "cycle",  # CYCLE (APT), G81..G89 (G-code): the following points are hole positions
    "home",  # GOHOME, G28, G53: a move to a machine position outside the part frame
    "insert",  # INSERT, PPRINT: free text for the post-processor or operator
    "partno",  # PARTNO, O program name
    "machine",  # other post-processor commands kept as written (STOP, DELAY, M codes, vendor records)
    "listing",  # listing header or trailer of a CAM "Information listing"
    "end",  # FINI, M02/M30
)


@dataclass(frozen=True, slots=True)
class Event:
    """A non-motion record of the file, anchored between two points.

    Attributes
    ----------
    kind : str
        One of :data:`EVENT_KINDS`.
    line : int
        1-based line of the record in the file.
    index : int
        Number of points read before the record: it applies to ``points[index:]``.
    name : str
        The parsed key of the record: operation name, coolant or cutter-compensation mode, unit, ...
    value : float
        The record's main number in SI units: tool number, spindle speed (rad/s); NaN when none.
    text : str
        The record as written (continuation lines joined, comments removed).
    """

    kind: str
    line: int
    index: int
    name: str = ""
    value: float = math.nan
    text: str = ""


@dataclass(frozen=True, slots=True)
class Arc:
    """A circular (or helical) move: APT ``CIRCLE/`` followed by its end point, or G-code G02/G03.

    The tool moves counter-clockwise about ``axis`` (right-hand rule) from ``points[start]`` to
    ``points[index]``; a component of the end point along ``axis`` makes it a helix. The readers set
    ``start = index - 1``; :func:`linearize_arcs` keeps the arc and widens the range to the chord
    points it inserts.

    Attributes
    ----------
    line : int
        1-based line of the CIRCLE record (APT) or of the G02/G03 block.
    index : int
        Index of the arc's end point.
    start : int
        Index of the arc's start point.
    centre : tuple of 3 floats
        Centre of the circle in the part frame, metres.
    axis : tuple of 3 floats
        Unit axis of the circle in the part frame.
    radius : float
        Radius as written in the file, metres (NaN when the record gives none).
    """

    line: int
    index: int
    start: int
    centre: tuple[float, float, float]
    axis: tuple[float, float, float]
    radius: float = math.nan

    @property
    def kind(self) -> str:
        """Always ``"arc"`` (lets events and arcs be filtered alike)."""
        return "arc"


def vec3(v) -> tuple[float, float, float]:
    """The first three entries of ``v`` as a tuple of Python floats (an :class:`Arc`'s centre or axis)."""
    return (float(v[0]), float(v[1]), float(v[2]))


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Toolpath:
    """The motion records of a CAM/CAD file, in file order, in SI units and in the part frame.

    Attributes
    ----------
    points : ndarray, shape (n, 3)
        Tool tip positions in metres, in the part frame (the file's frame after the MSYS/CSYS or
        machine kinematics the reader documents).
    axes : ndarray, shape (n, 3), or None
        Unit tool axis at each point (from the tool tip towards the spindle, the CAM convention),
        modal values carried over points that do not repeat it; None when the file says nothing
        about the tool axis.
    axis_given : ndarray of bool, shape (n,), or None
        True where the file gave the axis at that point, False where it was inherited (or a default);
        None exactly when ``axes`` is None.
    feeds : ndarray, shape (n,)
        Feed rate in m/s of the motion into each point; NaN where unknown, and on rapid moves.
    rapid : ndarray of bool, shape (n,)
        True when the motion into the point is a rapid (positioning) move.
    lines : ndarray of int64, shape (n,)
        1-based source line of each point's record.
    events : tuple of Event and Arc
        Non-motion records in file order (see :data:`EVENT_KINDS`).
    units : str
        Length unit the file is written in (``"mm"``, ``"inch"`` or ``"m"``; ``"mm,inch"`` if it
        changes).
    source : str
        Name of the file the toolpath was read from.
    rotary : ndarray, shape (n, 2), or None
        Rotary axis angles (radians) of a 5-axis G-code program at each point, as programmed
        (e.g. B and C of a table-table machine); None for other formats.
    """

    points: np.ndarray
    axes: np.ndarray | None
    axis_given: np.ndarray | None
    feeds: np.ndarray
    rapid: np.ndarray
    lines: np.ndarray
    events: tuple = field(default_factory=tuple)
    units: str = "mm"
    source: str = "<toolpath>"
    rotary: np.ndarray | None = None

    def __post_init__(self):
        pts = np.asarray(self.points, dtype=float)
        if pts.size == 0:
            pts = pts.reshape(0, 3)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"Toolpath.points must have shape (n, 3), got {pts.shape}")
        n = pts.shape[0]

        def vec(name, dtype, shape):
            a = np.asarray(getattr(self, name), dtype=dtype)
            if a.shape != shape:
                raise ValueError(f"Toolpath.{name} must have shape {shape}, got {a.shape}")
            return _readonly(a)

        object.__setattr__(self, "points", _readonly(pts))
        if (self.axes is None) != (self.axis_given is None):
            raise ValueError("Toolpath.axes and Toolpath.axis_given must both be given or both be None")
        if self.axes is not None:
            object.__setattr__(self, "axes", vec("axes", float, (n, 3)))
            object.__setattr__(self, "axis_given", vec("axis_given", bool, (n,)))
        object.__setattr__(self, "feeds", vec("feeds", float, (n,)))
        object.__setattr__(self, "rapid", vec("rapid", bool, (n,)))
        object.__setattr__(self, "lines", vec("lines", np.int64, (n,)))
        if self.rotary is not None:
            object.__setattr__(self, "rotary", vec("rotary", float, (n, 2)))
        object.__setattr__(self, "events", tuple(self.events))

    def __len__(self) -> int:
        return self.points.shape[0]

    def __repr__(self) -> str:
        return (
            f"Toolpath({self.source!r}, {len(self)} points, {int(self.rapid.sum())} rapid, "
            f"axes={'yes' if self.axes is not None else 'no'}, {len(self.events)} events, "
            f"units={self.units!r})"
        )

    def events_of(self, *kinds: str) -> tuple:
        """The events whose kind is one of ``kinds`` (``"arc"`` selects the :class:`Arc` records)."""
        return tuple(e for e in self.events if e.kind in kinds)

    @property
    def arcs(self) -> tuple[Arc, ...]:
        """The :class:`Arc` events, in file order."""
        return tuple(e for e in self.events if isinstance(e, Arc))


def arc_samples(
    start: np.ndarray, end: np.ndarray, centre: np.ndarray, axis: np.ndarray, tolerance: float
) -> np.ndarray:
    """Interior points of a circular or helical arc, spaced so that chords stay within ``tolerance``.

    Parameters
    ----------
    start, end : ndarray, shape (3,)
        End points of the arc (metres).
    centre : ndarray, shape (3,)
        A point on the arc's axis.
    axis : ndarray, shape (3,)
        Unit axis; the motion is counter-clockwise about it. An end that projects onto the start
        along the axis is a full turn.
    tolerance : float
        Largest distance, metres, between a chord and the arc (sagitta).

    Returns
    -------
    ndarray, shape (m, 3)
        Points strictly between ``start`` and ``end`` (m may be 0). Radius and height along the axis
        vary linearly with the angle, so a helix or a slightly inconsistent radius is followed
        exactly at both ends.
    """
    n = np.asarray(axis, dtype=float)
    u = np.asarray(start, dtype=float) - centre
    v = np.asarray(end, dtype=float) - centre
    hu, hv = float(u @ n), float(v @ n)
    up, vp = u - hu * n, v - hv * n
    ru, rv = float(np.linalg.norm(up)), float(np.linalg.norm(vp))
    if ru == 0.0 or rv == 0.0:
        return np.empty((0, 3))
    sweep = math.atan2(float(np.cross(up, vp) @ n), float(up @ vp)) % (2.0 * math.pi)
    if sweep < 1e-12:  # the end projects onto the start: a full turn (a helix if heights differ)
        sweep = 2.0 * math.pi if np.linalg.norm(up - vp) <= 1e-9 * max(ru, rv) else 0.0
    r = max(ru, rv)
    # Sagitta of a chord spanning angle d on radius r is r (1 - cos(d/2)).
    step = 2.0 * math.acos(max(-1.0, 1.0 - tolerance / r)) if tolerance < r else math.pi
    step = min(step, math.pi / 2.0)
    m = max(1, math.ceil(sweep / step)) if sweep > 0.0 else 1
    s = np.arange(1, m) / m
    phi = s * sweep
    e1 = up / ru
    e2 = np.cross(n, e1)
    radius = ru + (rv - ru) * s
    height = hu + (hv - hu) * s
    return centre + (radius * np.cos(phi))[:, None] * e1 + (radius * np.sin(phi))[:, None] * e2 + height[:, None] * n


def _slerp_rows(a0: np.ndarray, a1: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Unit vectors at fractions ``s`` of the great-circle arc from ``a0`` to ``a1``."""
    cos_w = float(np.clip(a0 @ a1, -1.0, 1.0))
    w = math.acos(cos_w)
    if w < 1e-12:
        return np.broadcast_to(a0, (s.size, 3)).copy()
    if math.pi - w < 1e-9:  # antipodal: any great circle; take the plain normalised blend
        out = (1.0 - s)[:, None] * a0 + s[:, None] * a1
        nrm = np.linalg.norm(out, axis=1, keepdims=True)
        return np.where(nrm > 1e-12, out / np.maximum(nrm, 1e-300), a0)
    return (np.sin((1.0 - s) * w)[:, None] * a0 + np.sin(s * w)[:, None] * a1) / math.sin(w)


def linearize_arcs(toolpath: Toolpath, tolerance: float = 1e-5) -> Toolpath:
    """Insert points along every :class:`Arc` so that chords stay within ``tolerance`` of the circle.

    Parameters
    ----------
    toolpath : Toolpath
        A reader's output.
    tolerance : float, default 1e-5
        Largest sagitta, metres (0.01 mm, the default planning tolerance of the project).

    Returns
    -------
    Toolpath
        The same toolpath with interior arc points inserted. Inserted points carry the arc's feed,
        rapid flag and source line, tool axes slerped between the arc's end axes (``axis_given``
        False) and rotary angles interpolated linearly. Every event keeps its place; each
        :class:`Arc` now spans ``points[start..index]`` including the inserted points.
    """
    if not tolerance > 0.0:
        raise ValueError(f"tolerance must be positive, got {tolerance!r}")
    tp = toolpath
    arcs = [e for e in tp.events if isinstance(e, Arc)]
    if not arcs:
        return tp
    chunks_p, chunks_a, chunks_r = [], [], []
    owner = []  # for each inserted chunk: index of the point it is inserted before
    for arc in arcs:
        if arc.index != arc.start + 1:
            continue  # already linearised
        p0, p1 = tp.points[arc.start], tp.points[arc.index]
        pts = arc_samples(p0, p1, np.asarray(arc.centre), np.asarray(arc.axis), tolerance)
        if pts.shape[0] == 0:
            continue
        m = pts.shape[0]
        s = np.arange(1, m + 1) / (m + 1)
        chunks_p.append(pts)
        if tp.axes is not None:
            chunks_a.append(_slerp_rows(tp.axes[arc.start], tp.axes[arc.index], s))
        if tp.rotary is not None:
            r0, r1 = tp.rotary[arc.start], tp.rotary[arc.index]
            chunks_r.append(r0 + s[:, None] * (r1 - r0))
        owner.append((arc.index, m))
    if not owner:
        return tp
    n = len(tp)
    before = np.array([o[0] for o in owner])
    counts = np.array([o[1] for o in owner])
    # New position of old point i: i + number of points inserted before it (before[j] <= i).
    shift = np.zeros(n + 1, dtype=np.int64)
    np.add.at(shift, before, counts)
    shift = np.cumsum(shift)
    new_pos = np.arange(n + 1) + shift
    total = n + int(counts.sum())
    old_at = np.full(total, -1, dtype=np.int64)
    old_at[new_pos[:n]] = np.arange(n)
    ins = old_at < 0
    # Each inserted point takes feed, rapid flag and line from the arc's end point.
    nxt = np.minimum.accumulate(np.where(ins, total, np.arange(total))[::-1])[::-1]
    src = np.where(ins, old_at[np.minimum(nxt, total - 1)], old_at)

    points = np.empty((total, 3))
    points[~ins] = tp.points
    points[ins] = np.concatenate(chunks_p)
    axes = given = rotary = None
    if tp.axes is not None:
        axes = np.empty((total, 3))
        axes[~ins] = tp.axes
        axes[ins] = np.concatenate(chunks_a)
        given = np.zeros(total, dtype=bool)
        given[~ins] = tp.axis_given
    if tp.rotary is not None:
        rotary = np.empty((total, 2))
        rotary[~ins] = tp.rotary
        rotary[ins] = np.concatenate(chunks_r)
    events: list[Event | Arc] = []
    for e in tp.events:
        if isinstance(e, Arc):
            events.append(Arc(e.line, int(new_pos[e.index]), int(new_pos[e.start]), e.centre, e.axis, e.radius))
        else:  # an event before the motion into point k stays before the chord points of that motion
            k = int(new_pos[e.index - 1]) + 1 if e.index > 0 else 0
            events.append(Event(e.kind, e.line, k, e.name, e.value, e.text))
    return Toolpath(
        points=points,
        axes=axes,
        axis_given=given,
        feeds=tp.feeds[src],
        rapid=tp.rapid[src],
        lines=tp.lines[src],
        events=tuple(events),
        units=tp.units,
        source=tp.source,
        rotary=rotary,
    )
