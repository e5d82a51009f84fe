"""Input validation shared by the kinematics modules: shapes and finite values, with the place named."""

from __future__ import annotations

import numpy as np

from planner.errors import PlannerError
from planner.validation import ArgumentError, as_floats

#: Element types of the one-pose fast path (anything else goes through the full check: no strings, booleans).
_REAL = frozenset((float, int, np.float64))


def times(t, n: int) -> np.ndarray:
    """Sample times (n,), finite, as floats; PlannerError naming ``t`` and the index otherwise."""
    t = as_floats(t, "t")
    if t.shape != (n,):
        raise PlannerError(f"t: expected shape ({n},) (one time per sample), got {t.shape}")
    bad = ~np.isfinite(t)
    if bad.any():
        raise PlannerError(f"t[{int(np.argmax(bad))}] is {t[np.argmax(bad)]}; times must be finite")
    return t


def rows_of_six(value, name: str, *, allow_nan_rows: bool = False) -> tuple[np.ndarray, bool]:
    """Return ``value`` as a float array (n, 6) and whether it was a single row (6,).

    Raises a :class:`PlannerError` naming ``name``, the row and the column of the first bad entry.
    With ``allow_nan_rows``, rows that are entirely NaN pass (they mark "no value" samples).
    """
    try:
        arr = as_floats(value, name)
    except ArgumentError as exc:
        raise PlannerError(f"{name}: expected numbers of shape (6,) or (n, 6): {str(exc).partition(': ')[2]}") from None
    single = arr.ndim == 1
    if single:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 6:
        raise PlannerError(f"{name}: expected shape (6,) or (n, 6), got {np.shape(value)}")
    bad = ~np.isfinite(arr)
    if allow_nan_rows:
        bad &= ~np.isnan(arr).all(axis=1, keepdims=True)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        where = f"{name}[{col}]" if single else f"{name}[{row}, {col}] (row {row})"
        raise PlannerError(f"{where} is {arr[row, col]}; every value must be finite")
    return arr, single


def six_floats(value, name: str) -> list[float] | None:
    """One row of six finite numbers as Python floats, for the one-pose fast paths.

    Returns None when ``value`` holds several rows (n, 6) (the caller decides whether that is an
    error); anything else that is not six finite numbers raises the error of :func:`rows_of_six`.
    A list, tuple or array of six numbers is converted without numpy's per-call overhead.
    """
    if type(value) is np.ndarray:
        vals = value.tolist() if value.shape == (6,) and value.dtype.kind in "fiu" else None
    elif isinstance(value, (list, tuple)) and len(value) == 6 and all(type(v) in _REAL for v in value):
        vals = value
    else:
        vals = None
    if vals is not None:
        try:
            out = [float(v) for v in vals]
        except (TypeError, ValueError):
            out = None
        if out is not None:
            total = sum(out)
            if total - total == 0.0:  # every entry finite (inf - inf and nan give nan)
                return out
    arr, single = rows_of_six(value, name)
    return arr[0].tolist() if single else None
