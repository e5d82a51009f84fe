"""Tangent estimation at waypoints from the C2 cubic spline through them (chord-length knots)."""

from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dgtsv

from planner.errors import NumericalError


def chord_knots(points: np.ndarray) -> np.ndarray:
    """Cumulative chord-length knots u (n,), u[0] = 0, for points (n, 3)."""
    h = np.linalg.norm(np.diff(points, axis=0), axis=1)
    return np.concatenate(([0.0], np.cumsum(h)))


def cubic_spline_slopes(u: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Derivatives dc/du (n, 3) at the knots of the not-a-knot C2 cubic spline c(u) through the points.

    The same spline as ``scipy.interpolate.CubicSpline(u, points)``; its tridiagonal slope system is
    solved directly (LAPACK gtsv) because the PH fit needs only the slopes. Two points give the chord;
    three give the interpolating parabola.
    """
    points = np.asarray(points, dtype=float)
    return slopes_rows(np.asarray(u, dtype=float), np.ascontiguousarray(np.diff(points, axis=0).T)).T


def slopes_rows(u: np.ndarray, dp: np.ndarray) -> np.ndarray:
    """:func:`cubic_spline_slopes` on component rows: knots u (n,), point differences dp (k, n - 1) as
    contiguous rows; returns the slopes as rows (k, n)."""
    n = u.shape[0]
    h = u[1:] - u[:-1]
    slope = dp / h
    if n == 2:
        return np.hstack((slope, slope))
    if n == 3:  # not-a-knot with three points: the parabola through them
        s0, s1 = slope[:, 0], slope[:, 1]
        m1 = (h[1] * s0 + h[0] * s1) / (h[0] + h[1])
        return np.stack((2 * s0 - m1, m1, 2 * s1 - m1), axis=1)
    dl, dd, du = np.empty(n - 1), np.empty(n), np.empty(n - 1)
    b = np.empty((dp.shape[0], n))  # the right-hand sides as rows: b.T is Fortran-ordered for LAPACK
    np.multiply(2.0, h[:-1] + h[1:], out=dd[1:-1])
    du[1:] = h[:-1]
    dl[:-1] = h[1:]
    b[:, 1:-1] = 3.0 * (h[1:] * slope[:, :-1] + h[:-1] * slope[:, 1:])
    d = u[2] - u[0]
    dd[0], du[0] = h[1], d
    b[:, 0] = ((h[0] + 2 * d) * h[1] * slope[:, 0] + h[0] ** 2 * slope[:, 1]) / d
    d = u[-1] - u[-3]
    dd[-1], dl[-1] = h[-2], d
    b[:, -1] = (h[-1] ** 2 * slope[:, -2] + (2 * d + h[-1]) * h[-2] * slope[:, -1]) / d
    x, info = dgtsv(dl, dd, du, b.T, overwrite_dl=1, overwrite_d=1, overwrite_du=1, overwrite_b=1)[3:]
    if info != 0:  # a singular system needs two coincident knots, which the callers' validation excludes
        raise NumericalError(f"singular cubic spline slope system (LAPACK gtsv info {info})")
    return x.T
