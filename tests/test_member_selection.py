"""The default PH quintic member (issue 12) picked by the fast selection is the rule as first written, or better.

``reference_member`` below is the selection as it landed with issue 12 (planner/curves/ph_quintic.py at
commit 0ffa5ec: the four members with A0 i A2* a pure vector, a 2 x 4-node Gauss screen, the 8 x 8-node
rule where the screen is not clear by a factor 10), frozen here verbatim as the oracle;
``ph_quintic._least_energy_member`` is the faster implementation of the same rule, with one change where the
reference rested on round-off: the energy's integrand 4 (W_j^2 + W_k^2) / |A|^6 (W = A* A') has no
cancellation (the reference's |A|^2 |A'|^2 - <A, A'>^2 - <A i, A'>^2 gave straight members energies of round-off
size, about the size of its tie term, so near-straight segments were decided by noise); ties of the energy
(straight members) go to the most even parametric speed (1e-24 of int dt / sigma), not to the least CC measure
(1e-9 of it), which chose members that stop on the way; and one change of 1e-10 rad at most: the fallback axis of antiparallel end
tangents fades out of the blend beyond 143 degrees between them (there the reference blends it in with a weight of
1e-12). On random Hermite data
of every kind (rough spatial and planar, smooth spline segments, near-straight, hairpins, exact degenerate
cases) both must return the same member (A equal to round-off), or, where they differ, the fast one's bending
energy (free of cancellation, on a finer rule) must not exceed the reference's by more than 1e-12 (of the larger
or of the scale 1 / |p1 - p0| of a bend's energy: a tie); on exactly collinear data any straight member will do.
The default suite checks a few thousand segments of each kind; ``-m slow`` (or running this file as a
script: ``python -m tests.test_member_selection [segments per kind]``) checks 1e5 and more.

The compiled rule (planner/curves/_hermite_member.c, what the fits use where a C compiler built it) is checked
against ``_least_energy_member`` the same way: the same member to round-off, or one of the same energy.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest

from planner.curves import ph_quintic
from planner.curves.ph_quintic import (
    _AXIS_FALLBACK,
    _IPERM,
    _ISIGN,
    _PRODUCTS,
    _dot,
    _least_energy_compiled,
    _least_energy_member,
    _member,
    _times_e_i,
    sqrt_rot,
)


def _energy_matrices(nodes: int, pieces: int = 1) -> tuple[np.ndarray, ...]:
    """Weights (K,) of the composite Gauss-Legendre rule on [0, 1] (``pieces`` equal pieces, ``nodes`` each) and
    the matrices that map the inner products of A0, A1, A2 to sigma = |A|^2, |A'|^2 and sigma' / 2 = <A, A'>
    (stacked: 3K, 6 products g00 g01 g02 g11 g12 g22), and to <A i, A'> (K, 3 products h01 h02 h12,
    h_jk = <A_j i, A_k> = -h_kj) at the K nodes."""
    x, wx = np.polynomial.legendre.leggauss(nodes)
    t = ((0.5 * (x + 1.0))[None] + np.arange(pieces)[:, None]).ravel() / pieces
    w = np.tile(wx, pieces) / (2.0 * pieces)
    nodes = t.size
    b = np.stack(((1 - t) ** 2, 2 * t * (1 - t), t * t), axis=1)  # A(t) = sum b_j A_j
    db = np.stack((-2 * (1 - t), 2 - 4 * t, 2 * t), axis=1)  # A'(t) = sum db_j A_j
    pairs = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
    Ms, Md, Mx = (np.zeros((nodes, 6)) for _ in range(3))
    for q, (j, k) in enumerate(pairs):
        f = 1.0 if j == k else 2.0  # g_jk appears as jk and kj
        Ms[:, q] = f * b[:, j] * b[:, k]
        Md[:, q] = f * db[:, j] * db[:, k]
        Mx[:, q] = b[:, j] * db[:, k] + (b[:, k] * db[:, j] if j != k else 0.0)
    Mh = np.zeros((nodes, 3))
    for q, (j, k) in enumerate(((0, 1), (0, 2), (1, 2))):  # <A i, A'> = sum b_j db_k h_jk, h_kj = -h_jk
        Mh[:, q] = b[:, j] * db[:, k] - b[:, k] * db[:, j]
    return w, np.vstack((Ms, Md, Mx)), Mh  # one product for s, d, x: one temporary, not three (page faults)


_SCREEN_RULE = _energy_matrices(4, 2)
_FULL_RULE = _energy_matrices(8, 8)
_SCREEN = 10.0
_TIE = 1e-9


def _reference_axis(Sc, Ss, sc, ss, lam, dp):
    """(cos, sin) (N,) of the delta = phi2 - phi0 (defined up to pi) at which A0 i A2* is a pure vector.

    The quaternion a0 i (a2 e^{i delta})* = (sc cos + ss sin) + S(delta) has the scalar part sigma.z with
    sigma = (sc, ss), z = (cos delta, sin delta): it vanishes on the axis z = +-sigma_perp. Where the end
    tangents are antiparallel sigma = 0 and every delta qualifies; there the axis maximizing |<S(delta), dp>|
    (b = (<Sc, dp>, <Ss, dp>)) decides. Both axes are blended sign-free, on doubled angles (an axis z ~ -z
    is the point (x^2 - y^2, 2 x y)), the second with the weight _AXIS_FALLBACK, so that the result is a
    continuous function of the data wherever the blend is nonzero. Both axes are carried onto themselves by
    every isometry of the data (rotations; the reflections that fix planar data or map mirror-symmetric data
    onto their reversal), so their blend is too. lam = |a0|^2 |a2|^2, dp = p1 - p0 (3, N).
    """
    bc, bs = _dot(Sc, dp), _dot(Ss, dp)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = _AXIS_FALLBACK / (lam * _dot(dp, dp))
        w = np.where(np.isfinite(w), w, 0.0)
        il = np.where(lam > 0, 1.0 / lam, 0.0)
    Dx = (ss * ss - sc * sc) * il + (bc * bc - bs * bs) * w  # doubled angle of sigma_perp = (-ss, sc) ...
    Dy = (-2.0 * il) * ss * sc + (2.0 * w) * bc * bs  # ... and of b
    r = np.hypot(Dx, Dy)
    # half angle: (r + Dx, Dy) ~ z for Dx >= 0 and (Dy, r - Dx) ~ z otherwise (no cancellation either way)
    pos = Dx >= 0
    x, y = np.where(pos, r + Dx, Dy), np.where(pos, Dy, r - Dx)
    n = np.hypot(x, y)
    ok = n > 0  # no axis at all: d1 antiparallel to d0 and p1 - p0 along them (a straight hairpin)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(ok, x / n, 1.0), np.where(ok, y / n, 0.0)


def _reference_energies(g, h, rule) -> np.ndarray:
    """4 int kappa^2 sigma dt (M,) by a Gauss ``rule`` of :func:`_energy_matrices` from the inner products
    g (6, M) and h (3, M) of A0, A1, A2 (see :func:`bending_energies`)."""
    w, Msdx, Mh = rule
    k = w.size
    sdx = Msdx @ g
    s, d, x = sdx[:k], sdx[k:2 * k], sdx[2 * k:]
    y = Mh @ h
    d *= s
    x *= x
    d -= x
    y *= y
    d -= y
    num = np.maximum(d, 0.0, out=d)  # |A|^2 |A'_perp|^2 >= 0 but for round-off
    x[...] = s
    x *= s
    x *= s  # sigma^3
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        f = np.divide(num, x, out=y)
    f[~(x > 0)] = np.inf
    return 4.0 * (w @ f)


def reference_member(dp, base, a0, a2, r0, r1) -> np.ndarray:
    """A (3, 4, N) of the default member (see :func:`batch_hermite`): of the four members with A0 i A2* a pure
    vector, the one of least bending energy.

    The candidates are delta in {delta0, delta0 + pi} (``_pure_vector_axis``) and, for each, phi0 at the maximum
    of <A0 + A2, Q> and phi0 + pi. Their energies E = 4 int Lambda / sigma^3 dt (see :func:`bending_energies`)
    follow from nine inner products of A0, A1, A2, themselves from a few inner products of a0, a2, Q
    (A1 = -(3/4)(A0 + A2) + Q/4, <A0, A0> = |d0|, ...). A coarse Gauss rule screens them: where one candidate's
    estimate is below 1 / _SCREEN of the other three's (smooth data: the others have cusps or loops) it is
    taken; elsewhere the composite rule of :func:`bending_energies` decides among the candidates within
    _SCREEN of the best estimate.
    """
    n = dp.shape[1]
    R = _PRODUCTS @ np.multiply(a0[:, None], a2[None]).reshape(16, n)  # a0 i a2* and a0 a2*, (vec, scalar)
    Sc, Ss = R[:3], R[4:7]
    c, s = _reference_axis(Sc, Ss, R[3], R[7], r0 * r1, dp)
    c02, e02 = R[7] * c - R[3] * s, R[3] * c + R[7] * s  # <a0, a2 e^{i delta}>, <a0 i, a2 e^{i delta}>
    # per delta (rows 0: delta0, 1: delta0 + pi): a2 e^{i delta}, Q, phi0 and the inner products at phi0
    a2d = np.stack((_times_e_i(a2, c, s), _times_e_i(a2, -c, -s)))  # (2, 4, N)
    S = Sc * c + Ss * s
    Q, qq = sqrt_rot(np.stack((base + 10.0 * S, base - 10.0 * S), axis=1).reshape(3, 2 * n))
    Q = Q.reshape(4, 2, n).transpose(1, 0, 2)
    qq = qq.reshape(2, n)  # |Q|^2 = |alpha|
    u0, v0 = (a0 * Q).sum(axis=1), (a0[_IPERM] * _ISIGN * Q).sum(axis=1)  # <a0, Q>, <a0 i, Q>  (2, N)
    u2, v2 = (a2d * Q).sum(axis=1), (a2d[:, _IPERM] * _ISIGN * Q).sum(axis=1)
    x, y = u0 + u2, v0 + v2  # <(a0 + a2d) e^{i phi0}, Q> = x cos + y sin: the maximum at phi0 = atan2(y, x)
    h = np.hypot(x, y)
    ok = h > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        c0, s0 = np.where(ok, x / h, 1.0), np.where(ok, y / h, 0.0)
    P0, P2 = c0 * u0 + s0 * v0, c0 * u2 + s0 * v2  # <A0, Q>, <A2, Q>
    V0, V2 = c0 * v0 - s0 * u0, c0 * v2 - s0 * u2  # <A0 i, Q>, <A2 i, Q>
    # candidates k = 2 * (delta index) + (phi0 + pi): the flip negates A0, A2 and so P, V
    f = np.array([1.0, -1.0])[:, None]
    sg = np.array([1.0, -1.0])[:, None]
    g02 = np.repeat(sg * c02, 2, axis=0)  # (4, N)
    e = np.repeat(sg * e02, 2, axis=0)
    P0, P2, V0, V2 = ((f[:, None] * z[None]).transpose(1, 0, 2).reshape(4, n) for z in (P0, P2, V0, V2))
    qq4 = np.repeat(qq, 2, axis=0)
    g00, g22 = np.broadcast_to(r0, (4, n)), np.broadcast_to(r1, (4, n))
    g01 = -0.75 * (r0 + g02) + 0.25 * P0
    g12 = -0.75 * (g02 + r1) + 0.25 * P2
    g11 = 0.5625 * (r0 + r1 + 2.0 * g02) - 0.375 * (P0 + P2) + 0.0625 * qq4
    g = np.stack((g00, g01, g02, g11, g12, g22)).reshape(6, 4 * n)
    hh = np.stack((-0.75 * e + 0.25 * V0, e, -0.75 * e - 0.25 * V2)).reshape(3, 4 * n)
    # screening: the energies by the 2 x 4-node rule from the inner products; a candidate below 1 / _SCREEN of
    # the other three is taken, elsewhere the full rule decides
    est = _reference_energies(g, hh, _SCREEN_RULE).reshape(4, n)
    # ties (a straight segment and the same line with stops, both of zero energy) go to the least CC measure
    # |A0 - 2 A1 + A2|^2 (FGMS 2008): _TIE of it, made dimensionless by (|d0| + |d1|)^2, joins the energy
    cc = (g[0] + 4.0 * g[3] + g[5] - 4.0 * g[1] + 2.0 * g[2] - 4.0 * g[4]).reshape(4, n)
    tie = _TIE / (r0 + r1) ** 2
    est = est + tie * cc
    best = np.argmin(est, axis=0)
    cols = np.arange(n)
    others = est.copy()
    others[best, cols] = np.inf
    bad = np.flatnonzero(~(others.min(axis=0) > _SCREEN * est[best, cols]))
    if bad.size:  # the candidates within _SCREEN of the best estimate, by the full rule
        k, col = np.nonzero(est[:, bad] < _SCREEN * est[best[bad], bad])
        seg = bad[col]
        kc = k * n + seg  # the candidates' columns of g, hh
        E = np.full((4, bad.size), np.inf)
        E[k, col] = _reference_energies(g[:, kc], hh[:, kc], _FULL_RULE) \
            + tie[seg] * cc.reshape(-1)[kc]
        best[bad] = np.argmin(E, axis=0)
    j, fl = best // 2, best % 2
    sign = 1.0 - 2.0 * fl
    return _member(a0, a2d[j, :, cols].T, Q[j, :, cols].T, sign * c0[j, cols], sign * s0[j, cols])


# ---------------------------------------------------------------------------------------------
# Random Hermite data (dp = p1 - p0, d0, d1 as component rows (3, N)) of every kind
# ---------------------------------------------------------------------------------------------


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=0)


def _rotate(v: np.ndarray, axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rows v (3, N) rotated about unit rows ``axis`` by ``angle`` (N,) (Rodrigues)."""
    c, s = np.cos(angle), np.sin(angle)
    return v * c + np.cross(axis, v, axis=0) * s + axis * _dot(axis, v) * (1 - c)


def _in_random_planes(rng, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Planar rows x e1 + y e2 (3, N) in a random plane per segment (x, y (N,) or (k, N))."""
    e1 = _unit(rng.normal(size=(3,) + x.shape[-1:]))
    e2 = _unit(np.cross(e1, rng.normal(size=e1.shape), axis=0))
    return e1[:, None] * x + e2[:, None] * y


def hermite_data(kind: str, n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(dp, d0, d1) of n random segments of one ``kind``."""
    rng = np.random.default_rng(seed)
    if kind == "rough spatial":
        dp, d0, d1 = rng.normal(size=(3, 3, n))
        d0 *= np.exp(rng.normal(scale=0.7, size=n))
        d1 *= np.exp(rng.normal(scale=0.7, size=n))
    elif kind == "rough planar":
        dp, d0, d1 = _in_random_planes(rng, *rng.normal(size=(2, 3, n))).transpose(1, 0, 2)
        d0 *= np.exp(rng.normal(scale=0.7, size=n))
        d1 *= np.exp(rng.normal(scale=0.7, size=n))
    elif kind == "smooth":  # spline segments: unit tangents turning by up to 0.5 rad, chord about 1
        d0 = _unit(rng.normal(size=(3, n)))
        turn = rng.uniform(0.0, 0.5, size=n) * rng.uniform(0.0, 1.0, size=n)
        d1 = _rotate(d0, _unit(np.cross(d0, rng.normal(size=(3, n)), axis=0)), turn)
        twist = 10.0 ** rng.uniform(-6, -1, size=n) * rng.normal(size=(3, n))
        dp = _unit(d0 + d1 + twist)
    elif kind == "near straight":
        d0 = _unit(rng.normal(size=(3, n)))
        eps = 10.0 ** rng.uniform(-10, -2, size=(3, n))
        dp = d0 * np.exp(rng.normal(scale=0.3, size=n)) + eps[0] * rng.normal(size=(3, n))
        d1 = d0 * np.exp(rng.normal(scale=0.3, size=n)) + eps[1] * rng.normal(size=(3, n))
        d0 = d0 + eps[2] * rng.normal(size=(3, n))
    elif kind == "hairpin":
        d0 = _unit(rng.normal(size=(3, n)))
        d1 = -d0 * np.exp(rng.normal(scale=0.3, size=n)) + 10.0 ** rng.uniform(-9, -1, size=n) * rng.normal(size=(3, n))
        along = rng.uniform(-1.0, 1.0, size=n) * (rng.uniform(size=n) < 0.3)
        dp = d0 * along + _unit(np.cross(d0, rng.normal(size=(3, n)), axis=0)) * rng.uniform(0.0, 2.0, size=n)
    elif kind == "exact degenerate":  # exactly collinear, antiparallel, planar in z = 0, or repeated
        m = n // 4
        u = _unit(rng.normal(size=(3, m)))
        k = np.exp(rng.normal(size=(3, m)))
        straight = (u * k[0], u * k[1], u * k[2])
        v = _unit(np.cross(u, rng.normal(size=(3, m)), axis=0))
        pin = (v * k[0] * (rng.uniform(size=m) < 0.5), u * k[1], -u * k[2])
        flat = rng.normal(size=(3, 3, m))
        flat[:, 2] = 0.0
        same = rng.normal(size=(3, n - 3 * m))
        parts = (straight, pin, tuple(flat), (same, same, same))
        dp, d0, d1 = (np.hstack([p[i] for p in parts]) for i in range(3))
    else:
        raise ValueError(kind)
    return dp, d0, d1


def spline_data(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Segments as the C1 spline builds them (dp / h, unit tangents) from random walks, rough to smooth."""
    from planner.curves.tangents import slopes_rows

    rng = np.random.default_rng(seed)
    out = []
    while sum(o[0].shape[1] for o in out) < n:
        m = int(rng.integers(4, 400))
        steps = rng.normal(size=(m, 3)) * np.exp(rng.normal(size=(m, 1)))
        steps[:, 2] *= rng.choice([0.0, 0.1, 1.0])  # planar, flat or spatial
        steps = np.cumsum(steps, axis=0) * rng.uniform(0.0, 0.95) + steps  # smoother for larger factors
        p = np.cumsum(steps, axis=0)
        dp = np.diff(p, axis=0).T
        h = np.linalg.norm(dp, axis=0)
        keep = h > 0
        dp, h = dp[:, keep], h[keep]
        m_ = slopes_rows(np.concatenate(([0.0], np.cumsum(h))), dp)
        m_ = m_ / np.linalg.norm(m_, axis=0)
        out.append((dp / h, m_[:, :-1], m_[:, 1:]))
    return tuple(np.hstack([o[i] for o in out])[:, :n] for i in range(3))


def accurate_energies(A: np.ndarray, pieces: int = 16, nodes: int = 8) -> np.ndarray:
    """Bending energies (M,) of PH quintics A (3, 4, M) free of cancellation, the arbiter of ties: kappa^2 sigma =
    4 (W_j^2 + W_k^2) / |A|^6 with W = A* A' (its j, k parts are r'' across the tangent in the frame of A), each a
    product of values at the nodes of a composite Gauss rule; a straight member gets 0 to round-off squared."""
    x, wx = np.polynomial.legendre.leggauss(nodes)
    t = ((0.5 * (x + 1.0))[None] + np.arange(pieces)[:, None]).ravel() / pieces
    w = np.tile(wx, pieces) / (2.0 * pieces)
    b = np.stack(((1 - t) ** 2, 2 * t * (1 - t), t * t))  # (3, K)
    db = np.stack((-2 * (1 - t), 2 - 4 * t, 2 * t))
    At = np.einsum("jk,jcm->ckm", b, A)  # (4, K, M)
    Dt = np.einsum("jk,jcm->ckm", db, A)
    a0, a1, a2, a3 = At
    b0, b1, b2, b3 = Dt
    wj = a0 * b2 - a2 * b0 + a1 * b3 - a3 * b1  # j and k parts of conj(A) A'
    wk = a0 * b3 - a3 * b0 + a2 * b1 - a1 * b2
    s = (At * At).sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        f = 4.0 * (wj * wj + wk * wk) / (s * s * s)
    f[~(s > 0)] = np.inf
    return w @ f


KINDS = ("rough spatial", "rough planar", "smooth", "near straight", "hairpin", "exact degenerate")


def _off_line(A: np.ndarray, dp: np.ndarray, d0: np.ndarray, d1: np.ndarray) -> float:
    """Largest distance (relative to |dp|) of the PH quintic A (3, 4) from the line along dp through its start, if
    the Hermite data are collinear to round-off (then every straight member has zero bending energy, and one with
    a momentary stop has a round-off energy peak that no rule of a few nodes sees); inf otherwise."""
    from planner.curves.ph_quintic import PHQuintic

    L = np.linalg.norm(dp)
    u = dp / L
    if max(np.linalg.norm(np.cross(u, d0)) / np.linalg.norm(d0), np.linalg.norm(np.cross(u, d1)) / np.linalg.norm(d1)) > 1e-14:
        return np.inf
    pts = PHQuintic.from_quaternions(*A).points(np.linspace(0.0, 1.0, 201))
    return float(np.linalg.norm(np.cross(pts, u), axis=1).max() / L)


def compiled_member(dp, base, a0, a2, r0, r1) -> np.ndarray:
    """A (3, 4, N) of the compiled rule (planner/curves/_hermite_member.c), as the numpy rule returns it."""
    assert ph_quintic._hermite_member is not None, COMPILED_MISSING
    return _least_energy_compiled(dp, base, a0, a2, r0, r1).transpose(1, 2, 0)


def compare(dp: np.ndarray, d0: np.ndarray, d1: np.ndarray, fast=_least_energy_member,
            reference=reference_member) -> tuple[int, int, float]:
    """(segments, segments where the members differ, largest relative energy excess of the ``fast`` selection's
    member over the ``reference``'s among those) on Hermite data rows; asserts the result is finite."""
    n = dp.shape[1]
    a, r = sqrt_rot(np.hstack((d0, d1)))
    args = (dp, 120.0 * dp - 15.0 * (d0 + d1), a[:, :n], a[:, n:], r[:n], r[n:])
    with np.errstate(all="ignore"):
        ref = reference(*args)
    new = fast(*args)
    assert np.isfinite(new).all()
    scale = np.abs(ref).max(axis=(0, 1))
    differ = np.flatnonzero(np.abs(new - ref).max(axis=(0, 1)) > 1e-9 * scale)
    worst = 0.0
    if differ.size:  # ties: equal energies to 1e-12 of the larger or of the scale 1 / |p1 - p0| of a bend's energy
        e_ref, e_new = accurate_energies(ref[..., differ]), accurate_energies(new[..., differ])
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.maximum(np.maximum(e_ref, e_new), 1.0 / np.linalg.norm(dp[:, differ], axis=0))
            rel = np.where(e_new <= e_ref, 0.0, (e_new - e_ref) / scale)
        for q in np.flatnonzero(rel > 1e-12):  # exactly collinear data: any straight member is as good
            rel[q] = min(rel[q], _off_line(new[..., differ[q]], dp[:, differ[q]], d0[:, differ[q]], d1[:, differ[q]]))
        worst = float(rel.max())
    return n, differ.size, worst


def test_the_arbiter_is_the_curves_bending_energy():
    """accurate_energies (which decides ties above) equals int |r' x r''|^2 / |r'|^5 dt of the curve itself, from
    PHQuintic's derivatives, on random spatial quintics (it once took the j, k parts of A' A*, not of A* A')."""
    from planner.curves.ph_quintic import PHQuintic

    rng = np.random.default_rng(5)
    A = rng.normal(size=(3, 4, 20))
    x, wx = np.polynomial.legendre.leggauss(8)
    t = ((0.5 * (x + 1.0))[None] + np.arange(16)[:, None]).ravel() / 16
    w = np.tile(wx, 16) / 32.0
    direct = []
    for k in range(A.shape[2]):
        c = PHQuintic.from_quaternions(*A[..., k])
        d1, d2 = c.derivative(t), c.derivative(t, 2)
        direct.append(w @ (np.linalg.norm(np.cross(d1, d2), axis=1) ** 2 / np.linalg.norm(d1, axis=1) ** 5))
    assert np.allclose(accurate_energies(A), direct, rtol=1e-12, atol=0.0)


def all_members(dp, base, a0, a2, r0, r1) -> list[np.ndarray]:
    """The four candidate members A (3, 4, N) of the rule (built as ``reference_member`` builds them)."""
    n = dp.shape[1]
    R = _PRODUCTS @ np.multiply(a0[:, None], a2[None]).reshape(16, n)
    c, s = _reference_axis(R[:3], R[4:7], R[3], R[7], r0 * r1, dp)
    a2d = np.stack((_times_e_i(a2, c, s), _times_e_i(a2, -c, -s)))
    S = R[:3] * c + R[4:7] * s
    Q = sqrt_rot(np.stack((base + 10.0 * S, base - 10.0 * S), axis=1).reshape(3, 2 * n))[0]
    Q = Q.reshape(4, 2, n).transpose(1, 0, 2)
    x = (a0 * Q).sum(axis=1) + (a2d * Q).sum(axis=1)
    y = (a0[_IPERM] * _ISIGN * Q).sum(axis=1) + (a2d[:, _IPERM] * _ISIGN * Q).sum(axis=1)
    h = np.hypot(x, y)
    with np.errstate(divide="ignore", invalid="ignore"):
        c0, s0 = np.where(h > 0, x / h, 1.0), np.where(h > 0, y / h, 0.0)
    return [_member(a0, a2d[k // 2], Q[k // 2], (1 - 2 * (k % 2)) * c0[k // 2], (1 - 2 * (k % 2)) * s0[k // 2])
            for k in range(4)]


RULES = {"numpy": _least_energy_member, "compiled": compiled_member}


@pytest.mark.parametrize("rule", RULES)
@pytest.mark.parametrize("kind, seed", [("near straight", 501), ("near straight", 503), ("smooth", 0)])
def test_the_selection_is_the_least_energy_member(kind, seed, rule):
    """Against the accurate energies of the four candidates, the selected member is the least (to 1e-9 of the
    larger of that energy and the scale 1 / |p1 - p0|). On these near-straight seeds the rule as first written
    (the oracle above, whose integrand cancels) picks a member of far larger energy on 3 and 2 of 20,000 segments
    (up to 4.5e3 times the scale: a loop where the data are nearly straight)."""
    dp, d0, d1 = hermite_data(kind, 20_000, seed)
    n = dp.shape[1]
    a, r = sqrt_rot(np.hstack((d0, d1)))
    args = (dp, 120.0 * dp - 15.0 * (d0 + d1), a[:, :n], a[:, n:], r[:n], r[n:])
    with np.errstate(divide="ignore", invalid="ignore"):
        least = np.min([accurate_energies(m) for m in all_members(*args)], axis=0)
        chosen = accurate_energies(RULES[rule](*args))
        excess = (chosen - least) / np.maximum(least, 1.0 / np.linalg.norm(dp, axis=0))
    assert excess.max() <= 1e-9, f"{kind}: {(excess > 1e-9).sum()} of {n} members exceed the least energy, worst {excess.max():.2g}"


@pytest.mark.parametrize("kind", KINDS)
def test_fast_selection_picks_the_reference_member(kind):
    n, differ, worst = compare(*hermite_data(kind, 3000, seed=KINDS.index(kind)))
    assert worst <= 1e-12, f"{kind}: {differ} of {n} members differ, energies by {worst:.1e}"


def test_fast_selection_on_spline_segments():
    n, differ, worst = compare(*spline_data(3000, seed=7))
    assert worst <= 1e-12, f"{differ} of {n} members differ, energies by {worst:.1e}"


@pytest.mark.slow
@pytest.mark.parametrize("kind", KINDS + ("spline",))
def test_fast_selection_on_many_segments(kind):
    """1e5 segments of each kind (0.3-2 s each)."""
    for seed in range(5):
        data = spline_data(20_000, seed=100 + seed) if kind == "spline" else hermite_data(kind, 20_000, 100 + seed)
        n, differ, worst = compare(*data)
        assert worst <= 1e-12, f"{kind}: {differ} of {n} members differ, energies by {worst:.1e}"


COMPILED_MISSING = (
    "planner/curves/_hermite_member.c is not built: the install found no C compiler (or Python's headers); "
    "install gcc (Debian: apt-get install gcc python3-dev) and run `pip install -e .` again"
)


def test_the_compiled_rule_is_built():
    """The install built the compiled rule (pyproject.toml makes it optional for users; the test command's machine has a
    C compiler, and without the module every fit would silently take the numpy rule, 1.8 times slower)."""
    assert ph_quintic._hermite_member is not None, COMPILED_MISSING


def test_the_compiled_kernel_refuses_what_it_cannot_read():
    """The kernel is private (ph_quintic builds its arrays), but a wrong array is an exception naming it, never a
    read past an array's end: rows and scales of different N, another dtype, a strided array, a short rule."""
    assert ph_quintic._hermite_member is not None, COMPILED_MISSING
    kernel = ph_quintic._hermite_member.least_energy_members
    rules = (ph_quintic._SCREEN_RULE, ph_quintic._SCREEN_BOUND, ph_quintic._FULL_RULE, ph_quintic._FULL_BOUND)
    consts = (ph_quintic._SCREEN, ph_quintic._TIE, ph_quintic._AXIS_FALLBACK, ph_quintic._AXIS_FADE, ph_quintic._EQUAL)
    X, out = np.ones((16, 2)), np.empty((2, 3, 4))
    with pytest.raises(ValueError, match=r"X must be \(16, N\) and out \(N, 3, 4\) for N root scales"):
        kernel(X, np.ones(3), out, *consts, *rules)
    with pytest.raises(TypeError, match="every array must be float64"):
        kernel(X.astype(np.float32), np.ones(2), out, *consts, *rules)
    with pytest.raises(ValueError, match="not C-contiguous"):
        kernel(np.ones((2, 16)).T, np.ones(2), out, *consts, *rules)
    w, Ms, Mw = ph_quintic._FULL_BOUND
    with pytest.raises(ValueError, match=r"full_lo: Ms must be \(K, 6\) and Mw \(K, 3\) for K weights"):
        kernel(X, np.ones(2), out, *consts, *rules[:3], (w, Ms[:-1], Mw))
    with pytest.raises(TypeError, match=r"screen must be a tuple \(w, Ms, Mw\)"):
        kernel(X, np.ones(2), out, *consts, rules[0][:2], *rules[1:])


@pytest.mark.parametrize("kind", KINDS + ("spline",))
def test_compiled_rule_picks_the_numpy_rules_member(kind):
    """The compiled rule (what hermite_rows, the splines and PHQuintic.hermite use where it is built) returns the
    numpy rule's member to round-off, or one of the same energy where the four tie (exact degenerate data: members
    related by a symmetry of the data, chosen by round-off in both)."""
    data = spline_data(5000, seed=11) if kind == "spline" else hermite_data(kind, 5000, seed=20 + KINDS.index(kind))
    n, differ, worst = compare(*data, fast=compiled_member, reference=_least_energy_member)
    assert worst <= 1e-12, f"{kind}: {differ} of {n} members differ, energies by {worst:.1e}"
    if kind not in ("exact degenerate",):
        assert differ == 0, f"{kind}: {differ} of {n} members differ (with equal energies)"


@pytest.mark.parametrize("continuity", ["C1", "C2"])
def test_fits_without_the_compiled_rule_are_the_same(monkeypatch, continuity):
    """An install without a C compiler (the module absent: hermite_rows takes the numpy rule) fits the same splines,
    C1 and C2, through rough random waypoints and a helix: the same control points to round-off."""
    from planner.curves.spline import fit_ph_spline

    rng = np.random.default_rng(8)
    t = np.linspace(0.0, 12.0, 400)
    for points in (np.cumsum(rng.normal(size=(300, 3)), axis=0), np.c_[np.cos(t), np.sin(t), 0.1 * t]):
        compiled = fit_ph_spline(points, continuity=continuity).control_points
        with monkeypatch.context() as m:
            m.setattr(ph_quintic, "_hermite_member", None)
            numpy_rule = fit_ph_spline(points, continuity=continuity).control_points
        scale = np.abs(points).max()
        assert np.abs(numpy_rule - compiled).max() <= 1e-12 * scale


@pytest.mark.slow
@pytest.mark.parametrize("kind", KINDS + ("spline",))
def test_compiled_rule_on_many_segments(kind):
    """1e5 segments of each kind against the numpy rule."""
    for seed in range(5):
        data = spline_data(20_000, seed=300 + seed) if kind == "spline" else hermite_data(kind, 20_000, 300 + seed)
        n, differ, worst = compare(*data, fast=compiled_member, reference=_least_energy_member)
        assert worst <= 1e-12, f"{kind}: {differ} of {n} members differ, energies by {worst:.1e}"


if __name__ == "__main__":
    from planner.curves import ph_quintic

    per_kind = int(sys.argv[1]) if len(sys.argv) > 1 else 100_000
    rank_close = ph_quintic._rank_close
    full = [0]

    def counted(g, hh, tcc, est, best, bad, n):  # counts the segments that reach the full rule
        full[0] += bad.size
        return rank_close(g, hh, tcc, est, best, bad, n)

    ph_quintic._rank_close = counted
    for kind in KINDS + ("spline",):
        full[0] = 0
        totals = [0, 0, 0.0]
        for seed in range(0, per_kind, 20_000):
            m = min(20_000, per_kind - seed)
            data = spline_data(m, 1000 + seed) if kind == "spline" else hermite_data(kind, m, 1000 + seed)
            n, differ, worst = compare(*data)
            totals = [totals[0] + n, totals[1] + differ, max(totals[2], worst)]
        print(
            f"{kind:18s} segments {totals[0]:7d}  full rule {full[0] / totals[0]:6.1%}  members differ {totals[1]:5d}"
            f"  worst energy difference {totals[2]:.1e}"
        )


@pytest.mark.parametrize("rule", RULES)
def test_straight_ties_go_to_a_member_without_a_stop(rule):
    """Collinear Hermite data with unequal end speeds: every straight candidate has zero energy, and the tie goes to
    the most even parametric speed (int dt / sigma), so not to a member that stops on the way where one of the four
    does not. On 1000 random such data (speeds and chord e^N(0, 1) apart) with a stop-free straight candidate, the
    tie-break as first written (the CC measure) chose a stop on 89 of 868 (e.g. (|p1 - p0|, |d0|, |d1|) = (1, 1, 4):
    2.5e-7 of the median speed; now 0.31); this one on 1 (a dip between the quadrature's nodes, where the chord is
    a sixth of the end speeds)."""
    from planner.curves.ph_quintic import PHQuintic

    rng = np.random.default_rng(21)
    t = np.linspace(0.0, 1.0, 4001)
    checked = stops = 0
    for _ in range(1000):
        u = _unit(rng.normal(size=(3, 1)))
        dp, d0, d1 = (u * k for k in np.exp(rng.normal(scale=1.0, size=3)))
        a, r = sqrt_rot(np.hstack((d0, d1)))
        args = (dp, 120.0 * dp - 15.0 * (d0 + d1), a[:, :1], a[:, 1:], r[:1], r[1:])
        with np.errstate(divide="ignore", invalid="ignore"):
            members = all_members(*args)
        curves = [PHQuintic.from_quaternions(*m[..., 0]) for m in members]
        straight = [c for c in curves if np.abs(np.cross(c.points(t), u[:, 0])).max() <= 1e-12 * np.linalg.norm(dp)]
        if not any(c.speed(t).min() > 1e-3 * np.median(c.speed(t)) for c in straight):
            continue
        checked += 1
        sp = PHQuintic.from_quaternions(*RULES[rule](*args)[..., 0]).speed(t)
        stops += sp.min() <= 1e-3 * np.median(sp)
    assert checked > 800 and stops <= 2, (checked, stops)


# ---------------------------------------------------------------------------------------------
# The axis's arithmetic: the exports of every job depend on its rounding (issue 25: byte-identical exports)
# ---------------------------------------------------------------------------------------------


def _plain_axis(R, lam, dp):
    """ph_quintic._pure_vector_axis with _blended_axis as at 2d3a501, frozen here verbatim (but for the names): the
    plain formulas, whose rounding the members, the moves' durations and so the JSON export of every job carry."""
    sc, ss = R[3], R[7]
    s2 = sc * sc + ss * ss
    k = 1.0 / np.sqrt(s2)
    np.copysign(k, np.where(np.abs(ss) >= np.abs(sc), -ss, sc), out=k)
    c, s = -ss * k, sc * k
    near = np.flatnonzero(~(s2 >= ph_quintic._AXIS_FADE * lam))
    if near.size:
        Rn, lamn, dpn, s2n = R[:, near], lam[near], dp[:, near], s2[near]
        scn, ssn = Rn[3], Rn[7]
        bc, bs = _dot(Rn[:3], dpn), _dot(Rn[4:7], dpn)
        w = _AXIS_FALLBACK * (1.0 - s2n / (ph_quintic._AXIS_FADE * lamn)) / (lamn * _dot(dpn, dpn))
        w = np.where(np.isfinite(w), w, 0.0)
        il = np.where(lamn > 0, 1.0 / lamn, 0.0)
        Dx = (ssn * ssn - scn * scn) * il + (bc * bc - bs * bs) * w
        Dy = (-2.0 * il) * ssn * scn + (2.0 * w) * bc * bs
        r = np.hypot(Dx, Dy)
        pos = Dx >= 0
        x, y = np.where(pos, r + Dx, Dy), np.where(pos, Dy, r - Dx)
        n = np.hypot(x, y)
        ok = n > 0
        c[near], s[near] = np.where(ok, x / n, 1.0), np.where(ok, y / n, 0.0)
    return c, s


def _axis_inputs(kind: str, n: int, seed: int):
    """(R, r0, r1, dp) of n random segments of a kind, as _least_energy_block passes them to _pure_vector_axis."""
    dp, d0, d1 = spline_data(n, seed) if kind == "spline" else hermite_data(kind, n, seed)
    a, r = sqrt_rot(np.hstack((d0, d1)))
    R = _PRODUCTS @ np.multiply(a[:, :n][:, None], a[:, n:][None]).reshape(16, n)
    return R, r[:n], r[n:], dp


@pytest.mark.parametrize("kind", KINDS + ("spline",))
def test_the_axis_rounds_as_the_plain_formulas(kind):
    """Wherever the plain formulas of 2d3a501 neither under- nor overflow, the axis is theirs bit for bit, in sigma's
    branch and in the blend of near-antiparallel tangents: beab05b (issue 24) took 1 / hypot(sc, ss) for
    1 / sqrt(s2) and a blend relative to sqrt(lam) and |dp|, which moved members by round-off and 1326 move
    durations of the whole NX job's JSON export by one ulp."""
    R, r0, r1, dp = _axis_inputs(kind, 20_000, seed=40 + (KINDS + ("spline",)).index(kind))
    with np.errstate(all="ignore"):
        want = _plain_axis(R, r0 * r1, dp)
        got = ph_quintic._pure_vector_axis(R, r0, r1, dp)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
    if kind == "hairpin":  # the blend is exercised
        assert np.count_nonzero(R[3] ** 2 + R[7] ** 2 < ph_quintic._AXIS_FADE * r0 * r1) > 1000


@pytest.mark.parametrize("tangents, chord", [(-255, 0), (255, 0), (0, -255), (0, 255), (-255, 255), (255, -255)])
def test_the_axis_is_the_same_at_any_scale(tangents, chord):
    """Tangents scaled by 4^tangents and the chord by 4^chord (so a0, a2 by 2^tangents, R and |a|^2 by 4^tangents;
    here 2^-510 to 2^510, where |a0|^2 |a2|^2 and the plain formulas' squares under- or overflow) give the axis of
    the unscaled data bit for bit: every scaling inside the axis is exact, so it rounds at every scale as at 1."""
    R, r0, r1, dp = _axis_inputs("hairpin", 5000, seed=61)
    R2, r0b, r1b, dp2 = _axis_inputs("rough spatial", 5000, seed=62)
    R, r0, r1, dp = np.hstack((R, R2)), np.concatenate((r0, r0b)), np.concatenate((r1, r1b)), np.hstack((dp, dp2))
    with np.errstate(all="ignore"):
        want = ph_quintic._pure_vector_axis(R, r0, r1, dp)
        got = ph_quintic._pure_vector_axis(np.ldexp(R, 2 * tangents), np.ldexp(r0, 2 * tangents),
                                           np.ldexp(r1, 2 * tangents), np.ldexp(dp, 2 * chord))
        plain = _plain_axis(np.ldexp(R, 2 * tangents), np.ldexp(r0 * r1, 4 * tangents), np.ldexp(dp, 2 * chord))
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
    assert not np.array_equal(plain[0], want[0])  # where the plain formulas lost it
