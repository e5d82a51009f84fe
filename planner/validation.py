"""Validation of user-supplied waypoints and tangents: clear errors that name the waypoint index."""

from __future__ import annotations

import math
import numbers
import warnings
from collections.abc import Sequence

import numpy as np

from planner.errors import PlannerError, WaypointError

#: Two consecutive waypoints closer than this fraction of the path's extent are duplicates.
DUPLICATE_RTOL = 1e-12


class ArgumentError(PlannerError):
    """A bad argument of a public function of the planner's API.

    Attributes
    ----------
    argument : str
        The argument at fault, with the index of a bad element when there is one (``"t[3]"``).
    """

    def __init__(self, argument: str, message: str):
        self.argument = argument
        self.detail = message
        super().__init__(f"{argument}: {message}")

    def __reduce__(self):  # picklable (worker processes send errors back): rebuilt from both arguments
        return (type(self), (self.argument, self.detail))


def _described(value) -> str:
    """What a bad value is, for a message (short)."""
    if value is None:
        return "None"
    if isinstance(value, str | bytes):
        return f"the string {value[:40]!r}"
    if isinstance(value, bool | np.bool_):
        return f"the boolean {bool(value)}"
    if isinstance(value, complex | np.complexfloating):
        return f"the complex number {value!r}"
    if isinstance(value, int) and abs(value) > 2**1023:
        return f"an integer of {len(str(abs(value)))} digits, beyond the float range"
    if isinstance(value, numbers.Real):
        return repr(value)
    kind = type(value).__name__
    return f"{'an' if kind[:1].lower() in 'aeiou' else 'a'} {kind}"


def as_floats(value, name: str) -> np.ndarray:
    """``value`` as a float ndarray (any shape), or :class:`ArgumentError` naming ``name`` when it holds anything
    but real numbers: strings, complex numbers, booleans, None, other objects, ragged nesting, integers beyond the
    float range. Finite values and shapes are the caller's to check."""
    if isinstance(value, str | bytes):
        raise ArgumentError(name, f"must be numbers, got {_described(value)}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            a = np.asarray(value)
    except (ValueError, TypeError, OverflowError):
        raise ArgumentError(name, "must be numbers in a rectangular array (rows of equal length)") from None
    kind = a.dtype.kind
    if kind in "fiu":
        return a.astype(float, copy=False)
    if kind == "c":
        raise ArgumentError(name, "must be real numbers, got complex numbers")
    if kind == "b":
        raise ArgumentError(name, "must be numbers, got booleans")
    if kind in "US":
        raise ArgumentError(name, f"must be numbers, got strings ({a.flat[0]!r:.40} ...)" if a.size else
                            "must be numbers, got strings")
    if kind == "O":
        bad = [x for x in a.flat if not isinstance(x, numbers.Real) or isinstance(x, bool | np.bool_)][:1]
        if not bad:
            try:
                return a.astype(float)
            except (OverflowError, TypeError, ValueError):
                bad = [x for x in a.flat if isinstance(x, int) and abs(x) > 2**1023][:1] or [a.flat[0]]
        raise ArgumentError(name, f"must be numbers, got {_described(bad[0])}")
    raise ArgumentError(name, f"must be numbers, got an array of {a.dtype}")


def finite_floats(value, name: str, shape: tuple | None = None, *, min_rows: int = 0) -> np.ndarray:
    """``value`` as a finite float ndarray, or :class:`ArgumentError` naming ``name`` (and the index of the first
    NaN or inf). ``shape``: the required shape, None for any length on an axis (``(None, 3)``), or a tuple of
    such shapes of which one must match (``((3,), (None, 3))``); ``min_rows``: the least length of axis 0."""
    a = as_floats(value, name)
    if shape is not None:
        shapes = shape if shape and isinstance(shape[0], tuple) else (shape,)
        if not any(len(sh) == a.ndim and all(w is None or w == n for w, n in zip(sh, a.shape, strict=True))
                   for sh in shapes):
            want = " or ".join("(" + ", ".join("n" if w is None else str(w) for w in sh) + ("," if len(sh) == 1
                               else "") + ")" for sh in shapes)
            raise ArgumentError(name, f"must have shape {want}, got {a.shape}")
    if a.ndim and a.shape[0] < min_rows:
        raise ArgumentError(name, f"needs at least {min_rows} rows, got {a.shape[0]}")
    bad = ~np.isfinite(a)
    if bad.any():
        i = np.unravel_index(int(np.argmax(bad)), a.shape)
        raise ArgumentError(name + "".join(f"[{j}]" for j in i), f"must be finite, got {float(a[i])!r}")
    return a


def as_float(value, name: str, *, finite: bool = True) -> float:
    """One real number as a float, or :class:`ArgumentError` naming ``name`` (strings, complex numbers, booleans,
    None, arrays of other sizes, integers beyond the float range; NaN and inf unless ``finite`` is False)."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real | np.ndarray):
        raise ArgumentError(name, f"must be a number, got {_described(value)}")
    a = as_floats(value, name)
    if a.size != 1:
        raise ArgumentError(name, f"must be a single number, got an array of shape {a.shape}")
    x = float(a.reshape(()))
    if finite and not math.isfinite(x):
        raise ArgumentError(name, f"must be finite, got {x!r}")
    return x


def as_int(value, name: str, lo: int | None = None, hi: int | None = None) -> int:
    """An integer (Python or numpy, not a boolean) within [lo, hi], or :class:`ArgumentError` naming ``name``."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Integral):
        raise ArgumentError(name, f"must be an integer, got {_described(value)}")
    k = int(value)
    if (lo is not None and k < lo) or (hi is not None and k > hi):
        raise ArgumentError(name, f"must be an integer in {lo if lo is not None else '-inf'}.."
                                  f"{hi if hi is not None else 'inf'}, got {k}")
    return k


def has_attributes(obj, name: str, what: str, *attributes: str):
    """``obj`` if it has every attribute named (duck typing), else :class:`ArgumentError`: ``name must be what``."""
    missing = [a for a in attributes if not hasattr(obj, a)]
    if missing:
        raise ArgumentError(name, f"must be {what}, got {_described(obj)}")
    return obj


def _as_rows(data, what: str, dim: int) -> np.ndarray:
    """Convert ``data`` to a float array (n, dim), naming the first malformed row on failure."""
    try:
        arr = as_floats(data, what)
    except ArgumentError:
        if isinstance(data, str | bytes) or not isinstance(data, Sequence | np.ndarray):
            raise WaypointError(f"{what} must be an array of numbers of shape (n, {dim}), got "
                                f"{_described(data)}") from None
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
                r = as_floats(row, what)
            except ArgumentError as exc:
                raise WaypointError(f"{what} row is not numeric ({str(exc).partition(': ')[2]})", i) from None
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
    with np.errstate(over="ignore"):  # refused below
        d = rows[:, 1:] - rows[:, :-1]
        spans = rows.max(axis=1) - rows.min(axis=1)
    extent = float(spans.max()) if p.shape[0] > 1 else 0.0
    if not np.isfinite(extent):  # name the two waypoints furthest apart along the first such axis
        ax = int(np.argmax(~np.isfinite(spans)))
        lo, hi = int(np.argmin(rows[ax])), int(np.argmax(rows[ax]))
        raise WaypointError(f"{'xyz'[ax] if dim == 3 else f'coordinate {ax}'} differs from waypoint {lo}'s by more "
                            "than the largest float: far too large", hi)
    if 1e-100 <= extent <= 1e100 or extent == 0.0:
        step = np.sqrt(np.einsum("ij,ij->j", d, d))
    else:  # |d|^2 would underflow or overflow: the steps scaled by a power of two
        e = 2.0 ** -round(np.log2(extent))
        step = np.sqrt(np.einsum("ij,ij->j", d * e, d * e)) / e
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
        a = as_floats(v, name)
    except ArgumentError:
        raise WaypointError(f"{name} must be a numeric {dim}-vector, got {_described(v)}") from None
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
    s = np.atleast_1d(as_floats(s, "s"))
    bad = ~np.isfinite(s) | (s < -1e-12 * length) | (s > length * (1 + 1e-12))
    if bad.any():
        i = int(np.argmax(bad))
        raise PlannerError(f"arc length s[{i}] = {s[i]} is outside [0, {length}]")
    return np.clip(s, 0.0, length)


def check_in_range(value, name: str, lo: float, hi: float, error: type[PlannerError] = PlannerError, *,
                   lo_closed: bool = False) -> float:
    """``value`` as a float in (lo, hi] (``[lo, hi]`` with ``lo_closed``), or ``error`` naming ``name`` (booleans,
    strings, complex numbers and NaN are refused). A :class:`PlannerError` itself carries ``field=name``."""
    extra = {"field": name, "value": value} if error is PlannerError else {}
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
        raise error(f"{name} must be a number, got {_described(value)}", **extra)
    try:
        x = float(value)
    except (TypeError, ValueError, OverflowError):
        raise error(f"{name} must be a number, got {_described(value)}", **extra) from None
    if not (math.isfinite(x) and (lo <= x if lo_closed else lo < x) and x <= hi):
        raise error(f"{name} must be in {'[' if lo_closed else '('}{lo:g}, {hi:g}], got {x!r}", **extra)
    return x
