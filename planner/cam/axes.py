"""The modal tool-axis field of a CAM pass: interpolated without overshoot, spin rotation-minimizing.

CAM files give the tool axis at some points and let the others inherit it (NX writes a vector only
when it changes), so the axis is piecewise constant with short, fast changes in between. A C2 cubic
spline through such data rings: on the NX file's passes :func:`planner.frames.tool_frames` (C2 cubic
spline of the axes) swings up to 75 degrees away from the CAM axes between two points. Here the
axis is interpolated component by component with the monotone piecewise cubic Hermite interpolant
(PCHIP, Fritsch and Carlson 1980) over the path parameters of the CAM points and normalized: C1,
exactly the CAM axis at every CAM point, constant where the CAM axis is constant, and each component
never leaves the range of its two neighbouring CAM values.

The spin about the axis is the exact rotation-minimizing motion of the spherical curve z(u) (juttler
seed, Prop. 1: angular velocity z x z', no component along z), built as in
:mod:`planner.frames.spherical_rmm` (reference motion plus spin integral) but with the spin integral
tabulated as Chebyshev series on panels aligned with the CAM points (the rate is smooth between them
and only continuous across them), so that a frame costs one axis evaluation and one Clenshaw sum:
a job's pose stream is millions of frames. The tests check it against
:func:`planner.frames.exact_spherical_rmm`.

Axes here are tool approach axes (tool z, from the flange towards the tool tip, as the robot frames
use them), i.e. minus the CAM vectors, which point from the tip towards the spindle.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.interpolate import PchipInterpolator

from planner.frames.spherical_rmm import (  # the same RMM (seed eq. 3)
    PieceBasedRMM,
    base_starts,
    chain_pieces,
    spin_rate,
)
from planner.protocols import Path
from planner.rotations import matrix_to_quaternion, matrix_to_rotvec, quaternion_to_matrix, rotate_vectors

#: Accuracy (rad) asked of each spin panel (its Chebyshev series' last two terms).
PANEL_TOL = 1e-13
#: Renew the base direction of the reference motion before z is farther than this from it (rad).
MAX_BASE_ANGLE = np.radians(100.0)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles (n,) between rows of unit vectors a and b (n, 3), radians, accurate at 0 and pi."""
    return 2.0 * np.arctan2(np.linalg.norm(a - b, axis=-1), np.linalg.norm(a + b, axis=-1))


def frame_with_axis(z: np.ndarray, x_hint: np.ndarray) -> np.ndarray:
    """Right-handed frame (3, 3) with column 2 = z and column 0 along ``x_hint`` projected off z."""
    x = x_hint - (x_hint @ z) * z
    if np.linalg.norm(x) < 1e-6:  # hint along the axis: any perpendicular will do
        e = np.eye(3)[int(np.argmin(np.abs(z)))]
        x = e - (e @ z) * z
    x = x / np.linalg.norm(x)
    return np.column_stack((x, np.cross(z, x), z))


def turn_axis(F: np.ndarray, z_new: np.ndarray) -> tuple[np.ndarray, float]:
    """Rotation axis (3,) and angle taking column 2 of F to ``z_new`` with no spin about the tool axis.

    The rotation is about n = z x z_new (perpendicular to both, so the angular velocity never has a
    component along the tool axis); for opposite axes n is F's column 0.
    """
    z = F[:, 2]
    n = np.cross(z, z_new)
    ang = float(angle_between(z[None], z_new[None])[0])
    norm = float(np.linalg.norm(n))
    if norm < 1e-12 * max(ang, 1e-300) or norm < 1e-15:
        n = F[:, 0] if ang > 1.0 else np.array([1.0, 0.0, 0.0])
    else:
        n = n / norm
    return n, ang


def transport(F: np.ndarray, z_new: np.ndarray) -> np.ndarray:
    """Frame F turned without spin so that its column 2 becomes ``z_new`` (3, 3), exactly.

    The result's column 2 is ``z_new`` itself (columns 0 and 1 re-orthonormalized against it), so
    moves that share an axis share bit-identical frames.
    """
    if np.array_equal(F[:, 2], z_new):
        return F
    n, ang = turn_axis(F, z_new)
    x = rotate_vectors(ang * n, F[:, 0])
    return frame_with_axis(np.asarray(z_new, dtype=float), x)


@dataclass(frozen=True, eq=False)
class AxisField:
    """Tool frames along one pass: column 2 the interpolated tool axis, spin rotation-minimizing.

    A frame provider for :func:`planner.motion.tool_orientation` (``frames(u)``, ``at_length(s)``,
    ``quaternions(u)``, ``path``).

    Attributes
    ----------
    path : PHSpline
        The pass's path (``waypoint_knots`` are the CAM points).
    axes : ndarray (m, 3)
        Tool approach axis at the CAM points (unit).
    motion : SpinTable or None
        The rotation-minimizing motion of z(u) = c(u) / |c(u)|, c the PCHIP of the axes over the CAM points'
        parameters (:class:`UnitAxis`); None when the axis is constant over the pass.
    start : ndarray (3, 3)
        Frame at the start of the pass.
    """

    path: Path
    axes: np.ndarray
    motion: SpinTable | None
    start: np.ndarray

    @property
    def interpolant(self) -> Callable[..., np.ndarray] | None:
        """The unnormalized axis c(u), a PchipInterpolator (None when the axis is constant over the pass)."""
        z = None if self.motion is None else self.motion.z
        return z.c if isinstance(z, UnitAxis) else None

    def to_state(self) -> dict:
        """The data of the field, for the saved-job file (:mod:`planner.jobfile`): the axis functions are not
        data, they are built from the path's CAM-point parameters and the axes (:meth:`from_state`)."""
        return {"path": self.path, "axes": self.axes, "start": self.start,
                "motion": None if self.motion is None else self.motion.to_state()}

    @classmethod
    def from_state(cls, state: dict) -> AxisField:
        """The field from :meth:`to_state` fields read back: the spin table about the axis :func:`axis_field`
        interpolates (the PCHIP of the axes over ``path.waypoint_knots``, built when first evaluated)."""
        path, axes, motion = state["path"], state["axes"], state["motion"]
        if motion is not None:
            motion = SpinTable.from_state(motion, UnitAxis(path.waypoint_knots, axes))
        return cls(path, axes, motion, state["start"])

    def axis(self, u) -> np.ndarray:
        """Tool axis (n, 3) at path parameters u (n,)."""
        u = np.atleast_1d(np.asarray(u, dtype=float))
        if self.interpolant is None:
            return np.broadcast_to(self.start[:, 2], (u.size, 3)).copy()
        return _unit(self.interpolant(u))

    def quaternions(self, u) -> np.ndarray:
        """Unit quaternions (n, 4) (scalar first) of the frames at u (n,), signs continuous."""
        u = np.atleast_1d(np.asarray(u, dtype=float))
        if self.motion is None:
            return np.broadcast_to(matrix_to_quaternion(self.start[None])[0], (u.size, 4)).copy()
        return self.motion.quaternion(u)

    def frames(self, u) -> np.ndarray:
        """Tool frames (n, 3, 3) at path parameters u (n,): columns x, y, z (z the approach axis)."""
        u = np.atleast_1d(np.asarray(u, dtype=float))
        if self.motion is None:
            return np.broadcast_to(self.start, (u.size, 3, 3)).copy()
        return quaternion_to_matrix(self.motion.quaternion(u))

    def at_length(self, s) -> np.ndarray:
        """Tool frames at arc lengths s (n,) from the start of the pass (metres)."""
        return self.frames(self.path.parameter_at_length(s))

    @cached_property
    def end(self) -> np.ndarray:
        """Frame at the end of the pass (3, 3) (evaluated once: the plan, the spin and the checks all ask for it)."""
        return self.frames(self.path.knots[-1:])[0]

    def axis_errors(self) -> np.ndarray:
        """Angle (m,) between the frames' tool axis and the given axis at each CAM point, radians."""
        F = self.frames(self.path.waypoint_knots)
        return angle_between(F[:, :, 2], self.axes)


def _clenshaw(C: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Chebyshev series sum_j C[i, j] T_j(x[i]) (n,) for per-sample coefficient rows C (n, d) (Clenshaw)."""
    b1 = np.zeros_like(x)
    b2 = np.zeros_like(x)
    for j in range(C.shape[1] - 1, 0, -1):
        b1, b2 = 2.0 * x * b1 - b2 + C[:, j], b1
    return x * b1 - b2 + C[:, 0]


@dataclass(frozen=True, eq=False)
class SpinTable(PieceBasedRMM):
    """The exact RMM of z(u) as a table: reference motion from a base direction plus a spin.

    Frame at u (juttler seed Prop. 1 and eq. 3): F(u) = q_ref(b, z(u)) q_base spin(theta(u)), with
    q_ref the shortest-arc rotation from the piece's base direction b to z(u), q_base the frame at the
    piece start, and theta(u) = int b.(z x z') / (1 + b.z) du, which cancels the reference motion's
    spin about z. theta is stored per panel as the integral of the Chebyshev interpolant of its rate
    (CHEB_N points of the first kind), panels being halved until the series' last two coefficients
    are below ``PANEL_TOL`` rad: evaluation is a Clenshaw sum per sample.

    Attributes
    ----------
    coeffs : ndarray (k, CHEB_N + 1)
        Chebyshev coefficients of theta - spin_start on each panel, in x = 2 (u - a) / (b - a) - 1;
        the others as in :class:`~planner.frames.spherical_rmm.PieceBasedRMM` (t is u here).
    """

    coeffs: np.ndarray

    def to_state(self) -> dict:
        """The table's arrays, for the saved-job file (:mod:`planner.jobfile`); z and dz are the owner's (not
        data: :meth:`AxisField.from_state` rebuilds them)."""
        return {"pieces": self.pieces, "bases": self.bases, "base_quaternions": self.base_quaternions,
                "panels": self.panels, "panel_piece": self.panel_piece, "spin_start": self.spin_start,
                "coeffs": self.coeffs}

    @classmethod
    def from_state(cls, state: dict, z: UnitAxis) -> SpinTable:
        """The table from :meth:`to_state` fields read back, about the unit axis ``z`` (its ``dz`` the derivative)."""
        return cls(z, z.dz, **state)

    def spin(self, u) -> np.ndarray:
        """theta(u) (n,), radians, relative to the base frame of u's piece."""
        return self._spin(np.atleast_1d(np.asarray(u, dtype=float)))[0]

    def _spin(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        k = np.clip(np.searchsorted(self.panels, u, side="right") - 1, 0, self.panel_piece.size - 1)
        a, b = self.panels[k], self.panels[k + 1]
        x = np.clip(2.0 * (u - a) / (b - a) - 1.0, -1.0, 1.0)
        return self.spin_start[k] + _clenshaw(self.coeffs[k], x), k

    def quaternion(self, u) -> np.ndarray:
        """Unit quaternions (n, 4) of the frames at u (n,)."""
        u = np.atleast_1d(np.asarray(u, dtype=float))
        theta, k = self._spin(u)
        return self._frames_on_panels(k, self.z(u), theta)


#: Chebyshev points per spin panel.
CHEB_N = 16
_CHEB_X = np.cos(np.pi * (np.arange(CHEB_N) + 0.5) / CHEB_N)  # points of the first kind, in (-1, 1)
# values at the points -> coefficients: c_k = (2 - delta_k0) / N sum_j f_j T_k(x_j) (discrete orthogonality)
_CHEB_M = (2.0 / CHEB_N) * np.cos(np.outer(np.arange(CHEB_N), np.pi * (np.arange(CHEB_N) + 0.5) / CHEB_N))
_CHEB_M[0] *= 0.5


def _panel_series(z, dz, bases, a, b, own) -> tuple[np.ndarray, np.ndarray]:
    """Chebyshev coefficients (k, N) of the spin rate on panels [a, b], and of its integral (k, N + 1).

    The integral's series is in x in [-1, 1] and vanishes at x = -1; it includes the factor (b - a) / 2.
    """
    half = 0.5 * (b - a)
    u = ((a + half)[:, None] + half[:, None] * _CHEB_X).ravel()
    f = spin_rate(np.repeat(bases[own], CHEB_N, axis=0), z(u), dz(u)).reshape(a.size, CHEB_N)
    c = f @ _CHEB_M.T
    C = np.polynomial.chebyshev.chebint(c, m=1, lbnd=-1.0, axis=1) * half[:, None]
    return c, C


def _rmm(z, dz, knots: np.ndarray, F0: np.ndarray) -> SpinTable:
    """The RMM of z on [knots[0], knots[-1]], panels aligned with the knots (see :class:`SpinTable`)."""
    # pieces: renew the base direction at a knot before z gets MAX_BASE_ANGLE away from it
    grid = np.unique(np.concatenate((knots, 0.5 * (knots[1:] + knots[:-1]))))
    zg = z(grid)
    starts = base_starts(zg, MAX_BASE_ANGLE)
    pieces = np.append(grid[starts], knots[-1])
    bases = zg[starts]
    breaks = np.unique(np.concatenate((knots, pieces)))
    a, b = breaks[:-1], breaks[1:]
    owner = np.clip(np.searchsorted(pieces, a, side="right") - 1, 0, len(starts) - 1)
    width_min = 1e-12 * (knots[-1] - knots[0])
    done = []
    for _ in range(60):
        c, C = _panel_series(z, dz, bases, a, b, owner)
        tail = 0.5 * (b - a) * (np.abs(c[:, -1]) + np.abs(c[:, -2]))
        good = (tail <= PANEL_TOL) | (b - a <= width_min)
        done.append((a[good], b[good], owner[good], C[good]))
        if good.all():
            break
        bad = ~good
        mid = 0.5 * (a + b)
        a, b, owner = (np.concatenate((a[bad], mid[bad])), np.concatenate((mid[bad], b[bad])),
                       np.concatenate((owner[bad], owner[bad])))
    else:  # pragma: no cover - the rate is smooth between knots, so halving resolves it
        done.append((a, b, owner, _panel_series(z, dz, bases, a, b, owner)[1]))
    pa, pb, po, C = (np.concatenate([x[i] for x in done]) for i in range(4))
    order = np.argsort(pa)
    pa, pb, po, C = pa[order], pb[order], po[order], C[order]
    total = np.polynomial.chebyshev.chebval(1.0, C.T)  # theta over each whole panel
    spin_start, base_q = chain_pieces(pa, total, po, pieces, bases, matrix_to_quaternion(F0[None])[0])
    return SpinTable(z, dz, pieces, bases, base_q, np.append(pa, pb[-1]), po, spin_start, C)


def axis_field(path, axes, start=None) -> AxisField:
    """Tool frames along a pass about the given tool axes, interpolated without overshoot.

    Parameters
    ----------
    path : PHSpline
        The pass's path; ``path.waypoint_knots`` are the parameters of the CAM points.
    axes : array_like (m, 3)
        Tool approach axis at each CAM point (nonzero; normalized here). Neighbouring axes may be
        up to (not including) 180 degrees apart; the split into passes keeps them within 90.
    start : array_like (3, 3), optional
        Frame at the start; its column 2 is replaced by turning it without spin onto the first
        axis (so the previous move's end frame can be passed as is). Default: column 0 along the
        direction of travel.

    Returns
    -------
    AxisField
    """
    a = _unit(np.asarray(axes, dtype=float))
    u = path.waypoint_knots
    if a.shape != (u.size, 3):
        raise ValueError(f"axes: expected one axis per CAM point, shape ({u.size}, 3), got {a.shape}")
    if start is None:
        F0 = frame_with_axis(a[0], path.tangent(path.knots[:1])[0])
    else:
        F0 = transport(np.asarray(start, dtype=float), a[0])
    if np.ptp(a, axis=0).max() == 0.0:
        return AxisField(path, a, None, F0)
    z = UnitAxis(u, a)
    return AxisField(path, a, _rmm(z, z.dz, u, F0), F0)


@dataclass(frozen=True, eq=False)
class UnitAxis:
    """The unit tool axis z(u) = c(u) / |c(u)| and its derivative dz/du, c the PCHIP of unit axes (m, 3) over
    parameters u (m,) (component by component, see the module docstring; built when first evaluated)."""

    u: np.ndarray
    axes: np.ndarray

    @cached_property
    def c(self) -> PchipInterpolator:
        """The unnormalized axis c(u)."""
        return PchipInterpolator(self.u, self.axes, axis=0)

    @cached_property
    def dc(self) -> PchipInterpolator:
        """dc/du."""
        return self.c.derivative()

    def __call__(self, x) -> np.ndarray:
        return _unit(self.c(np.asarray(x, dtype=float)))

    def dz(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        v = self.c(x)
        n = np.linalg.norm(v, axis=1, keepdims=True)
        zz = v / n
        d = self.dc(x)
        return (d - np.sum(d * zz, axis=1, keepdims=True) * zz) / n


def arc_departure(z: np.ndarray, a0: np.ndarray, a1: np.ndarray) -> np.ndarray:
    """Spherical distance (n, k) of unit vectors z (n, k, 3) from the great-circle arcs a0 -> a1 (n, 3).

    The distance to the shorter arc from a0 to a1 (the path a 5-axis machine takes between two CAM
    points): to the arc's great circle where z projects inside the arc, else to the nearer end.
    """
    n = np.cross(a0, a1)
    nn = np.linalg.norm(n, axis=1)
    ends = np.minimum(angle_between(z, a0[:, None]), angle_between(z, a1[:, None]))
    ok = nn > 1e-12
    n = n / np.where(ok, nn, 1.0)[:, None]
    off = np.einsum("nkd,nd->nk", z, n)
    proj = z - off[:, :, None] * n[:, None, :]
    # inside the arc: the projection lies between a0 and a1 (on the a1 side of a0 and vice versa)
    inside = (np.einsum("nkd,nd->nk", np.cross(a0[:, None], proj), n) >= 0.0) & (
        np.einsum("nkd,nd->nk", np.cross(proj, a1[:, None]), n) >= 0.0)
    plane = np.arcsin(np.clip(np.abs(off), 0.0, 1.0))
    return np.where(ok[:, None] & inside, plane, ends)


def axis_departure(field: AxisField, samples: int = 16) -> float:
    """Largest distance (radians) of the interpolated axis from the CAM's great-circle arcs between
    consecutive CAM points (sampled ``samples`` + 1 times per span); 0 for a constant axis."""
    if field.interpolant is None:
        return 0.0
    k = field.path.waypoint_knots
    u = k[:-1, None] + np.diff(k)[:, None] * np.linspace(0.0, 1.0, samples + 1)
    z = field.axis(u.ravel()).reshape(u.shape + (3,))
    return float(arc_departure(z, field.axes[:-1], field.axes[1:]).max())


def _relative_spin(F0: np.ndarray, F1: np.ndarray) -> np.ndarray:
    """Spin (n,) about the tool axis of the slerps from frames F0 to F1 (n, 3, 3), radians.

    A slerp turns with constant body angular velocity, whose component along the tool axis (body z)
    is the z component of the rotation vector of F0^T F1 (its size is returned).
    """
    return np.abs(matrix_to_rotvec(np.matmul(np.swapaxes(F0, 1, 2), F1))[:, 2])


def spin_about_axis(frames: np.ndarray) -> float:
    """Total spin about the tool axis (radians) of a sequence of frames (n, 3, 3) slerped pairwise."""
    F = np.asarray(frames, dtype=float)
    if F.shape[0] < 2:
        return 0.0
    return float(_relative_spin(F[:-1], F[1:]).sum())


def travel_frames(points: np.ndarray, axes: np.ndarray, last: np.ndarray | None = None) -> np.ndarray:
    """The naive CAM orientations (m, 3, 3): tool z = axis, x = direction of travel projected off z.

    What a point-to-point robot program built from the CAM data commands (the baseline the
    rotation-minimizing spin is compared with). The direction of travel at a point is its outgoing
    chord (incoming at the last point of a pass; ``last`` marks them when several passes are
    concatenated). Where the travel is along the axis, any perpendicular x is taken.
    """
    P = np.asarray(points, dtype=float)
    z = _unit(np.asarray(axes, dtype=float))
    if last is None:
        last = np.zeros(P.shape[0], dtype=bool)
        last[-1] = True
    t = np.empty_like(P)
    t[:-1] = P[1:] - P[:-1]
    t[last] = (P[1:] - P[:-1])[np.flatnonzero(last) - 1]
    x = t - np.einsum("ij,ij->i", t, z)[:, None] * z
    n = np.linalg.norm(x, axis=1)
    bad = n < 1e-9 * np.maximum(np.linalg.norm(t, axis=1), 1e-300)
    if bad.any():
        e = np.eye(3)[np.argmin(np.abs(z[bad]), axis=1)]
        x[bad] = e - np.einsum("ij,ij->i", e, z[bad])[:, None] * z[bad]
        n = np.linalg.norm(x, axis=1)
    x = x / n[:, None]
    return np.stack((x, np.cross(z, x), z), axis=2)


def travel_spin(point_sets, axis_sets) -> np.ndarray:
    """Spin (k,) about the tool axis, radians, of the naive CAM orientations (:func:`travel_frames`)
    slerped point to point along each of k passes (points (m_i, 3), tool axes (m_i, 3))."""
    sizes = np.array([len(p) for p in point_sets])
    if sizes.size == 0:
        return np.zeros(0)
    P = np.concatenate(point_sets)
    starts = np.concatenate(([0], np.cumsum(sizes)[:-1]))
    last = np.zeros(P.shape[0], dtype=bool)
    last[starts + sizes - 1] = True
    F = travel_frames(P, np.concatenate(axis_sets), last)
    step = np.concatenate((_relative_spin(F[:-1], F[1:]), [0.0]))
    step[last] = 0.0  # no slerp across passes
    return np.add.reduceat(step, starts)
