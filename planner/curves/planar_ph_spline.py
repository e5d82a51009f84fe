"""G1 planar PH cubic spline through planar waypoints, from DP-PH Hermite pieces, at constant height z.

Each span between consecutive waypoints gets the shortest DP-PH cubic with the span's end points and end
tangent directions (``dp_ph_hermite`` in "curve" mode): the path passes through every waypoint exactly and
its unit tangent is continuous (G1). A PH cubic has no inflection and turns by less than a full turn, so
spans whose data need an inflection (S-shaped) or too much turning have no PH cubic: such a span is split
on its reference cubic (the C2 cubic spline's span, or the cubic Hermite curve of the given tangents with
chord-length magnitudes) at its inflection points, or else at its midpoint, recursively, the new joints
taking the reference's point and tangent. The same split is made when the best PH cubic is more than
``max_length_ratio`` times as long as the reference (it would loop).

Parametrization: global parameter u with one knot per waypoint at its cumulative chord length (as the PH
quintic spline of planner.curves.spline); a span [u_i, u_i+1] split on its reference at t_a < t_b gives
the piece [u_i + t_a h_i, u_i + t_b h_i]. The arc length is a piecewise cubic polynomial: ``length`` and
``parameter_at_length`` are exact to round-off.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from planner import bernstein
from planner.curves.dp_cubic import DPCubic
from planner.curves.dp_ph_hermite import HermiteDataError, dp_ph_hermite
from planner.curves.piecewise_length import PiecewiseLength
from planner.curves.tangents import chord_knots, cubic_spline_slopes
from planner.errors import NoSolutionError, PlannerError, WaypointError
from planner.validation import (
    ArgumentError,
    as_float,
    as_floats,
    as_int,
    check_tangents,
    check_waypoints,
)

#: Waypoints given in 3-D must share z to this fraction of the path's extent.
Z_RTOL = 1e-9

_GL_X, _GL_W = np.polynomial.legendre.leggauss(16)
_GL_X, _GL_W = 0.5 * (_GL_X + 1.0), 0.5 * _GL_W


@dataclass(frozen=True, eq=False)
class PlanarPHSpline(PiecewiseLength):
    """A G1 piecewise PH cubic path in the plane z = const, parameter u in [knots[0], knots[-1]].

    Attributes
    ----------
    segments : tuple of DPCubic
        The PH cubic pieces in order (local parameter t in [0, 1]), planar (x, y), metres.
    breaks : ndarray (m + 1,)
        Global parameter at the ends of the pieces (contains every knot).
    knots : ndarray (N,)
        Global parameter at each waypoint (cumulative chord length, metres).
    z : float
        Height of the plane of the path (metres).

    Arc length (``segment_lengths``, ``cumulative_lengths``, ``length``, ``arc_length``,
    ``parameter_at_length``): :class:`~planner.curves.piecewise_length.PiecewiseLength`.
    """

    segments: tuple[DPCubic, ...]
    breaks: np.ndarray
    knots: np.ndarray
    z: float = 0.0

    # -- stacked data ---------------------------------------------------------------------------
    @cached_property
    def bezier(self) -> np.ndarray:
        """Bezier control points (m, 4, 2) of every piece."""
        return np.stack([s.to_bezier() for s in self.segments])

    @cached_property
    def sigma_coeffs(self) -> np.ndarray:
        """Bernstein coefficients (m, 3) of every piece's speed |dP/dt| (a quadratic)."""
        return np.stack([s.sigma() for s in self.segments])

    @property
    def piece_bounds(self) -> np.ndarray:
        """Global parameter at the ends of the pieces: the breaks (the arc-length bookkeeping's bounds)."""
        return self.breaks

    @property
    def n_segments(self) -> int:
        return len(self.segments)

    # -- evaluation -----------------------------------------------------------------------------
    def locate(self, u) -> tuple[np.ndarray, np.ndarray]:
        """Piece index (n,) and local parameter t (n,) of global parameters u (n,).

        Raises PlannerError for u outside [knots[0], knots[-1]] (beyond round-off) or not finite.
        """
        u = np.atleast_1d(np.asarray(u, dtype=float))
        lo, hi = self.breaks[0], self.breaks[-1]
        tol = 1e-12 * max(hi - lo, 1.0)
        bad = ~np.isfinite(u) | (u < lo - tol) | (u > hi + tol)
        if bad.any():
            i = int(np.argmax(bad))
            raise PlannerError(f"parameter u[{i}] = {u[i]} is outside [{lo}, {hi}]")
        k = np.clip(np.searchsorted(self.breaks, u, side="right") - 1, 0, self.n_segments - 1)
        h = self.breaks[k + 1] - self.breaks[k]
        return k, np.clip((u - self.breaks[k]) / h, 0.0, 1.0)

    def _lift(self, xy: np.ndarray, z: float) -> np.ndarray:
        return np.concatenate((xy, np.full(xy.shape[:-1] + (1,), z)), axis=-1)

    def points(self, u) -> np.ndarray:
        """Points r(u), shape (n, 3), z constant."""
        k, t = self.locate(u)
        xy = np.einsum("nk,nkd->nd", bernstein.basis(3, t), self.bezier[k])
        return self._lift(xy, self.z)

    def derivative(self, u) -> np.ndarray:
        """dr/du, shape (n, 3) (right-sided at breaks; G1 only: its length jumps at joints)."""
        k, t = self.locate(u)
        h = self.breaks[k + 1] - self.breaks[k]
        d = np.einsum("nk,nkd->nd", bernstein.basis(2, t), 3.0 * np.diff(self.bezier[k], axis=1))
        return self._lift(d / h[:, None], 0.0)

    def speed(self, u) -> np.ndarray:
        """|dr/du|, shape (n,), from the polynomial speed of the PH pieces."""
        k, t = self.locate(u)
        h = self.breaks[k + 1] - self.breaks[k]
        return np.einsum("nk,nk->n", bernstein.basis(2, t), self.sigma_coeffs[k]) / h

    def tangent(self, u) -> np.ndarray:
        """Unit tangent, shape (n, 3); continuous across joints (G1)."""
        d = self.derivative(u)
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def curvature(self, u) -> np.ndarray:
        """Signed curvature (1/m), shape (n,), positive when turning left (counter-clockwise)."""
        k, t = self.locate(u)
        c = self.bezier[k]
        d1 = np.einsum("nk,nkd->nd", bernstein.basis(2, t), 3.0 * np.diff(c, axis=1))
        d2 = np.einsum("nk,nkd->nd", bernstein.basis(1, t), 6.0 * np.diff(c, n=2, axis=1))
        cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
        return cross / np.linalg.norm(d1, axis=1) ** 3

    # -- quality figures ------------------------------------------------------------------------
    @property
    def waypoints(self) -> np.ndarray:
        """Points at the knots (N, 3)."""
        return self.points(self.knots)

    def tangent_jumps(self) -> np.ndarray:
        """Angle (rad) between the unit tangents on either side of every interior break (0 for G1)."""
        if self.n_segments < 2:
            return np.zeros(0)
        b = self.bezier
        left = b[:-1, 3] - b[:-1, 2]
        right = b[1:, 1] - b[1:, 0]
        cross = left[:, 0] * right[:, 1] - left[:, 1] * right[:, 0]
        return np.abs(np.arctan2(cross, np.einsum("nd,nd->n", left, right)))

    def to_ph_spline(self):
        """The same path as a spatial :class:`~planner.curves.spline.PHSpline` (PH cubic segments), so
        the frames, the time law and the exports take it like any other path.

        A planar PH cubic with P'(t) = w(t)^2, w = w0 (1-t) + w1 t, is the spatial one with quaternions
        A_k = Re(w_k) + Im(w_k) k: A i A* = (Re w^2, Im w^2, 0).

        Raises
        ------
        NotPHError
            A segment with no preimage w (a straight piece whose speed is not a perfect square).
        """
        from planner.curves.spline import PHSpline

        A = np.zeros((self.n_segments, 2, 4))
        for k, seg in enumerate(self.segments):
            w0, w1 = seg.preimage()
            A[k, :, 0] = (w0.real, w1.real)
            A[k, :, 3] = (w0.imag, w1.imag)
        starts = np.column_stack((self.bezier[:, 0, :], np.full(self.n_segments, self.z)))
        index = np.searchsorted(self.breaks, self.knots)
        return PHSpline(A, starts, self.breaks, "G1", 0, None if self.breaks.size == self.knots.size else index)

    def interpolation_errors(self, waypoints) -> np.ndarray:
        """Distance (N,) of the path at each knot from the given waypoints (N, 2) or (N, 3), metres."""
        w = np.asarray(waypoints, dtype=float)
        r = self.waypoints
        return np.linalg.norm(r[:, : w.shape[1]] - w, axis=1)


# -- fitting --------------------------------------------------------------------------------------
def _planar_input(waypoints, z) -> tuple[np.ndarray, float]:
    try:
        arr = as_floats(waypoints, "waypoints")
    except ArgumentError:
        arr = None
    dim = arr.shape[1] if arr is not None and arr.ndim == 2 and arr.shape[1] in (2, 3) else 3
    p = check_waypoints(waypoints, dim=dim)
    if dim == 2:
        z0 = 0.0 if z is None else float(z)
        if not np.isfinite(z0):
            raise WaypointError(f"z must be finite, got {z}")
        return p, z0
    extent = float(np.ptp(p, axis=0).max())
    z0 = float(p[0, 2]) if z is None else float(z)
    off = np.abs(p[:, 2] - z0) > Z_RTOL * max(extent, abs(z0), 1e-300)
    if off.any():
        i = int(np.argmax(off))
        raise WaypointError(
            f"z = {p[i, 2]} differs from the path's plane z = {z0}: a planar PH spline needs constant z", i
        )
    return p[:, :2], z0


def _planar_tangents(tangents, n: int) -> np.ndarray:
    try:
        arr = np.asarray(tangents, dtype=float)
    except (TypeError, ValueError):
        arr = None
    dim = arr.shape[1] if arr is not None and arr.ndim == 2 and arr.shape[1] in (2, 3) else 3
    d = check_tangents(tangents, n, dim=dim)
    if dim == 3:
        norm = np.linalg.norm(d, axis=1)
        off = np.abs(d[:, 2]) > 1e-9 * norm
        if off.any():
            i = int(np.argmax(off))
            raise WaypointError(f"tangent {d[i].tolist()} leaves the plane z = const", i)
        if (np.linalg.norm(d[:, :2], axis=1) == 0).any():
            i = int(np.argmax(np.linalg.norm(d[:, :2], axis=1) == 0))
            raise WaypointError("tangent has no component in the plane", i)
        d = d[:, :2]
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _bezier_split(c: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """de Casteljau: the two halves (4, 2) of a cubic Bezier split at t."""
    a = c
    left, right = [a[0]], [a[-1]]
    while len(a) > 1:
        a = (1 - t) * a[:-1] + t * a[1:]
        left.append(a[0])
        right.append(a[-1])
    return np.array(left), np.array(right[::-1])


def _inflections(c: np.ndarray) -> list[float]:
    """Parameters in (0.05, 0.95) where the cubic Bezier c (4, 2) changes its turning direction."""
    d = 3 * np.diff(c, axis=0)  # hodograph Bernstein coefficients (3, 2)
    dd = 2 * np.diff(d, axis=0)  # (2, 2)
    # cross(r', r'') as a quadratic: sample at 3 points and interpolate
    ts = np.array([0.0, 0.5, 1.0])
    r1 = bernstein.evaluate(d, ts)
    r2 = bernstein.evaluate(dd, ts)
    y = r1[:, 0] * r2[:, 1] - r1[:, 1] * r2[:, 0]
    coef = np.polynomial.polynomial.polyfit(ts, y, 2)
    scale = np.abs(y).max()
    if scale == 0:
        return []
    coef = np.where(np.abs(coef) <= 1e-12 * scale, 0.0, coef)
    coef = np.trim_zeros(coef, "b")
    if coef.size < 2:
        return []
    roots = np.polynomial.polynomial.polyroots(coef)
    return sorted(float(r.real) for r in roots if abs(r.imag) < 1e-12 and 0.05 < r.real < 0.95)


def _reference_length(c: np.ndarray) -> float:
    d = bernstein.evaluate(3 * np.diff(c, axis=0), _GL_X)
    return float(_GL_W @ np.linalg.norm(d, axis=1))


def _fit_span(c: np.ndarray, depth: int, max_depth: int, ratio: float):
    """PH pieces [(t_a, t_b, DPCubic)] of the reference cubic Bezier c (4, 2) on t in [0, 1]."""
    size = float(np.abs(c - c[0]).max())
    d0, d3 = c[1] - c[0], c[3] - c[2]
    if min(np.linalg.norm(d0), np.linalg.norm(d3)) <= 1e-9 * size or size == 0.0:
        raise NoSolutionError("the span's reference curve stops and reverses (a hairpin): no G1 path")
    best = None
    try:
        best = dp_ph_hermite(c[0], d0, c[3], d3)[0]
    except (NoSolutionError, HermiteDataError):  # HermiteDataError: the piece closes on itself
        pass
    if best is not None and (depth >= max_depth or best.length <= ratio * _reference_length(c)):
        return [(0.0, 1.0, best)]
    if depth >= max_depth:
        raise NoSolutionError(f"no PH cubic after {max_depth} subdivisions (does the path reverse here?)")
    cuts = _inflections(c) or [0.5]
    pieces = []
    edges = [0.0, *cuts, 1.0]
    rest = c
    for j in range(len(edges) - 1):
        a, b = edges[j], edges[j + 1]
        if j < len(edges) - 2:
            part, rest = _bezier_split(rest, (b - a) / (1.0 - a))
        else:
            part = rest
        for ta, tb, seg in _fit_span(part, depth + 1, max_depth, ratio):
            pieces.append((a + ta * (b - a), a + tb * (b - a), seg))
    return pieces


def fit_planar_ph_spline(
    waypoints, tangents=None, *, z: float | None = None, max_depth: int = 8, max_length_ratio: float = 2.0
) -> PlanarPHSpline:
    """G1 planar PH cubic spline (DP-PH Hermite pieces) through N >= 2 planar waypoints.

    Parameters
    ----------
    waypoints : array_like (N, 2) or (N, 3)
        Points in a plane z = const (metres); 3-D points must share z (to ``Z_RTOL`` of the extent).
    tangents : array_like (N, 2) or (N, 3), optional
        Tangent directions at the waypoints (lengths ignored; in-plane). Default: the tangents of the
        not-a-knot C2 cubic spline through the waypoints with chord-length knots.
    z : float, optional
        Height of the path for 2-D waypoints (default 0) or the plane 3-D waypoints must lie in.
    max_depth : int
        Largest number of nested splits of a span with no suitable PH cubic.
    max_length_ratio : float
        A span's PH cubic may be at most this many times as long as its reference cubic, else the span
        is split (avoids loops).

    Returns
    -------
    PlanarPHSpline
        Through every waypoint to round-off, exact arc length, unit tangent continuous: to round-off
        (about 1e-13 rad) in general and never worse than 1e-6 rad (checked; near hairpins the pieces
        end in near-cusps whose end tangents carry round-off).

    Raises
    ------
    WaypointError
        Fewer than 2 waypoints, non-finite data, consecutive duplicates, 3-D points off the plane, zero,
        out-of-plane or miscounted tangents (the message names the waypoint index).
    NoSolutionError
        A span admits no PH cubic even after ``max_depth`` splits (names the span).
    """
    p, z0 = _planar_input(waypoints, z)
    n = p.shape[0]
    u = chord_knots(p)
    h = np.diff(u)
    if tangents is None:
        m = cubic_spline_slopes(u, p)
        norms = np.linalg.norm(m, axis=1)
        if (norms <= 1e-12).any():
            i = int(np.argmax(norms <= 1e-12))
            raise WaypointError("the estimated tangent vanishes (the path reverses here); give tangents", i)
    else:
        m = _planar_tangents(tangents, n)
    max_depth = as_int(max_depth, "max_depth", 0, 64)
    max_length_ratio = as_float(max_length_ratio, "max_length_ratio")
    if not max_length_ratio > 1.0:
        raise PlannerError(f"max_length_ratio must exceed 1, got {max_length_ratio!r}")
    segments: list[DPCubic] = []
    breaks: list[float] = [float(u[0])]
    for i in range(n - 1):
        ref = np.array([p[i], p[i] + h[i] * m[i] / 3, p[i + 1] - h[i] * m[i + 1] / 3, p[i + 1]])
        try:
            pieces = _fit_span(ref, 0, max_depth, max_length_ratio)
        except NoSolutionError as exc:
            raise NoSolutionError(f"span from waypoint {i} to {i + 1}: {exc}") from None
        for _ta, tb, seg in pieces:
            segments.append(seg)
            breaks.append(float(u[i] + tb * h[i]))
        breaks[-1] = float(u[i + 1])
    spline = PlanarPHSpline(tuple(segments), np.array(breaks), u, z0)
    jumps = spline.tangent_jumps()
    if jumps.size and jumps.max() > 1e-6:  # never return a path that is not G1
        j = int(np.argmax(jumps)) + 1
        i = int(np.searchsorted(u, spline.breaks[j], side="right")) - 1
        raise NoSolutionError(f"span from waypoint {i} to {i + 1}: tangent turns by {jumps.max():.3g} rad at a joint")
    return spline


__all__ = ["PlanarPHSpline", "fit_planar_ph_spline"]
