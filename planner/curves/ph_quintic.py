"""Spatial Pythagorean-hodograph quintics from quadratic quaternion polynomials.

A(t) = (1-t)^2 A0 + 2(1-t)t A1 + t^2 A2 (quaternions), hodograph r'(t) = A(t) i A*(t), speed
sigma(t) = |A(t)|^2 (grm seed, sections 2.1-2.2). Everything here is exact polynomial algebra: the arc
length is a quintic polynomial in t, so lengths and their inversion need no quadrature.

The functions prefixed ``batch_`` work on stacks of quintics (A of shape (..., 3, 4)); the spline
fitters use them to build thousands of segments at numpy speed. :class:`PHQuintic` is the
one-segment view with the documented public API.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner import quaternion as qt
from planner.curves.ph_curve import PHSegment
from planner.errors import PlannerError
from planner.validation import check_vector

# ---------------------------------------------------------------------------------------------
# C1 Hermite interpolation (Farouki's family with two free angles)
# ---------------------------------------------------------------------------------------------

_CC_GRID = 24


def _cc_alpha_q(a0, a2, base, delta):
    """alpha = Q i Q* and Q (phase 0) for phase offset delta = phi2 - phi0; shapes (N, 3), (N, 4)."""
    a2d = qt.mul(a2, qt.exp_i(delta))  # a2 e^{i delta}
    alpha = base + 10.0 * qt.i_product(a0, a2d)  # Farouki: (3A0+4A1+3A2) i (..)* = alpha
    anorm = np.linalg.norm(alpha, axis=-1)
    safe = np.where(anorm[..., None] > 0, alpha, np.array([1.0, 0.0, 0.0]))
    return a2d, np.sqrt(anorm)[..., None] * qt.rotate_i_to(safe)


class _CCMeasure:
    """The CC measure of the Hermite family as a cheap trigonometric function of delta = phi2 - phi0.

    min over phi0 of |5 (A0 + A2) - Q|^2 = 25 |X|^2 + |alpha| - 10 sqrt((|alpha| |X|^2 + <X i X*, alpha>) / 2)
    with X = a0 + a2 e^{i delta}, because max_phi <X e^{i phi}, Q> = |(w0, w1)| for w = Q* X, and
    w0^2 + w1^2 = (|w|^2 + (w i w*)_i) / 2 = (|alpha| |X|^2 + <X i X*, alpha>) / 2. Everything is a
    trigonometric polynomial in delta with per-segment coefficients precomputed here.
    """

    def __init__(self, a0, a2, base, d0, d1):
        Sc = qt.i_product(a0, a2)
        a2i = qt.mul(a2, qt.I)
        Ss = qt.i_product(a0, a2i)
        e = d0 + d1
        dot = qt.dot
        bc, bs = dot(base, Sc), dot(base, Ss)
        cc, cs, ss = dot(Sc, Sc), dot(Sc, Ss), dot(Ss, Ss)
        z = np.zeros_like(cc)
        # coefficients on the basis (1, c, s, c^2, c s, s^2) of |X|^2, |alpha|^2 and <X i X*, alpha>
        self.X2 = np.stack((qt.norm2(a0) + qt.norm2(a2), 2 * dot(a0, a2), 2 * dot(a0, a2i), z, z, z), 1)
        self.al2 = np.stack((dot(base, base), 20 * bc, 20 * bs, 100 * cc, 200 * cs, 100 * ss), 1)
        ec, es = 10 * dot(e, Sc) + 2 * bc, 10 * dot(e, Ss) + 2 * bs
        self.xa = np.stack((dot(e, base), ec, es, 20 * cc, 40 * cs, 20 * ss), 1)

    @staticmethod
    def _basis(delta):
        c, s = np.cos(delta), np.sin(delta)
        return np.stack((np.ones_like(c), c, s, c * c, c * s, s * s), axis=-2)

    def on_grid(self, delta):
        """Measure (N, K) at the same K values of delta (K,) for every segment (three matrix products)."""
        b = self._basis(delta)
        alpha = np.sqrt(np.maximum(self.al2 @ b, 0.0))
        X2 = self.X2 @ b
        return 25 * X2 + alpha - 10 * np.sqrt(np.maximum(0.5 * (alpha * X2 + self.xa @ b), 0.0))

    def __call__(self, delta, rows=None):
        """Measure at per-segment values delta (N, K) (or (len(rows), K) for a subset of segments)."""
        sel = slice(None) if rows is None else rows
        X, G_, H_ = (C[sel].T[..., None] for C in (self.X2, self.al2, self.xa))
        c, s = np.cos(delta), np.sin(delta)
        cc, cs, ss = c * c, c * s, s * s
        P = X[0] + X[1] * c + X[2] * s
        G = G_[0] + G_[1] * c + G_[2] * s + G_[3] * cc + G_[4] * cs + G_[5] * ss
        H = H_[0] + H_[1] * c + H_[2] * s + H_[3] * cc + H_[4] * cs + H_[5] * ss
        alpha = np.sqrt(np.maximum(G, 0.0))
        return 25 * P + alpha - 10 * np.sqrt(np.maximum(0.5 * (alpha * P + H), 0.0))

    def newton(self, delta, steps: int, rows=None):
        """Newton iterations on dF/d delta = 0, exact first and second derivatives; delta (N, m)
        (or (len(rows), m) for a subset of segments)."""
        sel = slice(None) if rows is None else rows
        X, G_, H_ = (np.ascontiguousarray(C[sel].T)[..., None] for C in (self.X2, self.al2, self.xa))
        for _ in range(steps):
            c, s = np.cos(delta), np.sin(delta)
            cc, cs, ss = c * c, c * s, s * s
            d1 = cc - ss  # basis (1, c, s, c^2, cs, s^2); first derivative (0, -s, c, -2cs, c^2-s^2, 2cs)
            # second derivative (0, -c, -s, -2(c^2-s^2), -4cs, 2(c^2-s^2))
            P = X[0] + X[1] * c + X[2] * s
            P1 = X[2] * c - X[1] * s
            P2 = -X[1] * c - X[2] * s
            G = G_[0] + G_[1] * c + G_[2] * s + G_[3] * cc + G_[4] * cs + G_[5] * ss
            G1 = G_[2] * c - G_[1] * s + 2 * cs * (G_[5] - G_[3]) + G_[4] * d1
            G2 = -G_[1] * c - G_[2] * s + 2 * d1 * (G_[5] - G_[3]) - 4 * G_[4] * cs
            H = H_[0] + H_[1] * c + H_[2] * s + H_[3] * cc + H_[4] * cs + H_[5] * ss
            H1 = H_[2] * c - H_[1] * s + 2 * cs * (H_[5] - H_[3]) + H_[4] * d1
            H2 = -H_[1] * c - H_[2] * s + 2 * d1 * (H_[5] - H_[3]) - 4 * H_[4] * cs
            with np.errstate(all="ignore"):  # cusps of the measure (alpha or r = 0) give inf/nan
                a = np.sqrt(np.maximum(G, 1e-300))  # alpha = sqrt(G) and its derivatives
                a1 = G1 / (2 * a)
                a2 = (G2 - 2 * a1 * a1) / (2 * a)
                r = np.sqrt(np.maximum(0.5 * (a * P + H), 1e-300))  # r = sqrt(Y)
                r1 = 0.25 * (a1 * P + a * P1 + H1) / r
                r2 = (0.5 * (a2 * P + 2 * a1 * P1 + a * P2 + H2) - 2 * r1 * r1) / (2 * r)
                F1 = 25 * P1 + a1 - 10 * r1
                F2 = 25 * P2 + a2 - 10 * r2
                convex = F2 > 0
                step = np.where(convex, F1 / np.where(convex, F2, 1.0), 0.0)
            step = np.where(np.isfinite(step), step, 0.0)
            delta = delta - np.clip(step, -0.2, 0.2)
        return delta


def batch_hermite(p0, p1, d0, d1, angles=None) -> np.ndarray:
    """Quaternion coefficients A (N, 3, 4) of PH quintics with r(0)=p0, r(1)=p1, r'(0)=d0, r'(1)=d1.

    Inputs have shape (N, 3). With ``angles`` = (phi0, phi2) (scalars or (N,) arrays) the member
    A0 = sqrt|d0| n(d0) e^{i phi0}, A2 = sqrt|d1| n(d1) e^{i phi2}, A1 = -(3/4)(A0 + A2) + Q/4 with
    Q i Q* = 120 (p1 - p0) - 15 (d0 + d1) + 5 (A0 i A2* + A2 i A0*) and Q's phase fixed to 0 (the common
    phase of A0, A1, A2 does not change the curve) is returned. With ``angles=None`` the member closest
    to a PH cubic is chosen: the angles minimizing |A0 - 2 A1 + A2|^2 (the "CC" criterion of Farouki,
    Giannelli, Manni, Sestini 2008; zero exactly when the ordinary cubic Hermite interpolant is PH, which
    is then reproduced). Global over phi2 - phi0 (grid of 24, Newton from the best point and, where
    the second best is nearly as good, from it too), closed form in phi0.
    """
    p0, p1, d0, d1 = (np.asarray(x, dtype=float) for x in (p0, p1, d0, d1))
    a0 = np.sqrt(np.linalg.norm(d0, axis=-1))[:, None] * qt.rotate_i_to(d0)
    a2 = np.sqrt(np.linalg.norm(d1, axis=-1))[:, None] * qt.rotate_i_to(d1)
    base = 120.0 * (p1 - p0) - 15.0 * (d0 + d1)
    n = p0.shape[0]
    if angles is None:
        cc = _CCMeasure(a0, a2, base, d0, d1)
        grid = np.arange(_CC_GRID) * (2 * np.pi / _CC_GRID)
        Fg = cc.on_grid(grid)
        two = np.argpartition(Fg, 1, axis=1)[:, :2]
        rows = np.arange(n)
        best = grid[two[:, :1]]
        cand = np.concatenate((best, cc.newton(best, 4)), axis=1)  # Newton from the best grid point
        f = cc(cand)
        delta, fbest = cand[rows, np.argmin(f, axis=1)], f.min(axis=1)
        # where the second-best grid point is nearly as good, the basin is ambiguous: Newton from it too
        amb = np.flatnonzero(Fg[rows, two[:, 1]] < 1.5 * Fg[rows, two[:, 0]] + 1e-12 * np.abs(Fg).max(axis=1))
        if amb.size:
            c2 = cc.newton(grid[two[amb, 1:]], 4, amb)
            f2 = cc(c2, amb)[:, 0]
            better = f2 < fbest[amb]
            delta[amb[better]] = c2[better, 0]
        a2d, Q = _cc_alpha_q(a0, a2, base, delta)
        B = a0 + a2d  # A0 + A2 = B e^{i phi0}; phi0 maximizes <B e^{i phi0}, Q>
        phi0 = np.arctan2(qt.dot(qt.mul(B, qt.I), Q), qt.dot(B, Q))
        phi2 = phi0 + delta
    else:
        phi0 = np.broadcast_to(np.asarray(angles[0], dtype=float), (n,))
        phi2 = np.broadcast_to(np.asarray(angles[1], dtype=float), (n,))
        _, Q = _cc_alpha_q(qt.mul(a0, qt.exp_i(phi0)), a2, base, phi2)
    A0 = qt.mul(a0, qt.exp_i(phi0))
    A2 = qt.mul(a2, qt.exp_i(phi2))
    A1 = -0.75 * (A0 + A2) + 0.25 * Q  # Farouki's solution of the end-point condition
    return np.stack((A0, A1, A2), axis=-2)


# ---------------------------------------------------------------------------------------------
# Public one-segment class
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class PHQuintic(PHSegment):
    """A spatial PH quintic r(t), t in [0, 1], with hodograph r'(t) = A(t) i A*(t).

    Parameters
    ----------
    A : ndarray (3, 4)
        Bernstein coefficients A0, A1, A2 of the quadratic quaternion polynomial (scalar, i, j, k).
    p0 : ndarray (3,)
        Start point r(0) (metres).

    All evaluation methods take a parameter array t of shape (n,) (or a scalar) and are vectorized.
    """

    M = 3
    NAME = "PHQuintic"

    # -- constructors ------------------------------------------------------------------------
    @classmethod
    def from_quaternions(cls, A0, A1, A2, p0=(0.0, 0.0, 0.0)) -> PHQuintic:
        """The PH quintic with A(t) = (1-t)^2 A0 + 2(1-t)t A1 + t^2 A2 and r(0) = p0."""
        return cls(np.array([A0, A1, A2], dtype=float), np.asarray(p0, dtype=float))

    @classmethod
    def hermite(cls, p0, p1, d0, d1, angles: tuple[float, float] | None = None) -> PHQuintic:
        """C1 Hermite interpolant: r(0) = p0, r(1) = p1, r'(0) = d0, r'(1) = d1 (metres, metres/unit t).

        The PH quintic interpolants form a two-parameter family (Farouki's free angles phi0, phi2).
        ``angles=(phi0, phi2)`` (radians) selects a member explicitly; the default (None) picks the
        member closest to a PH cubic (see :func:`batch_hermite`), which reproduces the ordinary cubic
        Hermite interpolant whenever that is itself a PH curve.
        """
        p0 = check_vector(p0, "p0")
        p1 = check_vector(p1, "p1")
        d0 = check_vector(d0, "d0", nonzero=True)
        d1 = check_vector(d1, "d1", nonzero=True)
        if angles is not None:
            angles = tuple(float(a) for a in angles)
            if len(angles) != 2 or not np.isfinite(angles).all():
                raise PlannerError(f"angles must be two finite numbers (phi0, phi2), got {angles}")
        A = batch_hermite(p0[None], p1[None], d0[None], d1[None], angles)[0]
        return cls(A, p0)
