"""Input checks shared by the frame modules: every failure names the argument and the sample index."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from planner import quaternion as quat
from planner.errors import PlannerError
from planner.rotations import quaternion_to_matrix
from planner.validation import ArgumentError, as_float, as_floats

#: Tolerance on |v| - 1 for data that must be unit vectors, and on F^T F - I for frames.
UNIT_TOL = 1e-9


class FrameDataError(PlannerError):
    """Sampled curve data, a start frame or a frame parameter is unusable.

    Attributes
    ----------
    name : str
        The argument at fault (e.g. ``"tangents"``, ``"start"``).
    index : int or None
        The offending sample (0-based) or None when the argument as a whole is wrong.
    """

    def __init__(self, message: str, name: str, index: int | None = None):
        self.name = name
        self.index = index
        where = f"{name}[{index}]" if index is not None else name
        super().__init__(f"{where}: {message}")


def vectors(data, name: str, n: int | None = None) -> np.ndarray:
    """``data`` as a finite float array of shape (n, 3); raise naming the first bad row."""
    a = _floats(data, name)
    if a.ndim != 2 or a.shape[1] != 3:
        raise FrameDataError(f"expected an array of shape (n, 3), got shape {a.shape}", name)
    if n is not None and a.shape[0] != n:
        raise FrameDataError(f"has {a.shape[0]} rows but {n} are required (lengths must match)", name)
    if not np.isfinite(a).all():
        i = int(np.argmax(~np.isfinite(a).all(axis=1)))
        raise FrameDataError(f"is not finite ({a[i]})", name, i)
    return a


def _floats(data, name: str) -> np.ndarray:
    """Real numbers as a float array, or FrameDataError naming ``name`` (strings, complex, None, objects)."""
    try:
        return as_floats(data, name)
    except ArgumentError as exc:
        raise FrameDataError(str(exc).partition(": ")[2], name) from None


def _float(value, name: str) -> float:
    """One real number (NaN and inf pass: the caller checks), or FrameDataError naming ``name``."""
    try:
        return as_float(value, name, finite=False)
    except ArgumentError as exc:
        raise FrameDataError(str(exc).partition(": ")[2], name) from None


def has_curve(curve, name: str = "curve"):
    """``curve`` if it is a PH curve (has the quaternion coefficients ``A``), else FrameDataError."""
    if not hasattr(curve, "A"):
        raise FrameDataError(f"must be a PH curve (PHQuintic, PHCubic or a PH spline), got {type(curve).__name__}",
                             name)
    return curve


def has_path(path, name: str = "path"):
    """``path`` if it is a PH spline (fit_ph_spline / fit_ph_cubic_spline), else FrameDataError."""
    if not all(hasattr(path, a) for a in ("A", "knots", "locate", "waypoint_knots")):
        raise FrameDataError(f"must be a PH spline (fit_ph_spline or fit_ph_cubic_spline), got "
                             f"{type(path).__name__}", name)
    return path


def vector3(data, name: str) -> np.ndarray:
    """One vector of shape (3,) of real numbers (finite values are the caller's to check)."""
    a = _floats(data, name)
    if a.shape != (3,):
        raise FrameDataError(f"expected a vector of shape (3,), got shape {a.shape}", name)
    return a


def _norms(a: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("ij,ij->i", a, a))


def unit_vectors(data, name: str, n: int | None = None, tol: float = UNIT_TOL) -> np.ndarray:
    """Finite unit vectors (n, 3) (|norm - 1| <= tol); raise naming the first bad row."""
    a = vectors(data, name, n)
    dev = np.abs(_norms(a) - 1.0)
    if (dev > tol).any():
        i = int(np.argmax(dev > tol))
        raise FrameDataError(f"is not a unit vector (norm {np.linalg.norm(a[i])!r})", name, i)
    return a


def nonzero_directions(data, name: str, n: int | None = None) -> np.ndarray:
    """Finite nonzero vectors (n, 3) normalized to unit length; raise naming the first zero row."""
    a = vectors(data, name, n)
    norm = _norms(a)
    scale = max(float(norm.max(initial=0.0)), np.finfo(float).tiny)
    bad = norm <= 1e-13 * scale
    if bad.any():
        i = int(np.argmax(bad))
        raise FrameDataError(f"is zero (norm {norm[i]!r}); a direction is undefined there", name, i)
    return a / norm[:, None]


def frame(data, name: str, axis: np.ndarray | None = None, axis_column: int = 0,
          tol: float = UNIT_TOL) -> np.ndarray:
    """A right-handed orthonormal frame (3, 3) whose column ``axis_column`` equals ``axis``.

    Raises FrameDataError naming ``name`` when the shape is wrong, the matrix is not finite, not
    orthonormal, left-handed, or its axis column differs from ``axis`` by more than ``tol``.
    """
    f = _floats(data, name)
    if f.shape != (3, 3):
        raise FrameDataError(f"expected a (3, 3) frame (columns = frame vectors), got shape {f.shape}", name)
    if not np.isfinite(f).all():
        raise FrameDataError("is not finite", name)
    err = float(np.abs(f.T @ f - np.eye(3)).max())
    if err > tol:
        raise FrameDataError(f"is not orthonormal (max |F^T F - I| = {err:.3g})", name)
    if np.linalg.det(f) < 0:
        raise FrameDataError("is left-handed (det = -1); frames must be right-handed", name)
    if axis is not None:
        dev = float(np.linalg.norm(f[:, axis_column] - axis))
        if dev > tol:
            raise FrameDataError(
                f"column {axis_column} is {f[:, axis_column]} but must equal the axis {axis} "
                f"(deviation {dev:.3g})", name)
    return f


def positive_scalar(value, name: str) -> float:
    """A finite number > 0."""
    v = _float(value, name)
    if not np.isfinite(v) or v <= 0:
        raise FrameDataError(f"must be finite and > 0, got {v!r}", name)
    return v


def finite_scalar(value, name: str) -> float:
    """A finite number."""
    v = _float(value, name)
    if not np.isfinite(v):
        raise FrameDataError(f"must be finite, got {v!r}", name)
    return v


def cyclic_permutation(axis_column: int) -> np.ndarray:
    """The cyclic permutation matrix P (3, 3) with P e3 in column ``axis_column``: frame = U P.

    Jüttler's motions U(t) carry the moving axis in their third column (seed eq. 1); U P puts it in
    column ``axis_column`` and keeps the frame right-handed.
    """
    if axis_column not in (0, 1, 2):
        raise FrameDataError(f"must be 0, 1 or 2, got {axis_column!r}", "axis_column")
    return np.roll(np.eye(3), axis_column - 2, axis=1)


def default_frame(axis: np.ndarray, axis_column: int) -> np.ndarray:
    """A right-handed frame (3, 3) with the unit vector ``axis`` in column ``axis_column``.

    The frame is the shortest-arc rotation taking e1 to ``axis`` (half turn about e3 when axis = -e1),
    with its columns shifted cyclically.
    """
    m = quaternion_to_matrix(quat.rotate_i_to(np.asarray(axis, dtype=float)))
    return np.roll(m, axis_column, axis=1)


def curve_values(f: Callable, t: np.ndarray, name: str, unit: bool) -> np.ndarray:
    """Values (n, 3) of a user's curve callable ``f`` at parameters t (n,), checked.

    Raises FrameDataError naming ``name`` and the parameter value when ``f`` returns the wrong shape, a
    non-finite row or (``unit``) a row that is not a unit vector.
    """
    out = np.asarray(f(t), dtype=float)
    if out.shape != (t.shape[0], 3):
        raise FrameDataError(f"must return shape ({t.shape[0]}, 3) for t of shape {t.shape}, got {out.shape}",
                             name)
    bad = ~np.isfinite(out).all(axis=1)
    if unit:
        bad |= np.abs(np.linalg.norm(out, axis=1) - 1.0) > UNIT_TOL
    if bad.any():
        i = int(np.argmax(bad))
        what = "is not a finite unit vector" if unit else "is not finite"
        raise FrameDataError(f"{name}(t) at t = {t[i]!r} {what} ({out[i]})", name)
    return out
