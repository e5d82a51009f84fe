"""Tangent estimation at waypoints from the C2 cubic spline through them (chord-length knots)."""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_banded


def chord_knots(points: np.ndarray) -> np.ndarray:
    """Cumulative chord-length knots u (n,), u[0] = 0, for points (n, 3)."""
    h = np.linalg.norm(np.diff(points, axis=0), axis=1)
    return np.concatenate(([0.0], np.cumsum(h)))


def cubic_spline_slopes(u: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Derivatives dc/du (n, 3) at the knots of the not-a-knot C2 cubic spline c(u) through the points.

    The same spline as ``scipy.interpolate.CubicSpline(u, points)``; its tridiagonal slope system is
    solved directly (banded LU) because the PH fit needs only the slopes. Two points give the chord;
    three give the interpolating parabola.
    """
    n = points.shape[0]
    h = np.diff(u)
    slope = np.diff(points, axis=0) / h[:, None]
    if n == 2:
        return np.vstack((slope, slope))
    if n == 3:  # not-a-knot with three points: the parabola through them
        s = slope
        m1 = (h[1] * s[0] + h[0] * s[1]) / (h[0] + h[1])
        return np.vstack((2 * s[0] - m1, m1, 2 * s[1] - m1))
    ab = np.zeros((3, n))
    b = np.empty((n, points.shape[1]))
    ab[1, 1:-1] = 2.0 * (h[:-1] + h[1:])
    ab[0, 2:] = h[:-1]
    ab[2, :-2] = h[1:]
    b[1:-1] = 3.0 * (h[1:, None] * slope[:-1] + h[:-1, None] * slope[1:])
    d = u[2] - u[0]
    ab[1, 0] = h[1]
    ab[0, 1] = d
    b[0] = ((h[0] + 2 * d) * h[1] * slope[0] + h[0] ** 2 * slope[1]) / d
    d = u[-1] - u[-3]
    ab[1, -1] = h[-2]
    ab[2, -2] = d
    b[-1] = (h[-1] ** 2 * slope[-2] + (2 * d + h[-1]) * h[-2] * slope[-1]) / d
    return solve_banded((1, 1), ab, b, overwrite_ab=True, overwrite_b=True, check_finite=False)
