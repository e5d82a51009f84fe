"""What a toolpath reader returns: the CAM points in file order, their tool axes, feeds and events.

A :class:`Toolpath` keeps everything the later stages need to split a job into passes (rapid flags,
tool changes, operation names, arcs, source lines) without deciding anything about passes itself.
Units are SI: metres, metres per second, radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.interpolate import BSpline

from planner.io.errors import InputFileError
from planner.io.options import ARC_TOLERANCE_RANGE, ReaderArgumentTypeError, chord_tolerance, number_in
from planner.validation import _described

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
    "cycle",  # CYCLE (APT), G73/G81..G89 (G-code): a canned cycle starts (its holes are expanded into moves)
    "dwell",  # the tool waits in place: value = seconds (cycle DWELL / P at a hole bottom, G04)
    "setting",  # a controller setting that does not move the tool (Sinumerik CYCLE832 tolerance, G64, ...)
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


@dataclass(frozen=True, eq=False)
class Nurbs:
    """A NURBS move (NX ``NURBS/`` with ``KNOT/`` and ``CNTRL/``): the exact curve from ``points[start]``
    to ``points[index]``.

    The curve is ``C(u) = sum_i N_i,p(u) w_i P_i / sum_i N_i,p(u) w_i`` on the clamped knot vector
    ``knots`` (``N_i,p`` the B-spline basis of degree ``p``), evaluated with :class:`scipy.interpolate.BSpline`
    on homogeneous coordinates ``(w x, w y, w z, w)``. The readers set ``start = index - 1`` (the tool's
    position before the record is the first control point, the last control point is the end point);
    :func:`linearize_arcs` samples the curve within its tolerance and widens the range to the samples.

    Attributes
    ----------
    line : int
        1-based line of the ``NURBS/`` record.
    index, start : int
        Indices of the curve's end and start points in the toolpath.
    degree : int
        Polynomial degree ``p`` (order ``p + 1``).
    knots : ndarray, shape (m + p + 1,)
        Clamped knot vector (first and last values repeated ``p + 1`` times).
    control : ndarray, shape (m, 3)
        Control points in the part frame, metres.
    weights : ndarray, shape (m,)
        Positive weights (all 1 for a non-rational B-spline).
    axes : ndarray, shape (m, 3), or None
        Tool axes given with the control points (tip towards spindle, part frame); the tool axis along
        the curve is the same rational blend of them, normalised. None when the record gives none.
    """

    line: int
    index: int
    start: int
    degree: int
    knots: np.ndarray
    control: np.ndarray
    weights: np.ndarray
    axes: np.ndarray | None = None

    def __post_init__(self):
        t = np.asarray(self.knots, dtype=float)
        c = np.asarray(self.control, dtype=float).reshape(-1, 3)
        w = np.asarray(self.weights, dtype=float).reshape(-1)
        p = int(self.degree)
        if c.shape[0] != w.shape[0] or t.shape[0] != c.shape[0] + p + 1 or p < 1:
            raise ValueError(f"Nurbs: {c.shape[0]} control points, {w.shape[0]} weights and {t.shape[0]} knots do "
                             f"not make a B-spline of degree {p}")
        object.__setattr__(self, "knots", _readonly(t))
        object.__setattr__(self, "control", _readonly(c))
        object.__setattr__(self, "weights", _readonly(w))
        if self.axes is not None:
            object.__setattr__(self, "axes", _readonly(np.asarray(self.axes, dtype=float).reshape(-1, 3)))
        # homogeneous coordinates (w x, w y, w z, w) of the points, and of the axes when given
        cols = [c * w[:, None], w[:, None]]
        if self.axes is not None:
            cols.insert(1, self.axes * w[:, None])
        object.__setattr__(self, "_spline", BSpline(t, np.hstack(cols), p, extrapolate=False))

    @property
    def kind(self) -> str:
        """Always ``"nurbs"``."""
        return "nurbs"

    @property
    def domain(self) -> tuple[float, float]:
        """Parameter interval ``(u0, u1)`` of the curve."""
        p = self.degree
        return float(self.knots[p]), float(self.knots[-p - 1])

    def _homogeneous(self, u) -> np.ndarray:
        u0, u1 = self.domain
        return self._spline(np.clip(np.asarray(u, dtype=float), u0, u1))  # type: ignore[attr-defined]

    def evaluate(self, u) -> np.ndarray:
        """Points ``C(u)`` (shape ``u.shape + (3,)``, metres) of the exact curve; ``u`` clipped to the domain."""
        h = self._homogeneous(u)
        return h[..., :3] / h[..., -1:]

    def axis_at(self, u) -> np.ndarray | None:
        """Unit tool axes along the curve (shape ``u.shape + (3,)``), or None when the record gives none.

        The axes blend like the points, ``sum N_i w_i a_i / sum N_i w_i``, normalised.
        """
        if self.axes is None:
            return None
        a = self._homogeneous(u)[..., 3:6]
        return a / np.linalg.norm(a, axis=-1, keepdims=True)

    def sample_parameters(self, tolerance: float) -> np.ndarray:
        """Parameters ``u0 < ... < u1`` whose chords stay within ``tolerance`` (metres) of the curve.

        Starts from the distinct knots with 4 steps per knot span; an interval whose curve points at
        1/4, 1/2 and 3/4 lie farther than ``tolerance`` from its chord is split into
        ``ceil(1.25 sqrt(deviation / tolerance))`` equal parts (the chord error falls with the square of
        the step), until no interval is.
        """
        lo = ARC_TOLERANCE_RANGE[0] * NURBS_SAMPLING_FRACTION
        tolerance = number_in(tolerance, "tolerance", lo, ARC_TOLERANCE_RANGE[1],
                              what=f"positive, a length in metres in [{lo:g}, {ARC_TOLERANCE_RANGE[1]:g}]")
        u0, u1 = self.domain
        k = np.unique(self.knots[(self.knots >= u0) & (self.knots <= u1)])
        u = np.unique(np.concatenate([k[:-1, None] + np.diff(k)[:, None] * np.arange(4)[None, :] / 4.0,
                                      k[-1:, None]], axis=None))
        frac = np.array([0.25, 0.5, 0.75])
        pu = self.evaluate(u)
        for _ in range(40):
            a, b = u[:-1], u[1:]
            pa, pb = pu[:-1], pu[1:]
            pm = self.evaluate(a[:, None] + (b - a)[:, None] * frac[None, :])  # (n, 3, 3)
            d = (pb - pa)[:, None, :]
            dd = np.maximum(np.einsum("nki,nki->nk", d, d), 1e-300)
            lam = np.clip(np.einsum("nki,nki->nk", pm - pa[:, None, :], d) / dd, 0.0, 1.0)
            dev = np.linalg.norm(pm - (pa[:, None, :] + lam[..., None] * d), axis=-1).max(axis=1)
            bad = np.flatnonzero((dev > tolerance) & ((b - a) > 1e-15 * max(1.0, abs(u1))))
            if bad.size == 0:
                break
            parts = np.maximum(2, np.ceil(1.25 * np.sqrt(dev[bad] / tolerance))).astype(np.int64)
            owner = np.repeat(bad, parts - 1)
            step = np.arange(owner.size) - np.repeat(np.cumsum(parts - 1) - (parts - 1), parts - 1) + 1
            new = a[owner] + (b[owner] - a[owner]) * step / np.repeat(parts, parts - 1)
            order = np.argsort(np.concatenate((u, new)), kind="stable")
            u = np.concatenate((u, new))[order]
            pu = np.concatenate((pu, self.evaluate(new)))[order]
        return u

def vec3(v) -> tuple[float, float, float]:
    """The first three entries of ``v`` as a tuple of Python floats (an :class:`Arc`'s centre or axis)."""
    return (float(v[0]), float(v[1]), float(v[2]))


def _check_axes(axes: np.ndarray, lines: np.ndarray, source: str) -> None:
    """InputFileError naming the first point (index and source line) whose tool axis (row of ``axes``, shape (n, 3))
    has no direction: a NaN or infinite component, a length below 1e-12 or beyond the float range."""
    with np.errstate(over="ignore", invalid="ignore"):
        norm = np.sqrt(np.einsum("ij,ij->i", axes, axes))
    bad = np.flatnonzero(~(np.isfinite(norm) & (norm >= 1e-12)))
    if bad.size == 0:
        return
    i = int(bad[0])
    a = tuple(float(v) for v in axes[i])
    why = ("is not finite" if not np.isfinite(axes[i]).all() else "is zero" if norm[i] < 1e-12
           else "is too long to normalise")
    more = f" ({bad.size} points in all)" if bad.size > 1 else ""
    raise InputFileError(source, int(lines[i]), f"tool axis of point {i}", f"{a} {why}{more}: a tool axis is a "
                         "nonzero direction from the tool tip towards the spindle")


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
        object.__setattr__(self, "lines", vec("lines", np.int64, (n,)))
        if self.axes is not None:
            object.__setattr__(self, "axes", vec("axes", float, (n, 3)))
            object.__setattr__(self, "axis_given", vec("axis_given", bool, (n,)))
            _check_axes(self.axes, self.lines, str(self.source))
        object.__setattr__(self, "feeds", vec("feeds", float, (n,)))
        object.__setattr__(self, "rapid", vec("rapid", bool, (n,)))
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

    @property
    def nurbs(self) -> tuple[Nurbs, ...]:
        """The :class:`Nurbs` events, in file order."""
        return tuple(e for e in self.events if isinstance(e, Nurbs))


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


#: A NURBS is sampled within this fraction of the linearisation tolerance: with the planner's default
#: ``arc_tolerance = tolerance / 10`` its chords stay within 2 % of the CAM tolerance of the exact curve, the
#: margin the pass fit leaves (it refines while above 98 % of the tolerance), so the planned path stays
#: within the CAM tolerance of the NURBS itself, not only of its polyline.
NURBS_SAMPLING_FRACTION = 0.2


def linearize_arcs(toolpath: Toolpath, tolerance: float = 1e-5) -> Toolpath:
    """Insert points along every :class:`Arc` and :class:`Nurbs` so that chords stay within ``tolerance``.

    Parameters
    ----------
    toolpath : Toolpath
        A reader's output.
    tolerance : float, default 1e-5
        Largest distance, metres, between a chord and the circle (sagitta), 0.01 mm by default (the
        planning tolerance of the project). A NURBS is sampled within ``NURBS_SAMPLING_FRACTION`` (0.2)
        of it, so that the pass fit stays within its tolerance of the exact curve.

    Returns
    -------
    Toolpath
        The same toolpath with interior curve points inserted. Inserted points carry the curve's feed,
        rapid flag and source line; tool axes are slerped between the arc's end axes (``axis_given``
        False), or blended along a NURBS that gives axes; rotary angles are interpolated linearly.
        Every event keeps its place; each :class:`Arc` and :class:`Nurbs` now spans
        ``points[start..index]`` including the inserted points.
    """
    if not isinstance(toolpath, Toolpath):
        raise ReaderArgumentTypeError("toolpath", f"toolpath must be a Toolpath, got {_described(toolpath)}")
    tolerance = chord_tolerance(tolerance, "tolerance")
    tp = toolpath
    curves = [e for e in tp.events if isinstance(e, Arc | Nurbs)]
    if not curves:
        return tp
    chunks_p, chunks_a, chunks_r = [], [], []
    owner = []  # for each inserted chunk: index of the point it is inserted before
    for arc in curves:
        if arc.index != arc.start + 1:
            continue  # already linearised
        p0, p1 = tp.points[arc.start], tp.points[arc.index]
        nurbs_axes = None
        if isinstance(arc, Nurbs):
            u = arc.sample_parameters(tolerance * NURBS_SAMPLING_FRACTION)[1:-1]
            pts = arc.evaluate(u)
            nurbs_axes = arc.axis_at(u)
        else:
            pts = arc_samples(p0, p1, np.asarray(arc.centre), np.asarray(arc.axis), tolerance)
        if pts.shape[0] == 0:
            continue
        m = pts.shape[0]
        s = np.arange(1, m + 1) / (m + 1)
        chunks_p.append(pts)
        if tp.axes is not None:
            if nurbs_axes is not None:
                chunks_a.append(nurbs_axes)
            else:
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
    events: list[Event | Arc | Nurbs] = []
    for e in tp.events:
        if isinstance(e, Arc):
            events.append(Arc(e.line, int(new_pos[e.index]), int(new_pos[e.start]), e.centre, e.axis, e.radius))
        elif isinstance(e, Nurbs):
            events.append(replace(e, index=int(new_pos[e.index]), start=int(new_pos[e.start])))
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
