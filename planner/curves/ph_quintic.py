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
#: Newton evaluations from the starts of the global grid search (rough data, where the certificate fails).
_CC_SEARCH_EVALS = 6
#: Newton evaluations on the CC measure from the alpha-criterion start (most segments converge after one).
_CC_EVALS = 4
#: A Newton step has converged when its predicted decrease is below this fraction of F plus ...
_CC_RTOL = 1e-9
#: ... this fraction of the data scale 25 (|d0| + |d1|) (F's terms are a few times it: some 1000 ulps).
_CC_ATOL = 3e-13
#: Half-width (rad) of the arc around the fast path's angle within which the certificate must place the
#: global minimum (0.25 rad from the returned angle); segments whose certified arc is wider get the global
#: grid search ...
_CERT_ARC = 0.24
_CERT_X = float(np.sin(_CERT_ARC / 2) ** 2)
#: ... and the returned angle is the last Newton step (at most this, rad) from where it was certified.
_CERT_STEP = 0.01
_FLIP = np.array([2, 3, 0, 1])
_IPERM, _ISIGN = np.array([1, 0, 3, 2]), np.array([[-1.0], [1.0], [1.0], [-1.0]])  # <B i, Q> = sum B[_IPERM] Q _ISIGN


def _products_matrix() -> np.ndarray:
    """(8, 16): rows (vec, scalar) of p i q* and of p q* from the 16 products p_k q_l (row 4 k + l)."""
    M = np.zeros((8, 16))
    terms = (  # (row, k, l, sign)
        [(0, 0, 0, 1), (0, 1, 1, 1), (0, 2, 2, -1), (0, 3, 3, -1), (1, 1, 2, 1), (1, 2, 1, 1), (1, 0, 3, 1)]
        + [(1, 3, 0, 1), (2, 1, 3, 1), (2, 3, 1, 1), (2, 0, 2, -1), (2, 2, 0, -1)]
        + [(3, 0, 1, 1), (3, 1, 0, -1), (3, 3, 2, 1), (3, 2, 3, -1)]
        + [(4, 1, 0, 1), (4, 0, 1, -1), (4, 3, 2, 1), (4, 2, 3, -1), (5, 2, 0, 1), (5, 0, 2, -1), (5, 1, 3, 1)]
        + [(5, 3, 1, -1), (6, 3, 0, 1), (6, 0, 3, -1), (6, 2, 1, 1), (6, 1, 2, -1)]
        + [(7, 0, 0, 1), (7, 1, 1, 1), (7, 2, 2, 1), (7, 3, 3, 1)]
    )
    for row, k, l_, sign in terms:
        M[row, 4 * k + l_] = sign
    return M


_PRODUCTS = _products_matrix()

# The kernel below works on component rows: a quaternion array is (4, N), a vector array (3, N), so that
# every arithmetic operation runs on a contiguous row of N segments (the fitters call it for thousands).


def sqrt_rot(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows (4, N) of a quaternion A with A i A* = v, for vector rows v (3, N), and |v| = |A|^2 (N,).

    A = (r + |l|, 0, -n, m) / sqrt(2 (r + |l|)) for l >= 0 and (-n, m, r + |l|, 0) / sqrt(2 (r + |l|)) for
    l < 0, with v = (l, m, n) and r = |v| (sqrt|v| quaternion.rotate_i_to(v), its two branches); v = 0 gives 0.
    """
    l, m, n = v
    r = np.sqrt(l * l + m * m + n * n)
    q = r + np.abs(l)
    k = 1.0 / np.sqrt(np.maximum(q + q, 1e-300))
    X = np.empty((4,) + r.shape)
    np.multiply(q, k, out=X[0])
    X[1] = 0.0
    np.multiply(n, -k, out=X[2])
    np.multiply(m, k, out=X[3])
    return np.where(l < 0, X[_FLIP], X), r


def _i_product(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Vector part of p i q* on rows, (3, N) (quaternion.i_product)."""
    p0, p1, p2, p3 = p
    q0, q1, q2, q3 = q
    out = np.empty((3,) + p0.shape)
    out[0] = p0 * q0 + p1 * q1 - p2 * q2 - p3 * q3
    out[1] = p1 * q2 + p2 * q1 + p0 * q3 + p3 * q0
    out[2] = p1 * q3 + p3 * q1 - p0 * q2 - p2 * q0
    return out


def _times_e_i(q: np.ndarray, c: np.ndarray, s: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """q e^{i phi} on rows, with c = cos phi and s = sin phi."""
    w, x, y, z = q
    if out is None:
        out = np.empty(q.shape)
    np.subtract(c * w, s * x, out=out[0])
    np.add(c * x, s * w, out=out[1])
    np.add(c * y, s * z, out=out[2])
    np.subtract(c * z, s * y, out=out[3])
    return out


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
    sin 2 delta), as rows (3, N) and (5, N).

    With S(delta) = i_product(a0, a2 e^{i delta}) = Sc cos + Ss sin, sigma = (sigma_c, sigma_s) the scalar
    parts of a0 i a2*, a0 a2* (orthogonal to those of the vector parts: |S|^2 = |a0|^2 |a2|^2 - (sigma.z)^2,
    z = (cos, sin)), alpha = base + 10 S and X i X* = e + 2 S:
    P = P0 + 2 sigma.z_perp, G = G0 + 20 mb.z - 100 (sigma.z)^2, H = G / 5 + K0 + l.z, with
    mb = (Sc.base, Ss.base), l = 10 (Sc.e, Ss.e) - 2 mb (the "linear forms" Lc, Ls of ``_cc_eval``).
    """

    P: np.ndarray
    G: np.ndarray
    H: np.ndarray

    @classmethod
    def from_forms(cls, Lc, Ls, P0, G0, K0):
        """The measure from the forms of _cc_eval: (10 sigma, 20 mb, l) as rows Lc (cos parts), Ls (sin parts)."""
        self = cls.__new__(cls)
        sc, ss = 0.1 * Lc[0], 0.1 * Ls[0]
        # (sigma.z)^2 = |sigma|^2 / 2 + (sc^2 - ss^2) cos 2 delta / 2 + sc ss sin 2 delta
        self.P = np.stack((P0, 2 * ss, -2 * sc))
        G = (G0 - 50 * (sc * sc + ss * ss), Lc[1], Ls[1], 50 * (ss * ss - sc * sc), -100 * sc * ss)
        self.G = np.stack(G)
        self.H = 0.2 * self.G
        self.H[0] += K0
        self.H[1] += Lc[2]
        self.H[2] += Ls[2]
        return self

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


def _cc_grid_starts(cc: _CCMeasure):
    """Starts of the global search over a grid of 24 values of delta: the vertex of the parabola through the
    best grid point and its neighbours (N,), that best value (N,), and where another basin's best grid point
    (away from the first's neighbours) is nearly as good, those segments' indices and that point."""
    n, k, h = cc.P.shape[1], _CC_GRID, 2 * np.pi / _CC_GRID
    cols = np.arange(n)
    grid = np.arange(k) * h
    Fg = cc.on_grid(grid)  # (K, N)
    first = np.argmin(Fg, axis=0)
    fm, f0, fp = Fg[first - 1, cols], Fg[first, cols], Fg[(first + 1) % k, cols]
    curv = fm - 2 * f0 + fp
    with np.errstate(all="ignore"):
        off = np.where(curv > 0, 0.5 * h * (fm - fp) / curv, 0.0)
    Fg[first - 1, cols] = Fg[first, cols] = Fg[(first + 1) % k, cols] = np.inf
    second = np.argmin(Fg, axis=0)
    amb = np.flatnonzero(Fg[second, cols] < 1.5 * f0 + 1e-12 * cc.P[0])
    return grid[first] + np.clip(off, -h, h), f0, amb, grid[second[amb]]


def _alpha_start(sc, ss, bc, bs, s2):
    """(cos, sin) (N,) of a start at the global minimum of T = |S(delta) - w|^2 over the circle, and |sigma|.

    With z = (cos delta, sin delta) and M = [Sc Ss]: M^T M = |a0|^2 |a2|^2 I - sigma sigma^T (see _CCMeasure),
    so T = |w|^2 + |a0|^2 |a2|^2 - (sigma.z)^2 - 2 b.z with b = M^T w = (bc, bs), and its minimum over the
    circle is a 2 x 2 trust-region subproblem: in the frame u = sigma / |sigma|, z = (x, y), |b.u| = b1,
    |b.u_perp| = b2: x = b1 / t, y = b2 / (s2 + t), t > 0 the root of g(t) = (b1 / t)^2 + (b2 / (s2 + t))^2 = 1
    (Lagrange multiplier s2 + t >= s2: the global minimum). Here t is the largest of three lower bounds of
    that root, t >= b1 / x_c from x <= x_c, the positive root of the cubic b1 + (s2 - b2) x - b2 x^3 / 2
    (1/sqrt(1 - x^2) >= 1 + x^2 / 2), and z(t) is put on the circle: exact to O(x^5) where the minimum is flat
    (x small: w near the tip of a thin ellipse S, where Newton in delta converges slowly), in the global
    minimum's basin elsewhere, where Newton on the CC measure converges fast. (1/sqrt(g) is concave, so
    Newton on g(t) = 1 from there would rise monotonically to the root; on smooth and on random data a
    step of it spares no later Newton step on the measure.)
    """
    sn = np.sqrt(s2)  # sigma = 0 (no frame) gives nan: left to the grid search
    isn = 1.0 / sn
    uc, us = sc * isn, ss * isn
    B1 = uc * bc + us * bs
    B2 = uc * bs - us * bc
    b1, b2 = np.abs(B1), np.abs(B2)
    # Cardano for x^3 + 3 p3 x - 2 qh = 0, p3 = 2 (b2 - s2) / (3 b2), qh = b1 / b2: with disc >= 0 the real root
    # A - p3 / A = 2 qh / (A^2 + p3 + (p3 / A)^2) (A^2 >= -p3 there: no cancellation), which is >= 2 sqrt(-p3)
    # when p3 < 0; with three real roots (disc < 0) the largest is at most 2 sqrt(-p3) (so the fmax of the two)
    ib2 = 1.0 / b2
    p3 = (b2 - s2) * ib2 * (2.0 / 3.0)
    qh = b1 * ib2
    disc = qh * qh + p3 * p3 * p3
    A = np.cbrt(np.sqrt(np.abs(disc)) + qh)
    B = p3 / A
    xc = np.fmax((qh + qh) / (A * A + p3 + B * B), np.sqrt(-4.0 * p3))
    t = np.fmax(np.fmax(b1, b2 - s2), b1 / xc)  # t >= b1 (x <= 1), s2 + t >= b2 (y <= 1), t >= b1 / x_c
    x, y = b1 / t, b2 / (s2 + t)
    ir = 1.0 / np.sqrt(x * x + y * y)  # onto the circle
    x, y = np.copysign(x * ir, B1), np.copysign(y * ir, B2)
    return uc * x - us * y, us * x + uc * y, sn


def _cc_eval(forms, c, s, derivs=True):
    """The CC measure F (N,) at z = (c, s) = e^{i delta} and |u| + |v| = 25 P + a; with ``derivs`` also
    dF/d delta, d^2F/d delta^2 (after F) and the values Lz, Lp of the linear forms (last).

    forms = (Lc, Ls, P0, G0, K0): the linear forms (10 sigma, 20 mb, l, b) of _CCMeasure as rows of cos and
    sin coefficients, Lz = Lc c + Ls s and Lp = Ls c - Lc s (the derivative in delta), and the constants.
    F = 25 P + a - 10 r with P = P0 + 2 sigma.z_perp, a = |alpha| = sqrt(G), G = G0 + 20 mb.z - 100 (sigma.z)^2,
    r = sqrt((a P + H) / 2), H = G / 5 + K0 + l.z.
    """
    Lc, Ls, P0, G0, K0 = forms
    Lz, Lp = Lc * c + Ls * s, Ls * c - Lc * s
    sz, mz, lz = Lz[:3]
    sp, mp, lp = Lp[:3]
    P = P0 + 0.2 * sp
    q = sz * sz
    G = G0 + mz - q
    a = np.sqrt(G)
    r = np.sqrt(0.5 * (a * P + 0.2 * G + K0 + lz))
    Sg = 25.0 * P + a
    F = Sg - 10.0 * r
    if not derivs:
        return F, Sg
    G1 = mp - 2.0 * sz * sp  # P' = -sz / 5, P'' = -sp / 5
    G2 = 2.0 * (q - sp * sp) - mz
    ia = 0.5 / a
    a1 = G1 * ia
    a2 = (G2 - 2.0 * a1 * a1) * ia
    ir = 0.25 / r
    r1 = (a1 * P + 0.2 * (G1 - a * sz) + lp) * ir
    r2 = (a2 * P + 0.2 * (G2 - 2.0 * a1 * sz - a * sp) - lz - 4.0 * r1 * r1) * ir
    return F, a1 - 5.0 * sz - 10.0 * r1, a2 - 5.0 * sp - 10.0 * r2, Sg, Lz, Lp


def _cc_newton(forms, c, s, atol, evals=_CC_EVALS, clip=None):
    """Newton on dF/d delta = 0 from z = (c, s), at most ``evals`` evaluations of F, F', F'' (later ones only
    on the segments not yet converged). A step has converged when F'' > 0 and its predicted decrease is below
    _CC_RTOL F + atol; at a flat (quartic) minimum a Newton step leaves 16/81 of the excess, 8/27 of the
    predicted decrease, and near a regular one far less. Returns z after the last step, whether that step
    had converged, and (z, F, 25 P + |alpha|, the linear forms, the step) where it was taken."""
    F, F1, F2, Sg, Lz, Lp = _cc_eval(forms, c, s)
    step = F1 / np.abs(F2)  # a descent step also where F'' <= 0
    if clip is not None:  # far from the minimum (the grid search's starts)
        step = np.fmax(np.fmin(step, clip), -clip)
    conv = (F2 > 0) & (0.5 * F1 * step <= _CC_RTOL * F + atol)
    at = (c, s, F, Sg, Lz, Lp, step)
    k = 1.0 / np.sqrt(1.0 + step * step)
    c, s = (c + step * s) * k, (s - step * c) * k  # z e^{-i atan(step)}
    if evals > 1 and not conv.all():
        idx = np.flatnonzero(~conv)
        sub = tuple(f[..., idx] for f in forms)
        c[idx], s[idx], conv[idx], sub = _cc_newton(sub, c[idx], s[idx], atol[idx], evals - 1, clip)
        for full, part in zip(at, sub, strict=True):
            full[..., idx] = part
    return c, s, conv, at


def _cc_member(base, e, w, a0, a2, r0, r1):
    """(cos, sin) (N,) of delta = phi2 - phi0 of the member minimizing the CC measure, and S(delta) (3, N).

    Fast path: start at the global minimum of the alpha criterion |S(delta) - w|^2 (w = 3 (p1 - p0) - (d0 + d1),
    zero exactly for PH-cubic data; see _alpha_start), then Newton on F. A certificate then proves, per
    segment, that the global minimum of F lies within _CERT_ARC of where the last Newton step was taken;
    segments without it (Newton not converged, or the bound too weak) get the global grid search and
    Newton from the better of its result and the fast one.
    """
    n = base.shape[1]
    # the products a0 i a2* = (sigma_c, Sc) and a0 a2* = (sigma_s, Ss): S(delta) = Sc cos + Ss sin
    R = _PRODUCTS @ np.multiply(a0[:, None], a2[None]).reshape(16, n)
    Sc, Ss = R[:3], R[4:7]
    sc, ss = R[3], R[7]
    s2 = sc * sc + ss * ss
    lam = r0 * r1  # |a0|^2 |a2|^2
    Lc, Ls = np.empty((4, n)), np.empty((4, n))  # linear forms (10 sigma, 20 mb, l, b), see _cc_eval
    np.multiply(sc, 10.0, out=Lc[0])
    np.multiply(ss, 10.0, out=Ls[0])
    mc, ms, ec, es = _dot(Sc, base), _dot(Ss, base), _dot(Sc, e), _dot(Ss, e)
    np.multiply(mc, 20.0, out=Lc[1])
    np.multiply(ms, 20.0, out=Ls[1])
    Lc[2], Ls[2] = 10.0 * ec - 2.0 * mc, 10.0 * es - 2.0 * ms
    Lc[3], Ls[3] = _dot(Sc, w), _dot(Ss, w)  # b = M^T w
    bb = _dot(base, base)
    scale = 25.0 * (r0 + r1)
    forms = (Lc, Ls, r0 + r1, bb + 100.0 * lam, _dot(base, e) - 0.2 * bb)
    atol = _CC_ATOL * scale
    T0 = _dot(w, w) + lam
    with np.errstate(all="ignore"):  # degenerate data give inf/nan, caught by the certificate
        c, s, sn = _alpha_start(sc, ss, Lc[3], Ls[3], s2)
        c, s, conv, (c0, s0, F, Sg, (sz, _, _, bz), (sp, _, _, bp), step) = _cc_newton(forms, c, s, atol)
        # Certificate. For the fibres over u = 25 X i X* and v = alpha (nearest points A, B; Hopf map),
        # |u - v|^2 = F (2 Sg - F) exactly with Sg = |u| + |v| = 25 P + |alpha|, and u - v = 40 (S - w): so
        # F = Sg - sqrt(Sg^2 - 1600 T) >= 800 T / Sg, with T = |S - w|^2 the alpha criterion. P and alpha are
        # affine in z, so Sg(z') <= Sg(z) + L |z' - z|, L = 50 |sigma| + 10 |a0| |a2|, and
        # Sg <= Smax = 25 (|a0| + |a2|)^2 + |base| + 10 |a0| |a2|.
        Ff = F * (1.0 + 1e-12) + 1e-13 * scale  # F and Sg with their round-off
        rl = np.sqrt(lam)
        rx = np.sqrt(_CERT_X)
        Sbound = np.fmin(scale + 60.0 * rl + np.sqrt(bb), Sg + (100.0 * rx) * sn + (20.0 * rx) * rl)
        # Exactly, T(z') - T(z) = (z' - z)^T K (z' - z) - 2 gamma sin(theta) for z' = z e^{i theta}, with
        # K = M^T M - lambda I, lambda = z^T (M^T M z - b) (kappa = |a0|^2 |a2|^2 - lambda), gamma = T'(z) / 2,
        # and T(z) = |w|^2 + |a0|^2 |a2|^2 - (sigma.z)^2 - 2 b.z = T0 - kappa - b.z (sz, sp are 10 sigma.z, ...)
        kappa = 0.01 * (sz * sz) + bz
        Tz = T0 - kappa - bz  # the alpha criterion where the last step was taken
        mu = kappa - s2  # smallest eigenvalue of K; shifted to K + neg I >= 0, paid for below
        neg = np.fmax(-mu, 0.0)
        k11, k22 = bz + neg, kappa - 0.01 * (sp * sp) + neg  # z^T K z, z_perp^T K z_perp
        # With x = sin^2(theta / 2), |z' - z| = 2 sqrt(x), |sin(theta)| <= 2 sqrt(x) and (z' - z)^T K (z' - z) =
        # 4 x (k11 x - 2 k12 sqrt(x (1 - x)) + k22 (1 - x)) >= 4 x max(mu, (sqrt(k11 x) - sqrt(k22))_+^2)
        # (k12^2 <= k11 k22). So F(z') > F wherever h(x) = 800 (T(z) + that - 4 |gamma| sqrt(x) - 4 neg x)
        # - F min(Smax, Sg + 2 L sqrt(x)) > 0; h is convex with h(0) < 0, so h(x_max) > 0 proves it for every
        # |theta| >= _CERT_ARC: the global minimum lies in that arc. (T(z) less a margin for its cancellation.)
        Q = (4.0 * _CERT_X) * np.fmax(mu, np.fmax(np.sqrt(k11 * _CERT_X) - np.sqrt(k22), 0.0) ** 2)
        Q -= (4.0 * rx) * np.abs(0.01 * (sz * sp) + bp) + (4.0 * _CERT_X) * neg + 1e-13 * (T0 + lam)
        bad = np.flatnonzero(~(conv & (800.0 * (Tz + Q) > Ff * Sbound) & (np.abs(step) <= _CERT_STEP)))
        if bad.size:  # the global search: Newton from the grid's best basin (or the fast result where that is lower
            # than the grid's best) and from a second basin nearly as good; the best of them
            sub = (Lc[:, bad], Ls[:, bad], forms[2][bad], forms[3][bad], forms[4][bad])
            start, fg, amb, start2 = _cc_grid_starts(_CCMeasure.from_forms(*sub))
            nb = bad.size
            both = np.concatenate((np.arange(nb), amb))  # both basins' starts in one Newton run
            fast = _cc_eval(sub, c[bad], s[bad], derivs=False)[0] <= fg
            d = np.concatenate((start, start2))
            cb, sb = np.cos(d), np.sin(d)
            cb[:nb][fast], sb[:nb][fast] = c[bad][fast], s[bad][fast]
            sub2 = tuple(f[..., both] for f in sub)
            cb, sb = _cc_newton(sub2, cb, sb, atol[bad][both], _CC_SEARCH_EVALS, 0.2)[:2]
            Fb = _cc_eval(sub2, cb, sb, derivs=False)[0]
            worse = ~(Fb[:nb] <= fg)  # Newton lost: the grid point
            cb[:nb][worse], sb[:nb][worse], Fb[:nb][worse] = np.cos(start[worse]), np.sin(start[worse]), fg[worse]
            better = np.flatnonzero(Fb[nb:] < Fb[amb])  # the second basin where it is better
            cb[amb[better]], sb[amb[better]] = cb[nb + better], sb[nb + better]
            cb, sb = cb[:nb], sb[:nb]
            fail = ~np.isfinite(cb + sb)  # degenerate data (certified segments are finite)
            cb[fail], sb[fail] = 1.0, 0.0
            c[bad], s[bad] = cb, sb
    return c, s, Sc * c + Ss * s


def hermite_rows(dp, d0, d1, a0, a2, r0, r1, angles=None, root_scale=None) -> np.ndarray:
    """batch_hermite on component rows: dp = p1 - p0, d0, d1 (3, N), a0, a2 = sqrt_rot(d0), sqrt_rot(d1)
    (4, N) and r0, r1 = |d0|, |d1|; returns A (N, 3, 4), multiplied by ``root_scale`` (N,) if given (the
    interpolant of data scaled by h is h times the curve, sqrt(h) times A, with the same free angles)."""
    n = dp.shape[1]
    e = d0 + d1
    base = 120.0 * dp - 15.0 * e  # Farouki: alpha = base + 5 (A0 i A2* + A2 i A0*)
    if angles is None:
        c, s, S = _cc_member(base, e, 3.0 * dp - e, a0, a2, r0, r1)  # S = i_product(a0, a2 e^{i delta})
        a2d = _times_e_i(a2, c, s)  # a2 e^{i delta}
    else:
        phi0 = np.broadcast_to(np.asarray(angles[0], dtype=float), (n,))
        delta = np.broadcast_to(np.asarray(angles[1], dtype=float), (n,)) - phi0
        a2d = _times_e_i(a2, np.cos(delta), np.sin(delta))
        S = _i_product(a0, a2d)
    Q = sqrt_rot(base + 10.0 * S)[0]  # Farouki: (3A0+4A1+3A2) i (..)* = alpha
    if angles is None:  # A0 + A2 = (a0 + a2d) e^{i phi0}; phi0 maximizes <(a0 + a2d) e^{i phi0}, Q>
        B = a0 + a2d
        x, y = _dot(B, Q), _dot(B[_IPERM], Q * _ISIGN)  # <B, Q>, <B i, Q>
        with np.errstate(divide="ignore", invalid="ignore"):
            ir = 1.0 / np.sqrt(x * x + y * y)
            c0, s0 = x * ir, y * ir
        bad = ~np.isfinite(ir)
        if bad.any():
            c0[bad], s0[bad] = 1.0, 0.0
    else:
        c0, s0 = np.cos(phi0), np.sin(phi0)
    A = np.empty((3, 4, n))
    _times_e_i(a0, c0, s0, A[0])  # A0 = a0 e^{i phi0}
    _times_e_i(a2d, c0, s0, A[2])  # A2 = a2 e^{i phi2}
    np.multiply(A[0] + A[2], -0.75, out=A[1])
    A[1] += 0.25 * Q  # Farouki's solution of the end-point condition
    if root_scale is not None:
        A *= root_scale
    return A.transpose(2, 0, 1).copy()


def batch_hermite(p0, p1, d0, d1, angles=None) -> np.ndarray:
    """Quaternion coefficients A (N, 3, 4) of PH quintics with r(0)=p0, r(1)=p1, r'(0)=d0, r'(1)=d1.

    Inputs have shape (N, 3). With ``angles`` = (phi0, phi2) (scalars or (N,) arrays) the member
    A0 = sqrt|d0| n(d0) e^{i phi0}, A2 = sqrt|d1| n(d1) e^{i phi2}, A1 = -(3/4)(A0 + A2) + Q/4 with
    Q i Q* = 120 (p1 - p0) - 15 (d0 + d1) + 5 (A0 i A2* + A2 i A0*) and Q's phase fixed to 0 (the common
    phase of A0, A1, A2 does not change the curve) is returned.

    With ``angles=None`` the member closest to a PH cubic is chosen: the angles minimizing the "CC" measure
    |A0 - 2 A1 + A2|^2 of Farouki, Giannelli, Manni, Sestini (2008), in closed form in phi0 and globally over
    delta = phi2 - phi0. The search starts at the global minimum of the "alpha criterion" |S(delta) - w|^2
    (S = i_product(a0, a2 e^{i delta}), w = 3 (p1 - p0) - (d0 + d1); a 2 x 2 trust-region problem, solved
    exactly where the measure's minimum is flat) and runs Newton on the measure from there. Per segment:

    - PH-cubic data (the ordinary cubic Hermite interpolant is PH): both criteria vanish at the same delta
      (S(delta) = w), and that cubic is reproduced (to 1e-8 of its size in the tests, round-off in practice).
    - Certified segments: a lower bound of the measure (|u - v|^2 = F (2 (|u| + |v|) - F) for the fibres
      over u = 25 X i X*, v = alpha, with u - v = 40 (S - w)), evaluated in floating point with round-off
      margins, proves that the global minimum over delta lies within 0.25 rad of the returned delta, where
      Newton has converged: F'' > 0 and a last step predicting a decrease below 1e-9 of the measure plus
      3e-13 of the data scale 25 (|d0| + |d1|) / 4 (what remains is at most about 8/27 of that). Not proved:
      that no second local minimum within those 0.25 rad is lower.
    - Every other segment (rough data, where the bound is too weak) gets a global search: a grid of 24 values
      of delta, Newton (steps of at most 0.2 rad) from the parabola vertex at the best grid point, or from
      the fast path's result where that is already lower, and from the best grid point of a second basin
      within 1.5 times of it; the lowest result, never above the best grid value.

    Against a dense brute-force search (tests/test_ph_quintic.py) the measure is within 1e-9 of the minimum
    plus 1e-13 of the data scale 25 (|d0| + |d1|) / 4 (the size of its terms), on random Hermite data and on
    spline tangents through smooth or noisy waypoints (observed: about 1e-14 of the scale). On smooth
    waypoint data every segment is certified.
    """
    p0, p1, d0, d1 = (np.asarray(x, dtype=float) for x in (p0, p1, d0, d1))
    n = p0.shape[0]
    rows = np.empty((3, 3, n))  # p1 - p0, d0, d1 on contiguous rows
    np.subtract(p1.T, p0.T, out=rows[0])
    rows[1], rows[2] = d0.T, d1.T
    a, r = sqrt_rot(rows[1:].transpose(1, 0, 2).reshape(3, 2 * n))
    return hermite_rows(rows[0], rows[1], rows[2], a[:, :n], a[:, n:], r[:n], r[n:], angles)


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
        member closest to a PH cubic, minimizing |A0 - 2 A1 + A2|^2 (Farouki, Giannelli, Manni, Sestini
        2008): it reproduces the ordinary cubic Hermite interpolant whenever that is itself a PH curve, and
        its measure is within 1e-9 of the global minimum plus 1e-13 of 25 (|d0| + |d1|) / 4 (tested against
        a dense brute-force search); the global minimum is proved to lie within 0.25 rad of the chosen
        phi2 - phi0, or found by a global grid search where that proof fails (see :func:`batch_hermite`).
        """
        p0 = check_vector(p0, "p0")
        p1 = check_vector(p1, "p1")
        d0 = check_vector(d0, "d0", nonzero=True)
        d1 = check_vector(d1, "d1", nonzero=True)
        if angles is not None:
            values = tuple(float(a) for a in angles)
            if len(values) != 2 or not np.isfinite(values).all():
                raise PlannerError(f"angles must be two finite numbers (phi0, phi2), got {values}")
            angles = (values[0], values[1])
        A = batch_hermite(p0[None], p1[None], d0[None], d1[None], angles)[0]
        return cls(A, p0)
