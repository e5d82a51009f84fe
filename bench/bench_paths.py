"""Benchmark: PH quintic spline fitting against scipy's CubicSpline plus numerical arc length.

Prints, for N = 10, 100, 1000, 10000 waypoints on a smooth 3D path, the fit times (PH C1, PH C2,
CubicSpline), the time to sample 10^5 points, and the relative arc-length error: the PH spline's exact
polynomial length against an independent Gauss-Legendre integration of |r'| (exact for a PH spline,
whose speed is a polynomial), and the baseline's usual approach (length of the polyline through 10^5
samples of the cubic spline) against a converged quadrature of the cubic spline's speed.

Targets (issue 2): C1 fit of 1000 waypoints < 20 ms and within 3x of CubicSpline; C2 fit of 1000
waypoints < 1 s; PH arc length relative error < 1e-12.

The C1 and CubicSpline fits are timed in alternation, best of ``--repeat`` rounds each, so that their
ratio compares like with like on a shared machine; the load average is printed with the table.

Issue 12's figure: the C1 fit with the member rule of issue 12 (least bending energy of four members)
against the same fit with the former rule (the global minimum of the CC measure, kept below as the
baseline ``fit_c1_cc``), timed in alternation with the other two: "C1 new/former" (target <= 1.10; the rule runs
compiled, planner/curves/_hermite_member.c, and "C1 numpy rule ms" is the same fit with its numpy implementation,
what an install without a C compiler runs); and the
default C2 fit against the same fit started from the former rule's C1 spline, timed in alternation: "C2
new/former".

A second table (issue 12): waypoints of a rough random walk in a randomly oriented plane (15 as in the
issue, and 1000), the largest distance of the C1 and C2 paths from that plane over the path's extent
(round-off, about 1e-16; with the former CC member selection 4 % and 8 % for 15 waypoints).

Run: python bench/bench_paths.py [--sizes 10,100,1000,10000] [--repeat 15]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import best_time, print_table  # noqa: E402

from planner.curves import ph_quintic, spline  # noqa: E402
from planner.curves.ph_quintic import (  # noqa: E402
    _IPERM,
    _ISIGN,
    _PRODUCTS,
    _dot,
    _times_e_i,
    hermite_rows,
    sqrt_rot,
)
from planner.curves.spline import PHSpline, fit_ph_spline  # noqa: E402

SAMPLES = 100_000


def waypoints(n: int) -> np.ndarray:
    """n points along a smooth space curve (a wavy helix, about 0.5 m across), slightly jittered."""
    s = np.linspace(0.0, 6 * np.pi, n)
    rng = np.random.default_rng(42)
    p = np.c_[0.25 * np.cos(s), 0.25 * np.sin(s) + 0.05 * np.sin(3 * s), 0.02 * s]
    return p + rng.normal(scale=1e-6, size=p.shape)  # CAD export precision, 1 micron


def best_times(fns: dict[str, Callable[[], object]], repeat: int, min_round: float = 0.02) -> dict[str, float]:
    """Best wall time of one call (s) of each function, timed in alternation over ``repeat`` rounds."""
    number = {}
    for k, fn in fns.items():
        t0 = time.perf_counter()
        fn()
        number[k] = max(1, int(min_round / max(time.perf_counter() - t0, 1e-9)))
    best = dict.fromkeys(fns, float("inf"))
    for _ in range(repeat):
        for k, fn in fns.items():
            t0 = time.perf_counter()
            for _ in range(number[k]):
                fn()
            best[k] = min(best[k], (time.perf_counter() - t0) / number[k])
    return best


def gauss_length(deriv, knots: np.ndarray, nodes: int) -> float:
    """Integral of |deriv(u)| over the knot spans with a Gauss-Legendre rule per span."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    a, b = knots[:-1, None], knots[1:, None]
    u = (0.5 * (b - a) * x + 0.5 * (a + b)).ravel()
    speed = np.linalg.norm(deriv(u), axis=1).reshape(a.shape[0], nodes)
    return float((speed * w).sum(axis=1) @ (0.5 * (b - a)[:, 0]))


# ---------------------------------------------------------------------------------------------
# The former member rule (before issue 12), kept here only as the baseline of the fit-time figure:
# the global minimum of the CC measure |A0 - 2 A1 + A2|^2 over the two free angles (FGMS 2008), as
# planner/curves/ph_quintic.py had it at 76d902d^ (certified Newton from the alpha criterion, grid
# search where the certificate fails). Not part of the planner.
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



def _cc_hermite_rows(dp, d0, d1, a0, a2, r0, r1, angles=None, root_scale=None) -> np.ndarray:
    """The former ph_quintic.hermite_rows with the default member (``angles`` must be None)."""
    assert angles is None
    n = dp.shape[1]
    e = d0 + d1
    base = 120.0 * dp - 15.0 * e
    c, s, S = _cc_member(base, e, 3.0 * dp - e, a0, a2, r0, r1)
    a2d = _times_e_i(a2, c, s)
    Q = sqrt_rot(base + 10.0 * S)[0]
    B = a0 + a2d
    x, y = _dot(B, Q), _dot(B[_IPERM], Q * _ISIGN)
    with np.errstate(divide="ignore", invalid="ignore"):
        ir = 1.0 / np.sqrt(x * x + y * y)
        c0, s0 = x * ir, y * ir
    bad = ~np.isfinite(ir)
    if bad.any():
        c0[bad], s0[bad] = 1.0, 0.0
    A = np.empty((3, 4, n))
    _times_e_i(a0, c0, s0, A[0])
    _times_e_i(a2d, c0, s0, A[2])
    np.multiply(A[0] + A[2], -0.75, out=A[1])
    A[1] += 0.25 * Q
    if root_scale is not None:
        A *= root_scale
    return A.transpose(2, 0, 1).copy()


def fit_c1_cc(points: np.ndarray, continuity: str = "C1") -> PHSpline:
    """fit_ph_spline(points, continuity=...) with the former CC member rule: the same fit with its Hermite
    stage (spline.hermite_rows) swapped for the former one for the duration of the call (for C2: the C1 spline
    the Newton solve starts from)."""
    spline.hermite_rows = _cc_hermite_rows
    try:
        return fit_ph_spline(points, continuity=continuity)  # type: ignore[arg-type]
    finally:
        spline.hermite_rows = hermite_rows


def fit_c1_numpy(points: np.ndarray) -> PHSpline:
    """fit_ph_spline(points, continuity="C1") with the numpy implementation of the member rule (what an install
    without a C compiler runs) instead of the compiled one."""
    compiled, ph_quintic._hermite_member = ph_quintic._hermite_member, None
    try:
        return fit_ph_spline(points, continuity="C1")
    finally:
        ph_quintic._hermite_member = compiled


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="10,100,1000,10000")
    ap.add_argument("--repeat", type=int, default=15, help="rounds of the alternating C1 / CubicSpline timing")
    args = ap.parse_args()
    sizes = [int(v) for v in args.sizes.split(",")]
    rows = []
    load = os.getloadavg()
    for n in sizes:
        p = waypoints(n)
        u = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))))
        fits = {
            "c1": lambda p=p: fit_ph_spline(p, continuity="C1"),
            "cc": lambda p=p: fit_c1_cc(p),
            "np": lambda p=p: fit_c1_numpy(p),
            "cs": lambda p=p, u=u: CubicSpline(u, p),
        }
        t = best_times(fits, args.repeat)
        t_c1, t_cc, t_cs, t_np = t["c1"], t["cc"], t["cs"], t["np"]
        t2 = best_times({"c2": lambda p=p: fit_ph_spline(p, continuity="C2"),
                         "cc2": lambda p=p: fit_c1_cc(p, "C2")}, 2 if n >= 10000 else 4)
        t_c2, t_cc2 = t2["c2"], t2["cc2"]
        ph = fit_ph_spline(p, continuity="C1")
        ph2 = fit_ph_spline(p, continuity="C2")
        cs = CubicSpline(u, p)
        us = np.linspace(0.0, u[-1], SAMPLES)
        t_ph_s = best_time(lambda ph=ph, us=us: ph.points(us))
        t_cs_s = best_time(lambda cs=cs, us=us: cs(us))
        # PH: exact polynomial length vs Gauss-Legendre of |r'| from the control points (exact for PH)
        ph_err = max(
            abs(s.length - gauss_length(s.derivative, s.knots, 8)) / s.length for s in (ph, ph2)
        )
        # baseline: polyline through 1e5 samples vs converged quadrature of |c'|
        cs_ref = gauss_length(lambda x, cs=cs: cs(x, 1), u, 40)
        poly = float(np.linalg.norm(np.diff(cs(us), axis=0), axis=1).sum())
        cs_err = abs(poly - cs_ref) / cs_ref
        rows.append(
            [
                n,
                f"{t_c1 * 1e3:.3f}",
                f"{t_cc * 1e3:.3f}",
                f"{t_c1 / t_cc:.2f}",
                f"{t_np * 1e3:.3f}",
                f"{t_c2 * 1e3:.1f}",
                f"{t_c2 / t_cc2:.2f}",
                f"{t_cs * 1e3:.3f}",
                f"{t_c1 / t_cs:.2f}x",
                f"{ph2.iterations}",
                f"{t_ph_s * 1e3:.1f}",
                f"{t_cs_s * 1e3:.1f}",
                f"{ph_err:.1e}",
                f"{cs_err:.1e}",
                f"{ph.curvature_jumps().max(initial=0):.1e}",
                f"{ph2.curvature_jumps().max(initial=0):.1e}",
            ]
        )
    print(f"load average before / after: {load[0]:.2f} / {os.getloadavg()[0]:.2f} ({os.cpu_count()} cpus)")
    built = ph_quintic._hermite_member is not None
    print("member rule: " + ("compiled (planner/curves/_hermite_member.c)" if built else
                             "numpy (the compiled module is not built: no C compiler at install)"))
    print_table(
        [
            "N",
            "PH C1 fit ms",
            "C1 former rule ms",
            "C1 new/former",
            "C1 numpy rule ms",
            "PH C2 fit ms",
            "C2 new/former",
            "CubicSpline fit ms",
            "C1/CS",
            "C2 Newton its",
            "PH sample 1e5 ms",
            "CS sample 1e5 ms",
            "PH length rel err",
            "CS polyline length rel err",
            "C1 max curv jump 1/m",
            "C2 max curv jump 1/m",
        ],
        rows,
    )
    print()
    print_table(["planar walk waypoints", "C1 off-plane / extent", "C2 off-plane / extent"], planar_rows())


def planar_rows() -> list[list[object]]:
    """Off-plane figures of C1 and C2 fits of planar random walks in a random plane."""
    rows: list[list[object]] = []
    rng = np.random.default_rng(12)
    for n in (15, 1000):
        walk = np.cumsum(rng.normal(size=(n, 2)), axis=0)
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        o = rng.normal(size=3)
        p = walk @ q[:, :2].T + o
        row: list[object] = [n]
        for c in ("C1", "C2"):
            s = fit_ph_spline(p, continuity=c)
            pts = s.points(np.linspace(0.0, s.knots[-1], 20 * n))
            row.append(f"{np.abs((pts - o) @ q[:, 2]).max() / np.ptp(walk, axis=0).max():.1e}")
        rows.append(row)
    return rows


if __name__ == "__main__":
    main()
