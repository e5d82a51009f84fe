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

from planner.curves.ph_curve import PHSegment
from planner.errors import PlannerError
from planner.validation import check_vector

# ---------------------------------------------------------------------------------------------
# C1 Hermite interpolation (Farouki's family with two free angles)
# ---------------------------------------------------------------------------------------------

_CC_GRID = 24
_CC_NEWTON = 3

# The kernel below works on component rows: a quaternion array is (4, N), a vector array (3, N), so that
# every arithmetic operation runs on a contiguous row of N segments (the fitters call it for thousands).


def _sqrt_rot(v: np.ndarray) -> np.ndarray:
    """Rows (4, N) of a quaternion A with A i A* = v, for vector rows v (3, N) (sqrt|v| rotate_i_to(v))."""
    l, m, n = v
    r = np.sqrt(l * l + m * m + n * n)
    with np.errstate(invalid="ignore", divide="ignore"):  # v = 0 gives A = 0 (nan masked below)
        inv = np.where(r > 0, 1.0 / r, 0.0)
    lam, mu, nu = l * inv, m * inv, n * inv
    pos = lam >= 0
    c = 1.0 + np.abs(lam)
    scale = np.sqrt(r / (2.0 * c))  # see quaternion.rotate_i_to for the two branches
    return np.stack(
        (
            np.where(pos, c, -nu) * scale,
            np.where(pos, 0.0, mu) * scale,
            np.where(pos, -nu, c) * scale,
            np.where(pos, mu, 0.0) * scale,
        )
    )


def _i_product(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Vector part of p i q* on rows, (3, N) (quaternion.i_product)."""
    p0, p1, p2, p3 = p
    q0, q1, q2, q3 = q
    return np.stack(
        (
            p0 * q0 + p1 * q1 - p2 * q2 - p3 * q3,
            p1 * q2 + p2 * q1 + p0 * q3 + p3 * q0,
            p1 * q3 + p3 * q1 - p0 * q2 - p2 * q0,
        )
    )


def _times_e_i(q: np.ndarray, c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """q e^{i phi} on rows, with c = cos phi and s = sin phi."""
    w, x, y, z = q
    return np.stack((c * w - s * x, c * x + s * w, c * y + s * z, c * z - s * y))


def _dot(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Row-wise inner products (N,) of component rows."""
    return np.einsum("ij,ij->j", p, q)


class _CCMeasure:
    """The CC measure of the Hermite family as a cheap trigonometric function of delta = phi2 - phi0.

    min over phi0 of |5 (A0 + A2) - Q|^2 = 25 |X|^2 + |alpha| - 10 sqrt((|alpha| |X|^2 + <X i X*, alpha>) / 2)
    with X = a0 + a2 e^{i delta}, because max_phi <X e^{i phi}, Q> = |(w0, w1)| for w = Q* X, and
    w0^2 + w1^2 = (|w|^2 + (w i w*)_i) / 2 = (|alpha| |X|^2 + <X i X*, alpha>) / 2. Everything is a
    trigonometric polynomial in delta: ``P`` = |X|^2 holds the per-segment coefficients on the basis
    (1, cos, sin) of delta, ``G`` = |alpha|^2 and ``H`` = <X i X*, alpha> on (1, cos, sin, cos 2 delta,
    sin 2 delta), as rows (3, N) and (5, N). Inputs are component rows (a0, a2: (4, N); base, e: (3, N)).
    """

    def __init__(self, a0, a2, base, e):
        Sc = _i_product(a0, a2)  # i_product(a0, a2 e^{i delta}) = Sc c + Ss s
        a2i = np.stack((-a2[1], a2[0], a2[3], -a2[2]))  # a2 i
        Ss = _i_product(a0, a2i)
        V = np.stack((base, Sc, Ss, e))  # (4, 3, N): every inner product needed, in one einsum
        D = np.einsum("aik,bik->abk", V, V)
        (bb, bc, bs, be), (_, cc, cs, ce), (_, _, ss, se) = D[0], D[1], D[2]
        self.P = np.stack((_dot(a0, a0) + _dot(a2, a2), 2 * _dot(a0, a2), 2 * _dot(a0, a2i)))
        # on (1, c, s, c^2, cs, s^2): G = (bb, 20 bc, 20 bs, 100 cc, 200 cs, 100 ss),
        # H = (be, 10 ce + 2 bc, 10 se + 2 bs, 20 cc, 40 cs, 20 ss); c^2, s^2 = (1 +- cos 2d)/2, cs = sin 2d / 2
        self.G = np.stack((bb + 50 * (cc + ss), 20 * bc, 20 * bs, 50 * (cc - ss), 100 * cs))
        self.H = np.stack((be + 10 * (cc + ss), 10 * ce + 2 * bc, 10 * se + 2 * bs, 10 * (cc - ss), 20 * cs))

    @staticmethod
    def _basis(delta):
        """(5, ...) rows 1, cos, sin, cos 2 delta, sin 2 delta."""
        c, s = np.cos(delta), np.sin(delta)
        return np.stack((np.ones_like(c), c, s, c * c - s * s, 2 * c * s))

    @staticmethod
    def _measure(P, G, H):
        """F from P, G, H (overwrites G and H)."""
        alpha = np.sqrt(np.abs(G, out=G), out=G)  # |alpha|^2 >= 0 up to round-off
        H += alpha * P  # 2 (w0^2 + w1^2) >= 0 up to round-off
        r = np.sqrt(np.abs(H, out=H), out=H)
        return 25 * P + alpha - (10 / np.sqrt(2)) * r

    def on_grid(self, delta):
        """Measure (K, N) at the same K values of delta (K,) for every segment (three matrix products)."""
        b = self._basis(delta).T
        return self._measure(b[:, :3] @ self.P, b @ self.G, b @ self.H)

    def _rows(self, rows):
        if rows is None:
            return self.P, self.G, self.H
        return self.P[:, rows], self.G[:, rows], self.H[:, rows]

    def __call__(self, delta, rows=None):
        """Measure at per-segment values delta (N,) (or (len(rows),) for a subset of segments)."""
        X, G_, H_ = self._rows(rows)
        b = self._basis(delta)
        return self._measure(_dot(X, b[:3]), _dot(G_, b), _dot(H_, b))

    def newton(self, delta, steps: int, rows=None):
        """Newton iterations on dF/d delta = 0, exact first and second derivatives; delta (N,)
        (or (len(rows),) for a subset of segments)."""
        X, G_, H_ = self._rows(rows)
        C = np.zeros((3, 5, X.shape[1]))  # coefficients of P, G, H on (1, c, s, cos 2d, sin 2d)
        C[0, :3], C[1], C[2] = X, G_, H_
        B = np.empty((3, 5, X.shape[1]))  # the basis and its first and second derivatives in delta
        B[0, 0], B[1:, 0] = 1.0, 0.0
        with np.errstate(all="ignore"):  # cusps of the measure (alpha or r = 0) give inf/nan
            for _ in range(steps):
                c, s = np.cos(delta), np.sin(delta)
                C2, S2 = c * c - s * s, 2 * c * s  # cos 2 delta, sin 2 delta
                B[0, 1:] = c, s, C2, S2
                B[1, 1:] = -s, c, -2 * S2, 2 * C2
                B[2, 1:] = -c, -s, -4 * C2, -4 * S2
                (P, G, H), (P1, G1, H1), (P2, G2, H2) = np.einsum("gkn,dkn->dgn", C, B)
                a = np.sqrt(np.maximum(G, 1e-300))  # alpha = sqrt(G) and its derivatives
                a1 = G1 / (2 * a)
                a2 = (G2 - 2 * a1 * a1) / (2 * a)
                r = np.sqrt(np.maximum(0.5 * (a * P + H), 1e-300))  # r = sqrt(Y)
                r1 = 0.25 * (a1 * P + a * P1 + H1) / r
                r2 = (0.5 * (a2 * P + 2 * a1 * P1 + a * P2 + H2) - 2 * r1 * r1) / (2 * r)
                F1 = 25 * P1 + a1 - 10 * r1
                F2 = 25 * P2 + a2 - 10 * r2
                step = F1 / F2
                step[~((F2 > 0) & np.isfinite(step))] = 0.0
                delta = delta - np.clip(step, -0.2, 0.2)
        return delta


def _cc_delta(a0, a2, base, e) -> np.ndarray:
    """phi2 - phi0 (N,) of the member closest to a PH cubic, searched globally (see batch_hermite)."""
    cc = _CCMeasure(a0, a2, base, e)
    n, k, h = a0.shape[1], _CC_GRID, 2 * np.pi / _CC_GRID
    cols = np.arange(n)
    grid = np.arange(k) * h
    Fg = cc.on_grid(grid)  # (K, N)
    first = np.argmin(Fg, axis=0)
    fm, f0, fp = Fg[first - 1, cols], Fg[first, cols], Fg[(first + 1) % k, cols]
    # start Newton from the vertex of the parabola through the best grid point and its neighbours
    curv = fm - 2 * f0 + fp
    with np.errstate(all="ignore"):
        off = np.where(curv > 0, 0.5 * h * (fm - fp) / curv, 0.0)
    delta = cc.newton(grid[first] + np.clip(off, -h, h), _CC_NEWTON)
    f = cc(delta)
    worse = ~(f <= f0)
    delta[worse], f[worse] = grid[first[worse]], f0[worse]
    # a second basin whose best grid point (away from the first's neighbours) is nearly as good: Newton there too
    Fg[first - 1, cols] = Fg[first, cols] = Fg[(first + 1) % k, cols] = np.inf
    second = np.argmin(Fg, axis=0)
    amb = np.flatnonzero(Fg[second, cols] < 1.5 * f0 + 1e-12 * cc.P[0])
    if amb.size:
        d2 = cc.newton(grid[second[amb]], _CC_NEWTON, amb)
        better = cc(d2, amb) < f[amb]
        delta[amb[better]] = d2[better]
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
    p0, p1, d0, d1 = (np.asarray(x, dtype=float).T for x in (p0, p1, d0, d1))
    a0, a2 = _sqrt_rot(d0), _sqrt_rot(d1)
    base = 120.0 * (p1 - p0) - 15.0 * (d0 + d1)
    n = p0.shape[1]
    if angles is None:
        delta = _cc_delta(a0, a2, base, d0 + d1)
    else:
        phi0 = np.broadcast_to(np.asarray(angles[0], dtype=float), (n,))
        delta = np.broadcast_to(np.asarray(angles[1], dtype=float), (n,)) - phi0
    a2d = _times_e_i(a2, np.cos(delta), np.sin(delta))  # a2 e^{i delta}
    Q = _sqrt_rot(base + 10.0 * _i_product(a0, a2d))  # Farouki: (3A0+4A1+3A2) i (..)* = alpha
    if angles is None:  # A0 + A2 = (a0 + a2d) e^{i phi0}; phi0 maximizes <(a0 + a2d) e^{i phi0}, Q>
        B = a0 + a2d
        phi0 = np.arctan2(_dot(np.stack((-B[1], B[0], B[3], -B[2])), Q), _dot(B, Q))
    c0, s0 = np.cos(phi0), np.sin(phi0)
    A0 = _times_e_i(a0, c0, s0)
    A2 = _times_e_i(a2d, c0, s0)  # a2 e^{i phi2}
    A1 = -0.75 * (A0 + A2) + 0.25 * Q  # Farouki's solution of the end-point condition
    return np.stack((A0, A1, A2)).transpose(2, 0, 1).copy()


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
