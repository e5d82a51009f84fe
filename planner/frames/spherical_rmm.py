"""Rotation-minimizing motion of a smooth curve z(t) on the unit sphere (Jüttler 1998, sec. 2 and 7.2).

Use: the tool axis z(t) is prescribed (e.g. by CAD surface normals) and only the spin about it is
free. Frames are (n, 3, 3) with column 2 = z(t); the RMM is the motion whose angular velocity is
z x z' (seed Prop. 1, eq. 5), i.e. with no component along z.

Exact construction: a reference motion that is the shortest-arc rotation from a base direction b
to z(t), q(t) = (1 + b.z, b x z) / sqrt(2 (1 + b.z)), applied to a frame F_b on b, followed by a spin
theta(t) about the moving axis. By eq. (3) the spin must cancel the reference's component along z,
which is omega_ref . z = -b.(z x z') / (1 + b.z); so theta(t) = int b.(z x z') / (1 + b.z) dt. The
integral is computed by adaptive composite Gauss-Legendre quadrature (panels refined until a panel's
rule agrees with its two halves to 1e-14 rad), so the spin is exact to round-off level. The base b is
renewed (b = z at the piece start, F_b = the frame there) before z gets farther than 120 degrees from
it, which keeps 1 + b.z >= 1/2 away from the singularity z = -b.

The rational approximation (seed secs. 5, 6) replaces z by a spherical biarc spline and takes the
chain of Jüttler's rational arc motions.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from planner import quaternion as quat
from planner.errors import ConvergenceError
from planner.frames import validation as val
from planner.frames.piecewise_motion import PiecewiseArcMotion
from planner.frames.spherical_biarc import fit_spherical_biarcs
from planner.frames.validation import FrameDataError
from planner.rotations import matrix_to_quaternion, quaternion_to_matrix
from planner.validation import finite_floats

#: Gauss-Legendre order of each quadrature panel.
GL_ORDER = 16
#: Absolute accuracy (rad) asked of each panel.
PANEL_TOL = 1e-14
#: Largest angle (rad) between z and the base direction of its piece: 1 + b.z >= 1/2.
MAX_BASE_ANGLE = 2.0 * np.pi / 3.0

_GL_X, _GL_W = np.polynomial.legendre.leggauss(GL_ORDER)


def base_starts(zg: np.ndarray, max_angle: float = MAX_BASE_ANGLE) -> list[int]:
    """Indices into samples zg (m, 3) of a curve on the sphere where a new base direction starts: each
    base is used until z comes within one sample of ``max_angle`` (rad) from it, so that the
    shortest-arc reference 1 + b.z stays away from 0."""
    starts, j = [0], 0
    while True:
        far = np.flatnonzero(zg[j:] @ zg[j] < np.cos(max_angle))
        if far.size == 0:
            return starts
        j = j + max(int(far[0]) - 1, 1)
        starts.append(j)


def spin_rate(b: np.ndarray, z: np.ndarray, dz: np.ndarray) -> np.ndarray:
    """theta' = b.(z x z') / (1 + b.z), (n,): minus the reference motion's spin about z (seed eq. 3)."""
    return np.einsum("ij,ij->i", b, np.cross(z, dz)) / (1.0 + np.einsum("ij,ij->i", b, z))


def shortest_arc_quaternions(b: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Unit quaternions (n, 4) of the shortest-arc rotations taking b to z."""
    s = 1.0 + np.einsum("ij,ij->i", b, z)
    q = np.concatenate((s[:, None], np.cross(b, z)), axis=1)
    return q / np.sqrt(2.0 * s)[:, None]


def based_quaternions(bases: np.ndarray, base_quaternions: np.ndarray, z: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Unit quaternions (n, 4) of the frames q_ref(b, z) q_base spin(theta) (seed eq. 3).

    q_ref is the shortest-arc rotation from the base direction b (n, 3) to the axis z (n, 3), q_base
    (n, 4) the frame at the piece start (its column 2 on b), spin(theta) the turn by theta (n,) rad
    about the frame's column 2.
    """
    half = theta / 2
    zero = np.zeros_like(theta)
    spin = np.stack((np.cos(half), zero, zero, np.sin(half)), axis=1)
    return quat.mul(quat.mul(shortest_arc_quaternions(bases, z), base_quaternions), spin)


def chain_pieces(panel_starts: np.ndarray, panel_spins: np.ndarray, panel_piece: np.ndarray, pieces: np.ndarray,
                 bases: np.ndarray, q0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Spins at the panel starts and frames at the piece starts of a piecewise-based RMM.

    Parameters
    ----------
    panel_starts : ndarray (k,)
        Sorted panel start parameters; ``panel_spins`` (k,) the spin (rad) over each whole panel,
        ``panel_piece`` (k,) each panel's piece.
    pieces : ndarray (p + 1,)
        Piece breakpoints; ``bases`` (p, 3) the pieces' base directions (piece j ends on bases[j + 1]).
    q0 : ndarray (4,)
        Unit quaternion of the frame at the first piece start.

    Returns
    -------
    spin_start : ndarray (k,)
        Spin (rad) at each panel start, restarted at 0 at each piece start.
    base_quaternions : ndarray (p, 4)
        Frames at the piece starts, each the end frame of the previous piece.
    """
    cum = np.concatenate(([0.0], np.cumsum(panel_spins)))
    first_panel = np.searchsorted(panel_starts, pieces[:-1])
    spin_start = cum[:-1] - cum[first_panel][panel_piece]
    last = first_panel[1:] - 1
    end_spins = spin_start[last] + panel_spins[last]
    q = np.empty((len(bases), 4))
    q[0] = q0
    for j in range(1, len(bases)):  # each start needs the previous one: a short sequential product
        q[j] = based_quaternions(bases[j - 1 : j], q[j - 1 : j], bases[j : j + 1], end_spins[j - 1 : j])[0]
    return spin_start, q


@dataclass(frozen=True, eq=False)
class PieceBasedRMM:
    """An RMM of z(t) on the sphere stored as pieces and spin panels (seed eq. 3).

    The frame at t is ``based_quaternions(b, q_base, z(t), theta(t))`` with b, q_base the base
    direction and start frame of t's piece and theta(t) the spin from that frame; subclasses say how
    theta is evaluated on a panel (:class:`ExactSphericalRMM`: adaptive quadrature;
    :class:`planner.cam.axes.SpinTable`: Chebyshev series).

    Attributes
    ----------
    z, dz : callable
        The curve t (m,) -> unit vectors (m, 3) and its derivative.
    pieces : ndarray (p + 1,)
        Parameters where the base direction is renewed.
    bases : ndarray (p, 3)
        Base direction b of each piece (= z at the piece start).
    base_quaternions : ndarray (p, 4)
        Unit quaternions of the frames at the piece starts (signs continuous).
    panels : ndarray (k + 1,)
        Panel breakpoints (the pieces' breakpoints among them).
    panel_piece : ndarray (k,)
        Piece of each panel.
    spin_start : ndarray (k,)
        Spin theta (rad) at the start of each panel, relative to its piece's base frame.
    """

    z: Callable[..., np.ndarray]
    dz: Callable[..., np.ndarray]
    pieces: np.ndarray
    bases: np.ndarray
    base_quaternions: np.ndarray
    panels: np.ndarray
    panel_piece: np.ndarray
    spin_start: np.ndarray

    def _frames_on_panels(self, k: np.ndarray, z: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """Unit quaternions (n, 4) of the frames with axes z (n, 3) and spins theta (n,) rad on panels k (n,)."""
        piece = self.panel_piece[k]
        return based_quaternions(self.bases[piece], self.base_quaternions[piece], z, theta)


@dataclass(frozen=True, eq=False)
class ExactSphericalRMM(PieceBasedRMM):
    """The exact RMM of z(t) on [t0, t1], frames with column 2 = z(t); the spin on a panel by
    Gauss-Legendre quadrature from its start (see :class:`PieceBasedRMM` for the attributes)."""

    def _locate(self, t):
        t = np.atleast_1d(finite_floats(t, "t"))
        lo, hi = self.panels[0], self.panels[-1]
        slack = 1e-12 * max(1.0, abs(lo), abs(hi))
        bad = ~np.isfinite(t) | (t < lo - slack) | (t > hi + slack)
        if bad.any():
            i = int(np.argmax(bad))
            raise FrameDataError(f"= {t[i]!r} is outside the parameter range [{lo}, {hi}]", "t", i)
        t = np.clip(t, lo, hi)
        k = np.clip(np.searchsorted(self.panels, t, side="right") - 1, 0, self.panel_piece.shape[0] - 1)
        return t, k

    def spin(self, t) -> np.ndarray:
        """Spin theta(t) (n,) (rad) about the axis, relative to the base frame of t's piece."""
        t, k = self._locate(t)
        return self._spin(t, k)

    def _spin(self, t, k):
        a = self.panels[k]
        half = 0.5 * (t - a)
        s = (a + half)[:, None] + half[:, None] * _GL_X  # Gauss-Legendre nodes on [a, t]
        n, m = s.shape
        flat = s.ravel()
        zs = val.curve_values(self.z, flat, "z", True)
        ds = val.curve_values(self.dz, flat, "dz", False)
        b = np.repeat(self.bases[self.panel_piece[k]], m, axis=0)
        f = spin_rate(b, zs, ds).reshape(n, m)
        return self.spin_start[k] + half * (f @ _GL_W)

    def _eval(self, t):
        t, k = self._locate(t)
        z = val.curve_values(self.z, t, "z", True)
        return self._frames_on_panels(k, z, self._spin(t, k)), t, self.bases[self.panel_piece[k]], z

    def quaternion(self, t) -> np.ndarray:
        """Unit quaternions (n, 4) of the frames at t (n,), signs continuous."""
        return self._eval(t)[0]

    def frames(self, t) -> np.ndarray:
        """Frames (n, 3, 3) at t (n,): column 2 = z(t), columns 0, 1 rotation-minimizing."""
        return quaternion_to_matrix(self._eval(t)[0])

    def angular_velocity(self, t) -> np.ndarray:
        """Angular velocity (n, 3) (rad per unit t): omega_ref + theta' z (seed eq. 3); equals z x z'."""
        _, t, b, z = self._eval(t)
        dz = val.curve_values(self.dz, t, "dz", False)
        s, v = 1.0 + np.einsum("ij,ij->i", b, z), np.cross(b, z)
        ds, dv = np.einsum("ij,ij->i", b, dz), np.cross(b, dz)
        # omega = 2 vec(p' p*) / |p|^2 for p = (s, v) (seed eq. 7), |p|^2 = 2 s
        omega_ref = (s[:, None] * dv - ds[:, None] * v + np.cross(v, dv)) / s[:, None]
        return omega_ref + spin_rate(b, z, dz)[:, None] * z


def _panel_rule(f: Callable, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    half = 0.5 * (b - a)
    s = (a + half)[:, None] + half[:, None] * _GL_X
    return half * (f(s.ravel()).reshape(s.shape) @ _GL_W)


def _check_derivative(z: Callable, dz: Callable, lo: float, hi: float) -> None:
    """Compare dz with central differences of z at a few interior points; raise if they disagree."""
    ts = lo + (hi - lo) * np.array([0.1123, 0.3571, 0.5, 0.6667, 0.8919])
    h = 1e-6 * (hi - lo)
    fd = (val.curve_values(z, ts + h, "z", True) - val.curve_values(z, ts - h, "z", True)) / (2 * h)
    d = val.curve_values(dz, ts, "dz", False)
    err = np.linalg.norm(fd - d, axis=1)
    limit = 1e-5 * (np.linalg.norm(d, axis=1).max() + 1.0 / (hi - lo))
    if (err > limit).any():
        i = int(np.argmax(err > limit))
        raise FrameDataError(f"does not match the derivative of z at t = {ts[i]!r} "
                             f"(dz = {d[i]}, finite differences {fd[i]})", "dz")


def exact_spherical_rmm(z: Callable, dz: Callable, start=None, *, interval: tuple[float, float] = (0.0, 1.0),
                        max_panels: int = 1 << 16) -> ExactSphericalRMM:
    """The exact rotation-minimizing motion of a smooth curve z(t) on the unit sphere.

    Parameters
    ----------
    z : callable
        t (m,) -> unit vectors (m, 3), the prescribed axis (e.g. the tool axis), C1 at least.
    dz : callable
        t (m,) -> (m, 3), the derivative of z (checked against finite differences at a few points).
    start : array (3, 3), optional
        Frame at t0: right-handed orthonormal with column 2 = z(t0). Default: the shortest-arc
        rotation taking e1 to z(t0), columns shifted so that z is column 2.
    interval : (float, float)
        Parameter interval [t0, t1].
    max_panels : int
        Upper bound on the quadrature panels.

    Returns
    -------
    ExactSphericalRMM
        ``frames(t)``, ``quaternion(t)``, ``angular_velocity(t)`` (rad per unit t), ``spin(t)``.

    Raises
    ------
    FrameDataError
        Non-unit or non-finite z, dz inconsistent with z, bad start frame or interval.
    ConvergenceError
        If the spin integrand cannot be resolved (z not smooth).
    """
    lo, hi = (val.finite_scalar(v, "interval") for v in interval)
    if not hi > lo:
        raise FrameDataError(f"must satisfy t0 < t1, got {interval}", "interval")
    _check_derivative(z, dz, lo, hi)
    z0 = val.curve_values(z, np.array([lo]), "z", True)[0]
    f0 = val.default_frame(z0, 2) if start is None else val.frame(start, "start", z0, 2)
    q0 = matrix_to_quaternion(f0)

    # pieces: renew the base before z is MAX_BASE_ANGLE away from it (checked on a fine grid)
    grid = np.linspace(lo, hi, 4097)
    zg = val.curve_values(z, grid, "z", True)
    starts = base_starts(zg)
    pieces = np.append(grid[starts], hi)
    bases = zg[starts]

    # adaptive Gauss-Legendre panels inside each piece, all pieces at once per level
    a = np.concatenate([np.linspace(pieces[p], pieces[p + 1], 9)[:-1] for p in range(len(starts))])
    b = np.concatenate([np.linspace(pieces[p], pieces[p + 1], 9)[1:] for p in range(len(starts))])
    owner = np.repeat(np.arange(len(starts)), 8)
    done_a, done_b, done_v, done_p = [], [], [], []
    while a.size:
        def rate(s, own=owner):
            m = s.size // own.size
            b_s = np.repeat(bases[own], m, axis=0)
            return spin_rate(b_s, val.curve_values(z, s, "z", True), val.curve_values(dz, s, "dz", False))

        mid = 0.5 * (a + b)
        whole = _panel_rule(rate, a, b)
        halves = _panel_rule(rate, a, mid) + _panel_rule(rate, mid, b)
        good = np.abs(whole - halves) <= PANEL_TOL * np.maximum(1.0, np.abs(halves))
        done_a.append(a[good])
        done_b.append(b[good])
        done_v.append(halves[good])
        done_p.append(owner[good])
        bad = ~good
        if bad.any() and ((b - a)[bad].min() < 1e-10 * (hi - lo) or sum(x.size for x in done_a) > max_panels):
            i = int(np.flatnonzero(bad)[0])
            raise ConvergenceError("exact spherical RMM: the spin integral does not converge near "
                                   f"t = {a[i]:.9g} (z may have a corner there)")
        a, b, owner = (np.concatenate((a[bad], mid[bad])), np.concatenate((mid[bad], b[bad])),
                       np.concatenate((owner[bad], owner[bad])))
    a, b, v, own = (np.concatenate(x) for x in (done_a, done_b, done_v, done_p))
    order = np.argsort(a)
    a, b, v, own = a[order], b[order], v[order], own[order]

    # spins at the panel starts (0 at each piece start), frames at the piece starts (the previous end frames)
    spin_start, base_q = chain_pieces(a, v, own, pieces, bases, q0)
    panels = np.append(a, b[-1])
    return ExactSphericalRMM(z, dz, pieces, bases, base_q, panels, own, spin_start)


def rational_spherical_rmm(z: Callable, dz: Callable | None = None, tol: float = 1e-4, start=None, *,
                           interval: tuple[float, float] = (0.0, 1.0)) -> PiecewiseArcMotion:
    """Jüttler's rational approximation of the RMM of z(t): biarc spline + rational arc motions.

    Parameters
    ----------
    z, dz : callable
        The curve on the unit sphere and (optionally) its derivative, as in :func:`exact_spherical_rmm`.
    tol : float
        Tolerance (rad) of the spherical biarc spline approximating z (seed sec. 5).
    start : array (3, 3), optional
        Frame at t0 with column 2 = z(t0).
    interval : (float, float)
        Parameter interval.

    Returns
    -------
    PiecewiseArcMotion
        Rational motion (degree 6 per arc) with column 2 on the biarc spline (within ``tol`` of z and
        equal to z at the biarcs' Hermite knots); ``.exact()`` is the exact RMM of the biarc spline.
    """
    spline = fit_spherical_biarcs(z, tol, dz=dz, interval=interval)
    return spline.rmm(start=start, axis_column=2)
