"""Frames along a whole PH spline path: continuous across segments, closed paths, prescribed rolls.

Each segment's frame is its ER frame turned by an angle; the angle at the start of a segment continues
the previous segment's end frame, so frames (and their quaternions) are continuous along the path.

- ``"rmf"``: the exact rotation-minimizing frame (:mod:`planner.frames.rmf`).
- ``"grm"``: the rational GRM frame of every segment (:mod:`planner.frames.grm`).
- ``"er"``: the Euler-Rodrigues frame, made continuous at the joints (not rotation-minimizing).
- ``"juttler"``: Jüttler's rational RMM of a G1 PH cubic spline (juttler seed, section 7.1: one
  rational motion per circular tangent indicatrix, C0 at the joints).
- ``"double-reflection"``: the double reflection method on the samples asked for (sampled data).

On top of the base frame, the planner adds the least uniform twist that meets the user's constraints:
a closed path spreads its closing twist evenly over the arc length; prescribed rolls at waypoints are
met by a twist that is linear in arc length between them (the minimal-twist motion: constant twist
rate is what minimizes the integral of the squared spin about the tangent), never by a slerp.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from planner.errors import PlannerError
from planner.frames.double_reflection import double_reflection_frames
from planner.frames.grm import grm_many
from planner.frames.ph_cubic_rmm import ph_cubic_spline_rmm
from planner.frames.rmf import check_start_frame
from planner.frames.rmf_batch import PathRMFAngles
from planner.frames.validation import has_path
from planner.protocols import Path
from planner.rotations import quaternion_to_matrix
from planner.validation import finite_floats

METHODS = ("rmf", "grm", "er", "juttler", "double-reflection")


def _er_at(path, k: np.ndarray, t: np.ndarray) -> np.ndarray:
    """ER frames (n, 3, 3) of segments k at local parameters t."""
    return quaternion_to_matrix(path.quaternion_at_segment(k, t))


def _turned_quaternions(path, k, t, angle, unit: bool = True) -> np.ndarray:
    """Quaternions (n, 4) of the ER frames turned by ``angle`` about the tangent: A e^{i angle/2}
    (normalized when ``unit``)."""
    a0, a1, a2, a3 = path.quaternion_rows(k, t)
    c, s = np.cos(0.5 * angle), np.sin(0.5 * angle)
    if unit:  # |A e^{i angle/2}| = |A|
        inv = 1.0 / np.sqrt(a0 * a0 + a1 * a1 + a2 * a2 + a3 * a3)
        c, s = c * inv, s * inv
    Q = np.empty((t.size, 4))  # A (c + s i), written out
    Q[:, 0] = a0 * c - a1 * s
    Q[:, 1] = a0 * s + a1 * c
    Q[:, 2] = a2 * c + a3 * s
    Q[:, 3] = a3 * c - a2 * s
    return Q


def _angle_in(frame_col1: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """Angle (n,) of vectors (n, 3) in the normal planes of frames (n, 3, 3), from column 1 to column 2."""
    return np.arctan2(np.einsum("ni,ni->n", frame_col1, basis[:, :, 2]),
                      np.einsum("ni,ni->n", frame_col1, basis[:, :, 1]))


@dataclass(frozen=True, eq=False)
class PathFrames:
    """A continuous frame field along a PH spline.

    Attributes
    ----------
    path : PHSpline
    method : str
    segment_angles : list of callables, or None for "rmf"
        Per segment, t (n,) -> angle (n,) of the base frame against the segment's ER frame, 0 at t = 0
        (the exact RMF is evaluated for all segments at once from ``panels`` instead).
    offsets : ndarray (N,)
        Angle of the base frame against each segment's ER frame at its start.
    stations : ndarray (m,), corrections : ndarray (m,)
        The extra twist (rad) as a piecewise-linear function of arc length (constant outside).
    grm_frames : list of GRMFrame or None
        The per-segment GRM solutions (method "grm"), with their figures.
    """

    path: Path
    method: str
    segment_angles: list | None
    offsets: np.ndarray
    stations: np.ndarray
    corrections: np.ndarray
    grm_frames: list | None = None
    panels: PathRMFAngles | None = None

    def base_angle(self, u) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(segment, local t, angle against the ER frame) at global parameters u, before corrections."""
        k, t = self.path.locate(u)
        if self.segment_angles is None:  # exact RMF, all segments at once along sorted samples
            assert self.panels is not None
            return k, t, self.panels(k, t) + self.offsets[k]
        ang = np.empty_like(t)
        for seg in np.unique(k):
            idx = np.flatnonzero(k == seg)
            f = self.segment_angles[seg]
            ang[idx] = f.on_grid(t[idx]) if hasattr(f, "on_grid") else f(t[idx])
        return k, t, ang + self.offsets[k]

    def quaternions(self, u, unit: bool = True) -> np.ndarray:
        """Quaternions (n, 4) (scalar first, unit unless ``unit=False``) of the frames at parameters u (n,)."""
        u = np.atleast_1d(finite_floats(u, "u"))
        k, t, ang = self.base_angle(u)
        if self.stations.size:
            ang = ang + np.interp(self.path.arc_length(u), self.stations, self.corrections)
        return _turned_quaternions(self.path, k, t, ang, unit)

    def quaternions_at(self, k, t) -> np.ndarray | None:
        """Unit quaternions (n, 4) of the exact RMF at segments k (n,) and local parameters t (n,), for
        samplers that located their samples already; None for other methods or with prescribed rolls
        (then use :meth:`quaternions`)."""
        if self.segment_angles is not None or self.stations.size or self.panels is None:
            return None
        return _turned_quaternions(self.path, k, t, self.panels(k, t) + self.offsets[k])

    def frames(self, u) -> np.ndarray:
        """Frames (n, 3, 3) at global parameters u (n,): column 0 the unit tangent, columns 1, 2 the
        normal-plane vectors; orthonormal, right-handed, continuous along the path."""
        return quaternion_to_matrix(self.quaternions(u, unit=False))

    def at_length(self, s) -> np.ndarray:
        """Frames at arc lengths s (n,) from the start (metres)."""
        return self.frames(self.path.parameter_at_length(s))


def _segment_functions(path, method: str, weight) -> tuple[list | None, list | None]:
    if method == "rmf":
        return None, None
    if method == "er":
        zero = _Zero()
        return [zero] * path.n_segments, None
    if method == "grm":
        if path.degree != 5:
            raise PlannerError("method 'grm' needs a PH quintic spline (fit_ph_spline)")
        sols = grm_many(path.segments, weight)
        return [_GRMAngle(g) for g in sols], sols
    raise PlannerError(f"method must be one of {METHODS}, got {method!r}")


class _Zero:
    def __call__(self, t):
        return np.zeros_like(np.asarray(t, dtype=float))


class _GRMAngle:
    def __init__(self, g):
        self.g = g

    def __call__(self, t):
        return self.g.angle(t) - self.g.start_angle


def frame_field(
    path,
    method: str = "rmf",
    *,
    start=None,
    closed: bool = False,
    prescribed: Mapping[int, np.ndarray] | None = None,
    weight: str | Callable = "twist",
) -> PathFrames | MotionFrames:
    """Build the frame field of a PH spline path (``fit_ph_spline`` or ``fit_ph_cubic_spline`` result).

    Parameters
    ----------
    path : PHSpline
    method : "rmf" (exact, default), "grm", "er", "juttler" (PH cubic splines) or "double-reflection"
    start : array_like (3, 3), optional
        Frame at the start (column 0 the unit tangent). Default: the ER frame there.
    closed : bool
        The path ends where it starts (same point and tangent): the closing twist is spread evenly so
        the end frame equals the start frame.
    prescribed : mapping waypoint index -> vector (3,) or frame (3, 3), optional
        Tool roll set by the user at chosen waypoints: the normal-plane direction of column 1 there
        (a frame's column 1, or any vector, projected into the normal plane). Met exactly by the least
        uniform twist between consecutive prescriptions.
    weight : GRM objective (method "grm" only), see :func:`planner.frames.grm.grm`.

    Examples
    --------
    >>> import numpy as np
    >>> from planner.curves import fit_ph_spline
    >>> from planner.frames import frame_field
    >>> t = np.linspace(0.0, 1.0, 9)
    >>> path = fit_ph_spline(np.c_[0.2 * t, 0.03 * np.sin(2 * np.pi * t), 0.01 * t ** 2])
    >>> field = frame_field(path, "rmf")      # exact rotation-minimizing frames
    >>> F = field.frames(np.linspace(0.0, path.n_segments, 50))   # (50, 3, 3): tangent, two normal-plane vectors
    >>> F.shape, bool(np.abs(np.einsum("nij,nik->njk", F, F) - np.eye(3)).max() < 1e-12)
    ((50, 3, 3), True)
    """
    has_path(path)
    if not isinstance(method, str) or method not in METHODS:
        raise PlannerError(f"method must be one of {METHODS}, got {method!r}")
    if method in ("juttler", "double-reflection"):
        if closed or prescribed:
            raise PlannerError(f"closed paths and prescribed rolls are supported for {METHODS[:3]}, not {method!r}")
        return _motion_field(path, method, start)
    funcs, sols = _segment_functions(path, method, weight)
    er0 = _er_at(path, np.array([0]), np.zeros(1))[0]
    off0 = 0.0
    if start is not None:
        F = check_start_frame(start, er0[:, 0])
        off0 = float(_angle_in(F[None, :, 1], er0[None])[0])
    n = path.n_segments
    panels = PathRMFAngles(path.A) if funcs is None else None
    totals = panels.totals if panels is not None else np.array([f(np.ones(1))[0] for f in funcs or ()])
    if n > 1:
        end = _er_at(path, np.arange(n - 1), np.ones(n - 1))
        nxt = _er_at(path, np.arange(1, n), np.zeros(n - 1))
        delta = _angle_in(nxt[:, :, 1], end)  # ER_{k+1}(0) against ER_k(1) about the common tangent
        offsets = off0 + np.concatenate(([0.0], np.cumsum(totals[:-1] - delta)))
    else:
        offsets = np.array([off0])
    field = PathFrames(path, method, funcs, offsets, np.zeros(0), np.zeros(0), sols, panels)
    if closed and prescribed:
        raise PlannerError("closed=True and prescribed rolls together are not supported; prescribe the roll "
                           "at waypoint 0 instead of start/closing, or open the path")
    if closed:
        return _close(field)
    if prescribed:
        return _prescribe(field, prescribed)
    return field


def _close(field: PathFrames) -> PathFrames:
    path = field.path
    p = path.waypoints
    extent = max(float(np.ptp(p, axis=0).max()), 1e-300)
    if np.linalg.norm(p[-1] - p[0]) > 1e-9 * extent:
        raise PlannerError(
            f"closed=True but the path ends at {p[-1].tolist()}, not at its start {p[0].tolist()}"
        )
    ends = field.frames(np.array([path.knots[0], path.knots[-1]]))
    if np.linalg.norm(ends[0, :, 0] - ends[1, :, 0]) > 1e-6:
        raise PlannerError("closed=True but the tangents at the start and end differ (the path has a corner there)")
    closing = float(_angle_in(ends[:1, :, 1], ends[1:])[0])  # start frame seen from the end frame
    return PathFrames(path, field.method, field.segment_angles, field.offsets,
                      np.array([0.0, path.length]), np.array([0.0, closing]), field.grm_frames, field.panels)


def _prescribe(field: PathFrames, prescribed: Mapping[int, np.ndarray]) -> PathFrames:
    path = field.path
    wk = path.waypoint_knots
    idx = sorted(prescribed)
    for i in idx:
        if not isinstance(i, int | np.integer) or not 0 <= i < wk.size:
            raise PlannerError(f"prescribed frame at waypoint {i!r}: no such waypoint (0..{wk.size - 1})")
    u = wk[idx]
    base = field.frames(u)
    needed = []
    for j, i in enumerate(idx):
        v = np.asarray(prescribed[i], dtype=float)
        v = v[:, 1] if v.shape == (3, 3) else v
        if v.shape != (3,) or not np.isfinite(v).all():
            raise PlannerError(f"prescribed frame at waypoint {i}: expected a vector (3,) or frame (3, 3)")
        t = base[j, :, 0]
        w = v - (v @ t) * t
        if np.linalg.norm(w) <= 1e-9 * max(float(np.linalg.norm(v)), 1e-300):
            raise PlannerError(f"prescribed frame at waypoint {i}: the direction is parallel to the path tangent")
        needed.append(float(np.arctan2(w @ base[j, :, 2], w @ base[j, :, 1])))
    angles = np.array(needed)
    angles = angles[0] + np.concatenate(([0.0], np.cumsum(np.angle(np.exp(1j * np.diff(angles))))))
    s = path.arc_length(u)
    return PathFrames(path, field.method, field.segment_angles, field.offsets, s, angles, field.grm_frames,
                      field.panels)


@dataclass(frozen=True, eq=False)
class MotionFrames:
    """Frames of a path from a method that is not an angle against the ER frame (Jüttler's rational
    motion, double reflection): the same ``frames(u)`` / ``at_length(s)`` interface as PathFrames."""

    path: Path
    method: str
    motion: Any
    start: np.ndarray

    def frames(self, u) -> np.ndarray:
        u = np.atleast_1d(finite_floats(u, "u"))
        if self.method == "juttler":
            return self.motion.frames(u)
        order = np.argsort(u, kind="stable")  # double reflection runs along the sorted samples
        F = np.empty((u.size, 3, 3))
        F[order] = double_reflection_frames(self.path.points(u[order]), self.path.tangent(u[order]), self.start)
        return F

    def at_length(self, s) -> np.ndarray:
        return self.frames(self.path.parameter_at_length(s))


def _motion_field(path, method: str, start) -> MotionFrames:
    F0 = frame_field(path, "er").frames(path.knots[:1])[0]
    if start is not None:
        F0 = check_start_frame(start, F0[:, 0])
    if method == "double-reflection":
        return MotionFrames(path, method, None, F0)
    if path.degree != 3:
        raise PlannerError("method 'juttler' needs a G1 PH cubic spline (fit_ph_cubic_spline): its unit "
                           "tangents are circular arcs, which Jüttler's rational motions follow")
    hodographs = 3.0 * np.diff(path.control_points, axis=1)
    return MotionFrames(path, method, ph_cubic_spline_rmm(hodographs, path.knots, F0), F0)


def path_frames(path, u, method: str = "rmf", **options) -> np.ndarray:
    """Frames (n, 3, 3) of a PH spline path at global parameters u (n,); see :func:`frame_field`."""
    return frame_field(path, method, **options).frames(u)
