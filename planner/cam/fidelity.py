"""Fitting CAM passes with PH quintic splines that stay within a tolerance of the CAM polyline.

A spline forced through CAM points with global (C2 cubic) tangents overshoots at every change from a
straight run to an arc. Here every pass is fitted locally:

1. Tangents at the CAM points: along the line inside and at the ends of straight runs (points within
   ``line_tol`` of the chord through their neighbours), Bessel's three-point estimate elsewhere
   (h_i d_{i-1} + h_{i-1} d_i with unit chords d and chord lengths h: the tangent of the circle through
   the three points to first order, so linearised arcs keep their circle tangents), and the first and
   last chord's direction at the pass ends. Every tangent lies in the cone of its two chords: no
   overshoot.
2. Each span is the PH quintic Hermite interpolant of its end points and tangents (C1, local,
   |dr/du| = 1 at the knots with chord-length knots), the member of least bending energy among the four
   that respect the data's plane and symmetries (:func:`planner.curves.ph_quintic.batch_hermite`); with
   both tangents along the chord that is the straight chord itself, exactly.
3. The distance of the span from its CAM chord is measured on samples; a span farther than the
   tolerance (or not advancing monotonically along its chord) is split at its midpoint, a new knot on
   the chord with the chord's direction as tangent, and both halves are refitted. Halving repeats
   until every span is within tolerance; spans between two chord-direction knots are straight.

Deviation: every span lies over one CAM chord and advances monotonically along it, so the largest
distance of the span from the chord's line bounds the Hausdorff distance between the fitted path and
the polyline in both directions (every chord point has a path point in its normal plane, by
continuity). All passes of a job are fitted together, vectorized over spans.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner import bernstein
from planner.cam.passes import CamInputError
from planner.curves.ph_core import batch_control_points
from planner.curves.ph_quintic import batch_hermite
from planner.curves.spline import PHSpline

#: Default tolerance: largest distance of the fitted path from the CAM polyline, metres (0.01 mm).
DEFAULT_TOLERANCE = 1e-5
#: Samples per span while refining (the deviation is smooth in t: 33 samples find its maximum to ~0.1 %).
REFINE_SAMPLES = 33
#: Samples per span for the reported deviation.
REPORT_SAMPLES = 65
#: A span is refined while its sampled deviation exceeds this fraction of the tolerance.
REFINE_MARGIN = 0.98


@dataclass(frozen=True, eq=False)
class PassFit:
    """A pass's PH path and how closely it follows the CAM polyline.

    Attributes
    ----------
    path : PHSpline
        C1 PH quintic spline; ``path.waypoint_knots`` are the parameters of the CAM points (the
        knots the fit inserted lie on the CAM chords between them).
    points : ndarray (m, 3)
        The CAM points (metres).
    max_deviation : float
        Largest distance between the path and the CAM polyline, metres (two-sided, see module doc).
    span_deviation : ndarray (m - 1,)
        Largest distance of the path from each CAM chord, metres.
    knots_added : int
        Knots inserted on the CAM chords to meet the tolerance.
    straight_chords : int
        CAM chords on straight runs (fitted as exact straight segments unless refined at an end).
    rounds : int
        Refinement rounds (halvings) needed.
    """

    path: PHSpline
    points: np.ndarray
    max_deviation: float
    span_deviation: np.ndarray
    knots_added: int
    straight_chords: int
    rounds: int

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"path": self.path, "points": self.points, "max_deviation": self.max_deviation,
                "span_deviation": self.span_deviation, "knots_added": self.knots_added,
                "straight_chords": self.straight_chords, "rounds": self.rounds}

    @classmethod
    def from_state(cls, state: dict) -> PassFit:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0.0, n, 1.0)


def vertex_tangents(points: np.ndarray, first: np.ndarray, last: np.ndarray, line_tol: float):
    """Unit tangents (N, 3) at concatenated pass points, and which chords are on straight runs.

    Parameters
    ----------
    points : ndarray (N, 3)
        Points of several passes, one after the other.
    first, last : ndarray (N,) of bool
        Whether each point starts / ends its pass (every pass has at least two points).
    line_tol : float
        A point within this distance (metres) of the segment joining its neighbours is on a line.

    Returns
    -------
    tangents : ndarray (N, 3)
    straight : ndarray (N - 1,) of bool
        Chord i (points i -> i + 1, meaningful where not ``last[i]``) lies on a straight run.
    """
    P = points
    N = P.shape[0]
    c = np.diff(P, axis=0)
    h = np.linalg.norm(c, axis=1)
    d = c / np.where(h > 0, h, 1.0)[:, None]
    inner = ~first & ~last
    inner[0] = inner[-1] = False
    i = np.flatnonzero(inner)
    span = P[i + 1] - P[i - 1]
    dist = np.linalg.norm(np.cross(P[i] - P[i - 1], span), axis=1) / np.maximum(np.linalg.norm(span, axis=1), 1e-300)
    # collinear: close to the neighbours' segment and between them (not a reversal)
    col = (dist <= line_tol) & (np.einsum("ij,ij->i", d[i - 1], d[i]) > 0.0)
    collinear = np.zeros(N, dtype=bool)
    collinear[i] = col
    straight = collinear[:-1] | collinear[1:]  # chord j touches a collinear vertex at either end
    straight &= ~last[:-1]
    T = np.empty_like(P)
    fi = np.flatnonzero(first)
    la = np.flatnonzero(last)
    T[fi] = d[fi]
    T[la] = d[la - 1]
    din, dout = d[i - 1], d[i]
    s_in, s_out = straight[i - 1], straight[i]
    bessel = h[i][:, None] * din + h[i - 1][:, None] * dout  # Bessel: circle through three points
    t = np.where((col | (s_in & s_out))[:, None], din + dout, bessel)
    t = np.where((s_in & ~s_out & ~col)[:, None], din, t)
    t = np.where((s_out & ~s_in & ~col)[:, None], dout, t)
    T[i] = t
    return _unit(T), straight


@dataclass
class _Spans:
    """Spans being refined (struct of arrays)."""

    p0: np.ndarray
    p1: np.ndarray
    t0: np.ndarray
    t1: np.ndarray
    chord: np.ndarray  # unit direction of the CAM chord the span lies on
    key: np.ndarray  # global position: CAM chord index + fraction along it (sorts spans in order)
    width: np.ndarray  # fraction of the CAM chord the span covers
    A: np.ndarray | None = None

    def take(self, m: np.ndarray) -> _Spans:
        return _Spans(self.p0[m], self.p1[m], self.t0[m], self.t1[m], self.chord[m], self.key[m], self.width[m],
                      None if self.A is None else self.A[m])

    @property
    def hermite(self) -> np.ndarray:
        """``A``, which every span set has once its Hermite coefficients are set."""
        assert self.A is not None, "span coefficients not set"
        return self.A

    @staticmethod
    def join(parts: list[_Spans]) -> _Spans:
        fields = ("p0", "p1", "t0", "t1", "chord", "key", "width")
        out = _Spans(*(np.concatenate([getattr(s, f) for s in parts]) for f in fields))
        if all(s.A is not None for s in parts):
            out.A = np.concatenate([s.A for s in parts])
        return out


def _hermite(s: _Spans) -> np.ndarray:
    h = np.linalg.norm(s.p1 - s.p0, axis=1)[:, None]
    return batch_hermite(s.p0, s.p1, h * s.t0, h * s.t1)


def span_deviation(A: np.ndarray, p0: np.ndarray, chord: np.ndarray, samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Largest distance (n,) of PH spans from the lines through p0 along ``chord``, and monotonicity.

    Returns
    -------
    deviation : ndarray (n,)
        Max over ``samples`` uniform parameter samples of the distance from the chord line, metres.
    monotone : ndarray (n,) of bool
        The samples advance along the chord (their projections increase).
    """
    cp = batch_control_points(A, p0) - p0[:, None, :]  # (n, 6, 3), relative to p0
    along_cp = cp @ chord[:, :, None]  # (n, 6, 1): projection is linear, so project the control points
    perp_cp = cp - along_cp * chord[:, None, :]
    B = bernstein.basis(cp.shape[1] - 1, np.linspace(0.0, 1.0, samples))  # (samples, 6)
    along = (B @ along_cp)[:, :, 0]
    perp = B @ perp_cp
    dev = np.sqrt((perp * perp).sum(axis=2).max(axis=1))
    monotone = (np.diff(along, axis=1) > 0.0).all(axis=1)
    return dev, monotone


def fit_passes(point_sets, tolerance: float = DEFAULT_TOLERANCE, *, line_tol: float | None = None,
               max_rounds: int = 40) -> list[PassFit]:
    """Fit PH quintic splines within ``tolerance`` of several CAM polylines at once.

    Parameters
    ----------
    point_sets : sequence of array_like (m_k, 3)
        The points of each pass (metres), m_k >= 2, no two consecutive points equal.
    tolerance : float
        Largest distance allowed between a fitted path and its polyline, metres (default 0.01 mm).
    line_tol : float, optional
        Straight-run detection: a point this close to the segment of its neighbours is on a line
        (default ``tolerance / 10``).
    max_rounds : int
        Largest number of halvings of a span; a span still out of tolerance after it (or shorter
        than 1e-9 of its chord) is kept, and its deviation is reported.

    Returns
    -------
    list of PassFit
        One per pass, in order.

    Raises
    ------
    CamInputError
        A non-positive tolerance, a pass with fewer than two points or with two equal consecutive
        points (naming the pass and the point).
    """
    tolerance = float(tolerance)
    if not (np.isfinite(tolerance) and tolerance > 0.0):
        raise CamInputError(f"tolerance must be a positive length in metres, got {tolerance!r}")
    line_tol = tolerance / 10.0 if line_tol is None else float(line_tol)
    sets = [np.asarray(p, dtype=float) for p in point_sets]
    if not sets:
        return []
    for k, p in enumerate(sets):
        if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 2:
            raise CamInputError(f"pass {k}: needs at least two points of shape (m, 3), got {p.shape}")
        if not np.isfinite(p).all():
            raise CamInputError(f"pass {k}, point {int(np.argmax(~np.isfinite(p).all(axis=1)))}: not finite")
        h = np.linalg.norm(np.diff(p, axis=0), axis=1)
        if (h == 0.0).any():
            raise CamInputError(f"pass {k}, point {int(np.argmax(h == 0.0)) + 1}: equals the previous point")
    sizes = np.array([p.shape[0] for p in sets])
    P = np.concatenate(sets)
    N = P.shape[0]
    starts = np.concatenate(([0], np.cumsum(sizes)[:-1]))
    first = np.zeros(N, dtype=bool)
    first[starts] = True
    last = np.zeros(N, dtype=bool)
    last[starts + sizes - 1] = True
    T, straight = vertex_tangents(P, first, last, line_tol)
    j = np.flatnonzero(~last)  # CAM chords
    chord = _unit(P[j + 1] - P[j])
    spans = _Spans(P[j], P[j + 1], T[j], T[j + 1], chord, j.astype(float), np.ones(j.size))
    spans.A = _hermite(spans)
    todo = np.ones(j.size, dtype=bool)
    done = []
    rounds = np.zeros(N, dtype=int)  # per CAM chord (by its first point): halvings needed
    target = REFINE_MARGIN * tolerance
    for r in range(max_rounds + 1):
        cur = spans.take(todo)
        dev, mono = span_deviation(cur.hermite, cur.p0, cur.chord, REFINE_SAMPLES)
        bad = ((dev > target) | ~mono) & (cur.width > 1e-9)
        done.append(cur.take(~bad))
        if not bad.any() or r == max_rounds:
            if bad.any():
                done.append(cur.take(bad))
            break
        b = cur.take(bad)
        rounds[b.key.astype(int)] = r + 1
        mid = 0.5 * (b.p0 + b.p1)
        half = 0.5 * b.width
        left = _Spans(b.p0, mid, b.t0, b.chord, b.chord, b.key, half)
        right = _Spans(mid, b.p1, b.chord, b.t1, b.chord, b.key + half, half)
        new = _Spans.join([left, right])
        new.A = _hermite(new)
        spans = new
        todo = np.ones(new.key.size, dtype=bool)
    allspans = _Spans.join(done)
    order = np.argsort(allspans.key, kind="stable")
    allspans = allspans.take(order)
    dev, _ = span_deviation(allspans.hermite, allspans.p0, allspans.chord, REPORT_SAMPLES)
    cam_chord = np.floor(allspans.key).astype(int)  # global CAM chord index of every span
    # split per pass: global chord index j belongs to the pass whose points contain j
    pass_of_chord = np.repeat(np.arange(len(sets)), sizes)[cam_chord]
    bounds = np.searchsorted(pass_of_chord, np.arange(len(sets) + 1))
    out = []
    for k, p in enumerate(sets):
        a, b = bounds[k], bounds[k + 1]
        A = allspans.hermite[a:b]
        p0 = allspans.p0[a:b]
        h = np.linalg.norm(allspans.p1[a:b] - p0, axis=1)
        knots = np.concatenate(([0.0], np.cumsum(h)))
        local = cam_chord[a:b] - starts[k]
        is_vertex = np.concatenate((allspans.key[a:b] == np.floor(allspans.key[a:b]), [True]))
        wp = np.flatnonzero(is_vertex)
        added = int(b - a - (p.shape[0] - 1))
        path = PHSpline(A, p0, knots, "C1", 0, None if added == 0 else wp)
        per_chord = np.zeros(p.shape[0] - 1)
        np.maximum.at(per_chord, local, dev[a:b])
        c0, c1 = starts[k], starts[k] + sizes[k] - 1  # global indices of the pass's chords
        out.append(PassFit(path, p, float(per_chord.max()), per_chord, added, int(straight[c0:c1].sum()),
                           int(rounds[c0:c1].max())))
    return out


def fit_pass(points, tolerance: float = DEFAULT_TOLERANCE, **options) -> PassFit:
    """Fit one CAM polyline (m, 3) within ``tolerance``; see :func:`fit_passes`."""
    return fit_passes([points], tolerance, **options)[0]
