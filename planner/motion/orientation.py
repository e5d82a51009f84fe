"""Tool orientation along arc length: adapters for the frame providers and the orientation rate.

The time law and the sampler take any callable ``orientation(s) -> (n, 3, 3)`` giving the tool frame
(columns x, y, z; z the approach axis, UR convention) at arc lengths s (n,) in metres. Objects that
also have ``at_parameter(u)`` (frames at path parameters u) let the sampler skip a second arc-length
inversion.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from planner import quaternion as qt
from planner.motion.evaluator import evaluator_for
from planner.motion.limits import MotionInputError
from planner.protocols import FrameProvider
from planner.rotations import matrix_to_quaternion, rotation_angle

Orientation = Callable[[np.ndarray], np.ndarray]

__all__ = ["ConstantOrientation", "FrameOrientation", "Orientation", "orientation_rate",
           "tool_orientation"]


@dataclass(frozen=True, eq=False)
class FrameOrientation:
    """Tool frames from a frame provider with ``frames(u)`` and ``at_length(s)`` (n, 3, 3).

    Works with :func:`planner.frames.path.frame_field` (column 0 the unit tangent) and
    :func:`planner.cam.axis_field` (column 2 the tool axis already).

    Attributes
    ----------
    provider : object
        The frame field.
    z_column : int
        Which column of the provider's frames is the tool z-axis (0, 1 or 2). The columns are
        permuted cyclically so it lands in column 2 (keeps the frame right-handed).
    flip : bool
        Tool z is minus that column: columns 1 and 2 of the result are negated (a half turn about x).
    """

    provider: FrameProvider
    z_column: int = 2
    flip: bool = False
    _inverse: Any = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self):
        if self.z_column not in (0, 1, 2):
            raise MotionInputError("z_column", f"must be 0, 1 or 2, got {self.z_column!r}")
        for name in ("frames", "at_length"):
            if not callable(getattr(self.provider, name, None)):
                raise MotionInputError("provider", f"needs a callable {name}(...) returning (n, 3, 3) frames")
        path = getattr(self.provider, "path", None)
        fast = evaluator_for(path) if hasattr(path, "sigma_coeffs") else None
        object.__setattr__(self, "_inverse", fast)

    @property
    def column_map(self) -> np.ndarray:
        """The constant rotation C (3, 3) with tool frame = provider frame @ C."""
        shift = (self.z_column + 1) % 3  # column order (shift, shift + 1, shift + 2) puts z_column last
        C = np.eye(3)[:, [(shift + i) % 3 for i in range(3)]]
        return C * np.array([1.0, -1.0, -1.0]) if self.flip else C

    def _map(self, F: np.ndarray) -> np.ndarray:
        shift = (self.z_column + 1) % 3
        if shift:
            F = F[:, :, [(shift + i) % 3 for i in range(3)]]
        if self.flip:
            F = F * np.array([1.0, -1.0, -1.0])
        return F

    def __call__(self, s) -> np.ndarray:
        """Tool frames (n, 3, 3) at arc lengths s (n,) (the provider's frames at the exact u(s))."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        if self._inverse is not None:
            return self.at_parameter(self._inverse(s))
        return self._map(np.asarray(self.provider.at_length(s)))

    def at_parameter(self, u) -> np.ndarray:
        """Tool frames (n, 3, 3) at path parameters u (n,)."""
        return self._map(np.asarray(self.provider.frames(np.atleast_1d(np.asarray(u, dtype=float)))))

    def quaternions_at_parameter(self, u) -> np.ndarray | None:
        """Unit quaternions (n, 4) (scalar first) of the tool frames at u, if the provider has
        ``quaternions(u)`` (saves two conversions per sample); else None."""
        get = getattr(self.provider, "quaternions", None)
        if get is None:
            return None
        q = np.asarray(get(np.atleast_1d(np.asarray(u, dtype=float))))
        if self.z_column == 2 and not self.flip:
            return q
        return qt.mul(q, matrix_to_quaternion(self.column_map[None])[0])


    def quaternions_at_segment(self, k, t) -> np.ndarray | None:
        """Unit quaternions (n, 4) of the tool frames at path segments k (n,) and local parameters t (n,),
        if the provider evaluates there directly (``quaternions_at(k, t)``); else None."""
        get = getattr(self.provider, "quaternions_at", None)
        q = None if get is None else get(k, t)
        if q is None or (self.z_column == 2 and not self.flip):
            return q
        return qt.mul(q, matrix_to_quaternion(self.column_map[None])[0])


def tool_orientation(provider, z_column: int = 2, flip: bool = False) -> FrameOrientation:
    """Orientation callable of a frame provider; see :class:`FrameOrientation`.

    For ``axis_field(path, axes)`` keep the default (column 2 is the tool axis). For a path frame
    field (column 0 the tangent, columns 1 and 2 the rotation-minimizing normals) choose the normal
    the tool points along, e.g. ``tool_orientation(frame_field(path), z_column=2)``.
    """
    return FrameOrientation(provider, z_column, flip)


@dataclass(frozen=True, eq=False)
class ConstantOrientation:
    """The same tool frame R (3, 3) everywhere (e.g. a fixed-orientation spray pass)."""

    R: np.ndarray

    def __post_init__(self):
        R = np.asarray(self.R, dtype=float)
        if R.shape != (3, 3) or not np.isfinite(R).all():
            raise MotionInputError("R", f"must be a finite 3x3 matrix, got shape {R.shape}")
        if np.abs(R.T @ R - np.eye(3)).max() > 1e-9 or np.linalg.det(R) < 0:
            raise MotionInputError("R", "must be a rotation matrix (orthonormal, det +1)")
        object.__setattr__(self, "R", R)

    def __call__(self, s) -> np.ndarray:
        n = np.atleast_1d(np.asarray(s, dtype=float)).size
        return np.broadcast_to(self.R, (n, 3, 3)).copy()

    def at_parameter(self, u) -> np.ndarray:
        return self(u)


def orientation_rate(orientation: Orientation, s, lo, hi, h: float | None = None) -> np.ndarray:
    """Tool angular speed per unit arc length |omega| / v (rad/m) at arc lengths s (n,).

    Central differences of the frames at c +- h (second order in h), with the centre c = s moved
    inside [lo + h, hi - h] so that the stencil never straddles a joint where the rate may jump
    (the rate is then that at most h away from s).

    Parameters
    ----------
    orientation : callable s -> (n, 3, 3)
    s, lo, hi : array_like (n,)
        Points and the smooth interval around each (lo < hi), m.
    h : float, optional
        Half step, m (default 1e-4 of the shortest interval).
    """
    s, lo, hi = (np.atleast_1d(np.asarray(x, dtype=float)) for x in (s, lo, hi))
    width = hi - lo
    if h is None:
        h = 1e-4 * float(width.min())
    c = np.clip(s, lo + h, hi - h)  # centre of the stencil, inside the interval
    F = orientation(np.concatenate((c - h, c + h)))
    n = s.size
    return rotation_angle(F[:n], F[n:]) / (2.0 * h)
