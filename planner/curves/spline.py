"""PH quintic splines through waypoints: C1 (Hermite, local) and C2 (global Newton solve).

The spline is parametrized by a global parameter u with one knot per waypoint (chord-length spacing by
default), segment k covering [u_k, u_{k+1}] with local parameter t = (u - u_k) / h_k. Its arc length is
a piecewise quintic polynomial: ``length`` and ``parameter_at_length`` are exact to round-off.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from math import comb
from typing import Literal

import numpy as np

from planner import bernstein
from planner import quaternion as qt
from planner.curves.ph_core import (
    arc_length_coeffs,
    batch_control_points,
    batch_sigma,
    curvature_torsion,
)
from planner.curves.ph_cubic import PHCubic
from planner.curves.ph_quintic import PHQuintic, hermite_rows, sqrt_rot
from planner.curves.ph_spline_c2 import solve_c2
from planner.curves.tangents import slopes_rows
from planner.errors import PlannerError
from planner.validation import as_int, check_tangents, check_vector, checked_waypoint_steps, finite_floats


@dataclass(frozen=True, eq=False)
class PHSpline:
    """A piecewise PH quintic path r(u), u in [knots[0], knots[-1]].

    Attributes
    ----------
    A : ndarray (N, 3, 4)
        Quaternion Bernstein coefficients of each segment in its local parameter t in [0, 1].
    starts : ndarray (N, 3)
        Start point of each segment (the waypoints but the last), metres.
    knots : ndarray (N + 1,)
        Global parameter value at each waypoint (metres of chord length by default).
    continuity : str
        "G1", "C1" or "C2", the order the construction guarantees.
    iterations : int
        Newton iterations of the C2 solve (0 otherwise).
    waypoint_index : ndarray (n,) of int, optional
        Indices into ``knots`` of the user's waypoints, where the fit inserted knots; None when every
        knot is a waypoint.
    """

    A: np.ndarray
    starts: np.ndarray
    knots: np.ndarray
    continuity: str = "C1"
    iterations: int = 0
    waypoint_index: np.ndarray | None = None

    @property
    def waypoint_knots(self) -> np.ndarray:
        """Parameter value at each of the user's waypoints (a subset of ``knots`` where the fit
        inserted extra knots, as the PH cubic spline does where a span admits no PH cubic)."""
        return self.knots if self.waypoint_index is None else self.knots[self.waypoint_index]

    # -- stacked polynomial data --------------------------------------------------------------
    @cached_property
    def control_points(self) -> np.ndarray:
        """Bezier control points (N, degree + 1, 3) of every segment."""
        return batch_control_points(self.A, self.starts)

    @cached_property
    def sigma_coeffs(self) -> np.ndarray:
        """Bernstein coefficients (N, degree) of every segment's speed |dr/dt|."""
        return batch_sigma(self.A)

    @cached_property
    def segment_lengths(self) -> np.ndarray:
        """Exact arc length of every segment (N,), metres."""
        return self.sigma_coeffs.sum(axis=1) / self.sigma_coeffs.shape[1]

    @cached_property
    def cumulative_lengths(self) -> np.ndarray:
        """Arc length at every knot (N + 1,), starting at 0."""
        return np.concatenate(([0.0], np.cumsum(self.segment_lengths)))

    @property
    def length(self) -> float:
        """Total arc length (metres), exact."""
        return float(self.cumulative_lengths[-1])

    @property
    def n_segments(self) -> int:
        return self.A.shape[0]

    @cached_property
    def segments(self) -> list[PHQuintic | PHCubic]:
        """The segments as :class:`PHQuintic` objects (local parameter t in [0, 1])."""
        cls = PHQuintic if self.degree == 5 else PHCubic
        return [cls(a, p) for a, p in zip(self.A, self.starts, strict=True)]

    @property
    def waypoints(self) -> np.ndarray:
        """Points at the knots (N + 1, 3): the segment starts and the end point."""
        return np.vstack((self.starts, self.control_points[-1, -1]))

    # -- evaluation ----------------------------------------------------------------------------
    def locate(self, u) -> tuple[np.ndarray, np.ndarray]:
        """Segment index (n,) and local parameter t (n,) of global parameters u (n,) (finite; beyond the knots the
        end segments extend). ArgumentError names a bad ``u``."""
        u = np.atleast_1d(finite_floats(u, "u", ((), (None,))))
        k = np.clip(np.searchsorted(self.knots, u, side="right") - 1, 0, self.n_segments - 1)
        h = self.knots[k + 1] - self.knots[k]
        return k, (u - self.knots[k]) / h

    @property
    def degree(self) -> int:
        """Polynomial degree of the segments (5 for PH quintics, 3 for PH cubics)."""
        return 2 * self.A.shape[1] - 1

    @cached_property
    def _power(self) -> list[np.ndarray]:
        """Power-basis coefficients in t of r and its derivatives: list over order of (deg+1-order, N, 3)."""
        n = self.degree
        cp = self.control_points  # (N, n+1, 3)
        M = np.zeros((n + 1, n + 1))  # Bernstein -> power: t^k coefficient of B_{n,j}
        for k in range(n + 1):
            for j in range(k + 1):
                M[k, j] = comb(n, k) * comb(k, j) * (-1) ** (k - j)
        c = np.ascontiguousarray(np.einsum("kj,njd->knd", M, cp))
        out = [c]
        for _ in range(n):
            c = np.arange(1, c.shape[0])[:, None, None] * c[1:]
            out.append(np.ascontiguousarray(c))
        return out

    @cached_property
    def _A_rows(self) -> np.ndarray:
        """Power-basis coefficients (m, 4, N) in t of every segment's quaternion polynomial A(t),
        component-major so that evaluation gathers contiguous rows."""
        m = self.A.shape[1]
        M = np.zeros((m, m))
        for k in range(m):
            for j in range(k + 1):
                M[k, j] = comb(m - 1, k) * comb(k, j) * (-1) ** (k - j)
        return np.ascontiguousarray(np.einsum("kj,njc->kcn", M, self.A))

    def quaternion(self, u) -> np.ndarray:
        """The quaternion polynomial A(t) (n, 4) of each sample's segment (r' = A i A* per unit t)."""
        k, t = self.locate(u)
        return self.quaternion_at_segment(k, t)

    def quaternion_rows(self, k, t) -> list[np.ndarray]:
        """Components (w, x, y, z), each (n,), of A(t) of segments k (n,) at local parameters t (n,)."""
        P = self._A_rows
        out = []
        for c in range(4):
            r = P[-1, c][k] * t
            for j in range(P.shape[0] - 2, 0, -1):
                r += P[j, c][k]
                r *= t
            r += P[0, c][k]
            out.append(r)
        return out

    def quaternion_at_segment(self, k, t) -> np.ndarray:
        """A(t) (n, 4) of segments k (n,) at local parameters t (n,) in [0, 1] (no search for the segment)."""
        return np.stack(self.quaternion_rows(k, finite_floats(t, "t")), axis=1)

    def _derivative_t(self, k, t, order):
        """d^order r / dt^order of segments k (n,) at local parameters t (n,), by Horner's rule."""
        c = self._power[order]
        r = c[-1][k]
        tt = t[:, None]
        for j in range(c.shape[0] - 2, -1, -1):
            r = r * tt + c[j][k]
        return r

    def points(self, u) -> np.ndarray:
        """Points r(u), shape (n, 3)."""
        k, t = self.locate(u)
        return self._derivative_t(k, t, 0)

    def derivative(self, u, order: int = 1) -> np.ndarray:
        """Derivative d^order r / du^order, shape (n, 3) (right-sided at knots)."""
        order = as_int(order, "order", 1, 5)
        k, t = self.locate(u)
        h = self.knots[k + 1] - self.knots[k]
        return self._derivative_t(k, t, order) / h[:, None] ** order

    def speed(self, u) -> np.ndarray:
        """|dr/du|, shape (n,)."""
        k, t = self.locate(u)
        h = self.knots[k + 1] - self.knots[k]
        return np.einsum("nk,nk->n", bernstein.basis(self.degree - 1, t), self.sigma_coeffs[k]) / h

    def tangent(self, u) -> np.ndarray:
        """Unit tangent, shape (n, 3)."""
        d = self.derivative(u)
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def curvature(self, u) -> np.ndarray:
        """Curvature (1/m), shape (n,)."""
        return curvature_torsion(*(self.derivative(u, o) for o in (1, 2, 3)))[0]

    def torsion(self, u) -> np.ndarray:
        """Torsion (1/m), shape (n,)."""
        return curvature_torsion(*(self.derivative(u, o) for o in (1, 2, 3)))[1]

    def arc_length(self, u) -> np.ndarray:
        """Exact arc length from the start to u, shape (n,)."""
        k, t = self.locate(u)
        S = arc_length_coeffs(self.sigma_coeffs[k])
        return self.cumulative_lengths[k] + np.einsum("nk,nk->n", bernstein.basis(self.degree, t), S)

    def parameter_at_length(self, s) -> np.ndarray:
        """Global parameters u (n,) at arc lengths s (n,) from the start, s in [0, length]; exact.

        Newton on each segment's arc-length polynomial from a cubic Hermite guess of the inverse
        (:class:`~planner.curves.arc_evaluator.SplineEvaluator`, built once per spline).
        """
        return self._evaluator(np.atleast_1d(finite_floats(s, "s", ((), (None,)))))

    @cached_property
    def _evaluator(self):
        from planner.curves.arc_evaluator import SplineEvaluator

        return SplineEvaluator.of(self)

    # -- quality figures -----------------------------------------------------------------------
    def curvature_jumps(self) -> np.ndarray:
        """|kappa(u_j+) - kappa(u_j-)| (1/m) at the N - 1 interior knots."""
        if self.n_segments < 2:
            return np.zeros(0)
        ones = np.ones(self.n_segments - 1)
        k_left = np.arange(self.n_segments - 1)
        h = np.diff(self.knots)

        def kappa(k, t):
            d = [self._derivative_t(k, t, o) / h[k, None] ** o for o in (1, 2, 3)]
            return curvature_torsion(*d)[0]

        return np.abs(kappa(k_left + 1, 0 * ones) - kappa(k_left, ones))

    def tangent_jumps(self) -> np.ndarray:
        """|dr/du(u_j+) - dr/du(u_j-)| / |dr/du| at the interior knots (0 to round-off for C1)."""
        if self.n_segments < 2:
            return np.zeros(0)
        h = np.diff(self.knots)
        cp = self.control_points
        n = self.degree
        left = n * (cp[:-1, -1] - cp[:-1, -2]) / h[:-1, None]
        right = n * (cp[1:, 1] - cp[1:, 0]) / h[1:, None]
        return np.linalg.norm(right - left, axis=1) / np.linalg.norm(left, axis=1)

    def tangent_angles(self) -> np.ndarray:
        """Angle (rad) between the unit tangents on either side of each interior knot (0 for G1)."""
        if self.n_segments < 2:
            return np.zeros(0)
        cp = self.control_points
        left = cp[:-1, -1] - cp[:-1, -2]
        right = cp[1:, 1] - cp[1:, 0]
        cross = np.linalg.norm(np.cross(left, right), axis=1)
        return np.arctan2(cross, np.einsum("ni,ni->n", left, right))

    def interpolation_errors(self, waypoints) -> np.ndarray:
        """Distance (n,) of the path from the given waypoints (n, 3) at their knots, metres.

        Both one-sided values count: where a segment ends (its last control point, which carries the
        error of the construction) and where the next one starts.
        """
        cp = self.control_points
        left = np.vstack((cp[:1, 0], cp[:, -1]))
        right = np.vstack((cp[:, 0], cp[-1:, -1]))
        idx = slice(None) if self.waypoint_index is None else self.waypoint_index
        w = finite_floats(waypoints, "waypoints", (len(left[idx]), 3))
        # hypot: no overflow of the squares, whatever the scale of the waypoints
        return np.maximum(np.hypot.reduce(left[idx] - w, axis=1), np.hypot.reduce(right[idx] - w, axis=1))


def _align_phases(A: np.ndarray) -> np.ndarray:
    """Rotate each segment's A by e^{i theta_k} (curve unchanged) so that A_k(1) = A_{k+1}(0)."""
    if A.shape[0] < 2:
        return A
    end, start = A[:-1, 2], A[1:, 0]
    # start = end e^{i psi}: e^{i psi} = end^-1 start, whose (scalar, i) parts are (cos psi, sin psi)
    rel = qt.mul(qt.conj(end), start)
    psi = np.arctan2(rel[:, 1], rel[:, 0])
    theta = np.concatenate(([0.0], -np.cumsum(psi)))
    return qt.mul(A, qt.exp_i(theta)[:, None, :])


def fit_ph_spline(
    waypoints,
    tangents=None,
    *,
    continuity: Literal["C1", "C2"] = "C2",
    end_tangents=None,
    angles: tuple[float, float] | None = None,
) -> PHSpline:
    """PH quintic spline through N >= 2 waypoints, exact arc length, C1 or C2.

    Parameters
    ----------
    waypoints : array_like (N, 3)
        Points the path passes through, metres.
    tangents : array_like (N, 3), optional
        Tangent directions at the waypoints (C1 only; lengths are ignored, the path leaves each
        waypoint with |dr/du| = 1). Default: the tangents of the not-a-knot C2 cubic spline through the
        waypoints with chord-length knots.
    continuity : "C1" or "C2"
        "C1": each segment is the PH quintic Hermite interpolant of its end points and tangents (local,
        fast, tangent-continuous). "C2" (default): curvature-continuous; the global Newton solve of
        :mod:`planner.curves.ph_spline_c2` started from the C1 spline.
    end_tangents : pair of array_like (3,), optional
        C2 only: tangent directions at the first and last waypoint (default: the cubic spline's).
    angles : (phi0, phi2), optional
        C1 only: the free angles of every segment's Hermite interpolant (default: the member of least
        bending energy among the four where A0 i A2* is a pure vector, see :meth:`PHQuintic.hermite`).

    Returns
    -------
    PHSpline
        Passes through every waypoint to round-off. With the default member the fit respects the data's
        geometry, C1 and C2 alike, to round-off: rotated, translated, uniformly scaled or reflected
        waypoints give the same path moved alike; waypoints in a plane (any plane) give a path in that
        plane; waypoints in order along a line give the straight path; waypoints symmetric about a plane
        (reflected = reversed) give a path symmetric about it (tests/test_curves_symmetry.py). The C2 solve
        keeps these: its least-norm Newton steps from the C1 spline commute with the isometries.

    Raises
    ------
    WaypointError
        Fewer than 2 waypoints, non-3D or non-finite data, consecutive duplicates, zero or non-finite
        tangents, tangent count not matching (the message names the waypoint index).
    ConvergenceError
        The C2 solve failed (the message names the span).

    Examples
    --------
    >>> import numpy as np
    >>> from planner.curves import fit_ph_spline
    >>> t = np.linspace(0.0, 1.0, 9)
    >>> bead = np.c_[0.2 * t, 0.03 * np.sin(2 * np.pi * t), np.zeros_like(t)]
    >>> path = fit_ph_spline(bead)            # C2 (default); continuity="C1" for the local Hermite fit
    >>> path.n_segments, round(path.length, 6)   # m: the arc length is a polynomial, exact
    (8, 0.238857)
    >>> float(path.interpolation_errors(bead).max()) < 1e-15
    True
    """
    p, dp, h = checked_waypoint_steps(waypoints)  # dp: p[k + 1] - p[k] as rows (3, N)
    if continuity not in ("C1", "C2"):
        raise PlannerError(f"continuity must be 'C1' or 'C2', got {continuity!r}")
    size = float(h.max())
    if not 1e-100 <= size <= 1e100:  # squares of lengths would underflow or overflow: fit the data scaled by 4^-k
        k = round(np.log2(size) / 2.0)  # (exact), and scale the path back: the fit commutes with scaling
        s = fit_ph_spline(p * 4.0**-k, tangents, continuity=continuity, end_tangents=end_tangents, angles=angles)
        return PHSpline(s.A * 2.0**k, p[:-1], s.knots * 4.0**k, s.continuity, s.iterations, s.waypoint_index)
    u = np.concatenate(([0.0], np.cumsum(h)))  # chord_knots(p)
    if tangents is not None:
        if continuity == "C2":
            raise PlannerError(
                "a C2 spline determines its interior tangents; give end_tangents=(t0, t1) for C2, "
                "or continuity='C1' to prescribe tangents at every waypoint"
            )
        d = check_tangents(tangents, p.shape[0])
        m = np.ascontiguousarray((d / np.linalg.norm(d, axis=1, keepdims=True)).T)  # unit tangents as rows
    else:
        m = slopes_rows(u, dp)  # cubic_spline_slopes(u, p) as rows (3, n)
    if end_tangents is not None:
        if continuity != "C2":
            raise PlannerError("end_tangents is for continuity='C2'; for C1 pass tangents=")
        if len(end_tangents) != 2:
            raise PlannerError("end_tangents must be a pair (t0, t1)")
        t0 = check_vector(end_tangents[0], "end_tangents[0]", nonzero=True)
        t1 = check_vector(end_tangents[1], "end_tangents[1]", nonzero=True)
        m = m.copy()
        m[:, 0] = t0 / np.linalg.norm(t0)
        m[:, -1] = t1 / np.linalg.norm(t1)
    # segment k interpolates d0 = h_k m_k, d1 = h_k m_{k+1}: h_k times the interpolant of (dp / h_k, m_k, m_{k+1}),
    # whose roots sqrt_rot(m) are shared by neighbouring segments
    a, r = sqrt_rot(m)
    A = hermite_rows(dp / h, m[:, :-1], m[:, 1:], a[:, :-1], a[:, 1:], r[:-1], r[1:], angles, np.sqrt(h))
    if continuity == "C1":
        return PHSpline(A, p[:-1], u, "C1", 0)
    sq = np.sqrt(h)[:, None, None]
    A_u, iterations = solve_c2(_align_phases(A) / sq, p, h, m[:, 0], m[:, -1])
    return PHSpline(A_u * sq, p[:-1], u, "C2", iterations)
