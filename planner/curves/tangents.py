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


#: Waypoints lie on one line when each is within this many units of round-off of their largest coordinate from it
#: (collinear points rotated, moved or scaled in floating point are off their line by a few).
LINE_ULPS = 16.0


#: Largest slope |dr/du| (chord-length u: the steps' slope is 1) at waypoints on a line (Fritsch and Carlson's
#: bound of a monotone cubic, 3 times the secant). A straight PH quintic of unit chord with end speeds a, b (the
#: square of a quadratic in t, of integral 1) exists exactly where (a + b) / 8 - sqrt(a b) / 12 <= 1: with
#: a, b <= 3 always; beside a short step the cubic spline's slope can be 10 (no straight member: a loop).
LINE_SLOPE_MAX = 3.0


def line_direction(p: np.ndarray) -> np.ndarray | None:
    """Unit direction (3,) of the line through every waypoint p (n, 3) to round-off, or None if there is none.

    The line runs from the first waypoint to the one furthest from it; each waypoint's distance from it must be
    at most LINE_ULPS ulps of the largest coordinate (the round-off of collinear points rotated or moved). The
    direction's sign is that of the line's first step. Nine waypoints spread over the data are tried first
    (through two of them: most data are refused by them).
    """
    n = p.shape[0]
    tol = LINE_ULPS * np.finfo(float).eps * float(np.abs(p).max())
    for rows in ((p[(np.arange(9) * (n - 1)) // 8] - p[0]).T if n > 9 else None, (p - p[0]).T):
        if rows is None:
            continue
        far = int(np.argmax(np.einsum("ij,ij->j", rows, rows)))
        e = rows[:, far] / np.linalg.norm(rows[:, far])
        off = np.hypot(np.hypot(rows[1] * e[2] - rows[2] * e[1], rows[2] * e[0] - rows[0] * e[2]),
                       rows[0] * e[1] - rows[1] * e[0])  # |r x e|
        if off.max() > tol * (1.0 if rows.shape[1] == n else 4.0):  # (a line through two of nine: within 2 tol)
            return None
    return e if e @ (p[1] - p[0]) >= 0.0 else -e


def straight_slopes(p: np.ndarray, dp: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The slopes m (3, n) (rows, those of :func:`slopes_rows`) of waypoints p (n, 3) (steps dp (3, n - 1)) on
    one line, zeroed where they would take a PH path off the line; unchanged for any other waypoints.

    A PH curve on a line moves one way between stops (its hodograph A i A* keeps its direction while A is not 0),
    so the path stays on the line only if at every waypoint the slope points the way the path goes on (and comes
    from) or is 0: where the waypoints turn back (antiparallel steps) the slope is 0 (the path stops and turns),
    and where the cubic spline overshoots (its slope points backwards) it is 0 too. A slope is also at most
    LINE_SLOPE_MAX (see there). Waypoints in order along a line keep their slopes (the chord-length cubic spline
    is the line itself: slope 1).

    Returns (slopes, mask (n,) of the zeroed ones, unit direction of the line or None).
    """
    e = line_direction(p)
    if e is None:
        return m, np.zeros(p.shape[0], dtype=bool), None
    way = np.sign(e @ dp)  # +-1 per step (no step is 0: consecutive duplicates are refused)
    before, after = np.r_[way[:1], way], np.r_[way, way[-1:]]  # the step into and out of each waypoint
    zero = (before != after) | ~((e @ m) * after > 0.0)
    size = np.sqrt(np.einsum("ij,ij->j", m, m))
    steep = ~zero & (size > LINE_SLOPE_MAX)
    if not (zero.any() or steep.any()):
        return m, zero, e
    m = m.copy()
    m[:, zero] = 0.0
    m[:, steep] *= LINE_SLOPE_MAX / size[steep]
    return m, zero, e


def across(e: np.ndarray) -> np.ndarray:
    """A unit vector (3,) perpendicular to the unit vector e (3,), chosen by coordinates: the coordinate axis least
    along e (the first of equals) with its part along e removed."""
    c = np.zeros(3)
    c[int(np.argmin(np.abs(e)))] = 1.0
    v = c - (c @ e) * e
    return v / np.linalg.norm(v)
