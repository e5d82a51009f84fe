"""Validation of user-supplied waypoints and tangents: clear errors that name the waypoint index."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from planner.errors import PlannerError, WaypointError

#: Two consecutive waypoints closer than this fraction of the path's extent are duplicates.
DUPLICATE_RTOL = 1e-12


def _as_rows(data, what: str, dim: int) -> np.ndarray:
    """Convert ``data`` to a float array (n, dim), naming the first malformed row on failure."""
    try:
        arr = np.asarray(data, dtype=float)
    except (ValueError, TypeError):
        arr = None
    if arr is not None and arr.size == 0:
        arr = arr.reshape(0, dim)
    if arr is None or arr.ndim != 2:
        if isinstance(data, np.ndarray) and data.ndim != 2:
            raise WaypointError(f"{what} must be an array of shape (n, {dim}), got shape {data.shape}")
        if not isinstance(data, Sequence) and not isinstance(data, np.ndarray):
            raise WaypointError(f"{what} must be a sequence of {dim}-vectors, got {type(data).__name__}")
        for i, row in enumerate(data):
            try:
                r = np.asarray(row, dtype=float)
            except (ValueError, TypeError) as exc:
                raise WaypointError(f"{what} row is not numeric ({exc})", i) from None
            if r.shape != (dim,):
                raise WaypointError(f"{what} row must have {dim} coordinates, got {np.shape(row)}", i)
        raise WaypointError(f"{what} must be an array of shape (n, {dim})")
    if arr.shape[1] != dim:
        raise WaypointError(f"{what} must have {dim} coordinates per row, got {arr.shape[1]}")
    return arr


def check_waypoints(waypoints, *, min_count: int = 2, dim: int = 3) -> np.ndarray:
    """Validated waypoints as a float array (n, dim).

    Raises
    ------
    WaypointError
        Fewer than ``min_count`` points, wrong dimension, NaN/inf coordinates, or two consecutive
        points that coincide (the message names the index of the second one).
    """
    return checked_waypoint_steps(waypoints, min_count=min_count, dim=dim)[0]


def checked_waypoint_steps(waypoints, *, min_count: int = 2, dim: int = 3):
    """:func:`check_waypoints`, also returning the steps between consecutive waypoints as contiguous rows
    (dim, n - 1) and their lengths (n - 1,) (the chord lengths the fitters need)."""
    p = _as_rows(waypoints, "waypoints", dim)
    if p.shape[0] < min_count:
        raise WaypointError(f"need at least {min_count} waypoints, got {p.shape[0]}")
    if not np.isfinite(p).all():
        i = int(np.argmax(~np.isfinite(p).all(axis=1)))
        raise WaypointError(f"coordinates must be finite, got {p[i].tolist()}", i)
    rows = np.ascontiguousarray(p.T)  # reductions along contiguous rows are fast
    d = rows[:, 1:] - rows[:, :-1]
    step = np.sqrt(np.einsum("ij,ij->j", d, d))
    extent = float((rows.max(axis=1) - rows.min(axis=1)).max()) if p.shape[0] > 1 else 0.0
    dup = step <= DUPLICATE_RTOL * max(extent, np.finfo(float).tiny)
    if dup.any():
        i = int(np.argmax(dup)) + 1
        raise WaypointError(f"duplicates waypoint {i - 1} (consecutive points must differ)", i)
    return p, d, step


def check_tangents(tangents, n: int, *, dim: int = 3) -> np.ndarray:
    """Validated tangent directions (n, dim): finite, nonzero, one per waypoint."""
    d = _as_rows(tangents, "tangents", dim)
    if d.shape[0] != n:
        raise WaypointError(f"got {d.shape[0]} tangents for {n} waypoints (need one per waypoint)")
    bad = ~np.isfinite(d).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise WaypointError(f"tangent must be finite, got {d[i].tolist()}", i)
    zero = np.linalg.norm(d, axis=1) == 0.0
    if zero.any():
        i = int(np.argmax(zero))
        raise WaypointError("tangent is the zero vector", i)
    return d


def check_vector(v, name: str, dim: int = 3, nonzero: bool = False) -> np.ndarray:
    """A single finite vector of length ``dim`` named ``name`` in error messages."""
    try:
        a = np.asarray(v, dtype=float)
    except (ValueError, TypeError):
        raise WaypointError(f"{name} must be a numeric {dim}-vector, got {v!r}") from None
    if a.shape != (dim,):
        raise WaypointError(f"{name} must have shape ({dim},), got {a.shape}")
    if not np.isfinite(a).all():
        raise WaypointError(f"{name} must be finite, got {a.tolist()}")
    if nonzero and not np.any(a):
        raise WaypointError(f"{name} must not be the zero vector")
    return a


def check_arc_lengths(s, length: float) -> np.ndarray:
    """Arc lengths s (n,) as floats clipped to [0, length]; values beyond round-off outside it, or not
    finite, raise naming the index (``arc length s[i] = ... is outside [0, L]``)."""
    s = np.atleast_1d(np.asarray(s, dtype=float))
    bad = ~np.isfinite(s) | (s < -1e-12 * length) | (s > length * (1 + 1e-12))
    if bad.any():
        i = int(np.argmax(bad))
        raise PlannerError(f"arc length s[{i}] = {s[i]} is outside [0, {length}]")
    return np.clip(s, 0.0, length)


def check_in_range(value, name: str, lo: float, hi: float, error: type[PlannerError] = PlannerError) -> float:
    """``value`` as a float in (lo, hi], or ``error`` naming ``name`` (booleans and NaN are refused)."""
    if isinstance(value, bool):
        raise error(f"{name} must be a number, got {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise error(f"{name} must be a number, got {value!r}") from None
    if not (math.isfinite(x) and lo < x <= hi):
        raise error(f"{name} must be in ({lo:g}, {hi:g}], got {x!r}")
    return x
