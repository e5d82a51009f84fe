"""Deprecated: tool frames about prescribed tool axes by a C2 cubic axis spline (juttler seed, section 7.2).

The pipeline does not use :func:`tool_frames` any more: tool frames about the axes a CAM file gives are
:func:`planner.cam.axis_field` (monotone PCHIP axes that never overshoot the CAM vectors, exact rotation-minimizing
spin; what ``planner.plan`` uses). ``tool_frames`` stays for the next release, unchanged, and warns
(``DeprecationWarning``) naming that replacement on every call; it goes in the release after the next one.

Spraying, gluing and deburring jobs give the tool axis at every waypoint (e.g. minus the surface
normal), which leaves only the spin about it free. The axis field is interpolated smoothly on the unit
sphere (a C2 cubic spline of the axis vectors over the path's waypoint parameters, normalized), and
the spin is chosen rotation-minimizing: the exact RMM of the spherical curve z(u), or Jüttler's
rational approximation of it (spherical biarcs + rational arc motions). Frames have column 2 = tool z.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.interpolate import CubicSpline

from planner.errors import PlannerError, WaypointError
from planner.frames.spherical_rmm import exact_spherical_rmm, rational_spherical_rmm
from planner.frames.validation import has_path
from planner.protocols import Path
from planner.validation import check_tangents, finite_floats

#: Neighbouring tool axes more than this far apart (degrees) are a flip, not a smooth tilt.
FLIP_DEG = 90.0
#: An axis within this angle (degrees) of the direction of travel is reported.
PARALLEL_DEG = 5.0

METHODS = ("exact", "rational")


class ToolAxisWarning(UserWarning):
    """The tool axis is nearly parallel to the direction of travel at a waypoint."""


@dataclass(frozen=True, eq=False)
class ToolFrames:
    """Tool frames along a path: column 2 the interpolated tool axis, spin rotation-minimizing.

    Attributes
    ----------
    path : PHSpline
    method : "exact" or "rational"
    axis_spline : scipy CubicSpline
        The unnormalized axis interpolant c(u); the tool axis is c(u) / |c(u)|.
    motion : object
        The spherical motion (``frames(u)``), exact or rational.
    """

    path: Path
    method: str
    axis_spline: Callable[..., np.ndarray]
    motion: Any

    def axis(self, u) -> np.ndarray:
        """The interpolated tool axis (n, 3) at global parameters u."""
        c = self.axis_spline(np.atleast_1d(finite_floats(u, "u")))
        return c / np.linalg.norm(c, axis=1, keepdims=True)

    def frames(self, u) -> np.ndarray:
        """Tool frames (n, 3, 3) at global parameters u (n,): columns x, y, z (z = tool axis)."""
        return self.motion.frames(np.atleast_1d(finite_floats(u, "u")))

    def at_length(self, s) -> np.ndarray:
        """Tool frames at arc lengths s (n,) from the start of the path (metres)."""
        return self.frames(self.path.parameter_at_length(s))


def _check_axes(path, axes) -> np.ndarray:
    n = path.waypoint_knots.size
    a = check_tangents(axes, n)  # finite, nonzero, one per waypoint (errors name the index)
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    cosang = np.einsum("ni,ni->n", a[:-1], a[1:])
    flips = np.flatnonzero(cosang < np.cos(np.radians(FLIP_DEG)))
    if flips.size:
        i = int(flips[0]) + 1
        ang = float(np.degrees(np.arccos(np.clip(cosang[i - 1], -1, 1))))
        raise WaypointError(
            f"tool axis turns {ang:.1f} deg from waypoint {i - 1} (more than {FLIP_DEG:.0f}): a flip, not a tilt; "
            "check the sign of the normals or split the path there with a reorientation move",
            i,
        )
    tan = path.tangent(path.waypoint_knots)
    par = np.abs(np.einsum("ni,ni->n", a, tan)) > np.cos(np.radians(PARALLEL_DEG))
    for i in np.flatnonzero(par)[:5]:
        warnings.warn(
            f"waypoint {i}: tool axis within {PARALLEL_DEG:.0f} deg of the direction of travel",
            ToolAxisWarning,
            stacklevel=3,
        )
    return a


def _default_start(path, z0: np.ndarray) -> np.ndarray:
    """Start frame with column 2 = z0 and column 0 along the direction of travel (projected)."""
    t = path.tangent(path.knots[:1])[0]
    x = t - (t @ z0) * z0
    if np.linalg.norm(x) < 1e-6:  # travel along the axis: any x will do
        e = np.eye(3)[np.argmin(np.abs(z0))]
        x = e - (e @ z0) * z0
    x /= np.linalg.norm(x)
    return np.column_stack((x, np.cross(z0, x), z0))


def tool_frames(path, axes, method: str = "exact", *, start=None, tol: float = 1e-4) -> ToolFrames:
    """Deprecated (use :func:`planner.cam.axis_field`): rotation-minimizing tool frames about a prescribed tool axis.

    Parameters
    ----------
    path : PHSpline
        The fitted path (``fit_ph_spline`` / ``fit_ph_cubic_spline``).
    axes : array_like (N, 3)
        Tool axis at each of the user's waypoints (any nonzero length; e.g. minus the surface normal).
    method : "exact" (default) or "rational"
        Exact RMM of the interpolated axis curve, or Jüttler's rational approximation (biarcs to
        ``tol`` radians).
    start : array_like (3, 3), optional
        Tool frame at the start, column 2 = the axis there. Default: x along the direction of travel.

    Raises
    ------
    WaypointError
        Axes not one per waypoint, zero or non-finite (naming the index), or a flip of more than
        90 degrees between neighbours (naming the waypoint).

    Warns
    -----
    ToolAxisWarning
        An axis within 5 degrees of the direction of travel (naming the waypoint).
    """
    warnings.warn("planner.frames.tool_frames is deprecated and will be removed in the release after the next one: "
                  "use planner.cam.axis_field(path, axes, start) (monotone axes, exact rotation-minimizing spin; "
                  "what planner.plan uses)", DeprecationWarning, stacklevel=2)
    has_path(path)
    if method not in METHODS:
        raise PlannerError(f"method must be one of {METHODS}, got {method!r}")
    a = _check_axes(path, axes)
    u = path.waypoint_knots
    spline = CubicSpline(u, a) if u.size > 2 else CubicSpline(u, a, bc_type="natural")

    def z(x):
        c = spline(np.asarray(x, dtype=float))
        return c / np.linalg.norm(c, axis=-1, keepdims=True)

    def dz(x):
        c = spline(np.asarray(x, dtype=float))
        n = np.linalg.norm(c, axis=-1, keepdims=True)
        d = spline(np.asarray(x, dtype=float), 1)
        zz = c / n
        return (d - np.sum(d * zz, axis=-1, keepdims=True) * zz) / n

    F0 = _default_start(path, a[0]) if start is None else np.asarray(start, dtype=float)
    interval = (float(u[0]), float(u[-1]))
    motion: Any
    if method == "exact":
        motion = exact_spherical_rmm(z, dz, F0, interval=interval)
    else:
        motion = rational_spherical_rmm(z, dz, tol, F0, interval=interval)
    return ToolFrames(path, method, spline, motion)
