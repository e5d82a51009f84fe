"""The default member of the PH quintic Hermite family (issue 12's rule), one compiled pass per segment.

:func:`least_energy_members` returns, for each segment, the member of least bending energy among the four
whose A0 i A2* is a pure vector (the rule and why: :func:`planner.curves.ph_quintic.batch_hermite`). The
rule's arithmetic is a few hundred floating-point operations per segment with early decisions (most
segments of smooth data are settled by one candidate's 8-node estimate and two nodes of each other one);
as numpy array operations it cost six times the rest of a C1 spline fit (a temporary array per step, every
bound computed in full), so it is compiled with numba, one loop over the segments that keeps everything in
registers. The decisions are those of the rule as first written (tests/test_member_selection.py holds it as
the oracle): the same candidates, the same Gauss rules (:func:`planner.curves.ph_quintic._energy_matrices`),
the same factor and margins; partial sums of an energy's nonnegative terms are lower bounds of it, so a
candidate is dropped as soon as a partial sum exceeds what it must exceed.

Numba compiles the kernel on its first call in a process (about 2 s) and caches the machine code beside this
module (or in the user's cache directory where that is read-only), so later processes load it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numba import njit

# The kernel reads one array of input rows and writes one array of output rows, in loops over the segments
# with no calls and no branches but selects: LLVM vectorizes them (with more arrays it would need more run-time
# overlap checks than it makes, and leave the loops scalar: 3x slower).



def _compiled(inline: bool = False) -> Callable[[Callable[..., Any]], Any]:
    """numba's njit as this module uses it: no Python error checks (a division by zero gives inf or nan, as in
    numpy), the GIL released, inlined into its callers if ``inline``, the machine code cached on disk; where no
    cache location is writable (a read-only install and no home directory) compiled once per process instead."""
    options: dict[str, Any] = {"error_model": "numpy", "nogil": True, "inline": "always" if inline else "never"}

    def compile_(fn: Callable[..., Any]) -> Any:
        try:
            return njit(cache=True, **options)(fn)
        except RuntimeError:  # "cannot cache function ...: no locator available"
            return njit(cache=False, **options)(fn)

    return compile_

#: Rows of the input X: dp = p1 - p0 (3), base = 120 dp - 15 (d0 + d1) (3), a0 (4), a2 (4), |d0|, |d1|.
X_DP, X_BASE, X_A0, X_A2, X_R0, X_R1, X_ROWS = 0, 3, 6, 10, 14, 15, 16
#: Rows of the candidates Y: A0, A1, A2 of candidate k at 12 k (4 rows each), then the tie terms T (4).
_T, _ROWS = 48, 52


@_compiled()
def _candidate_rows(X, axis_fallback, tie_weight, Y):  # pragma: no cover - compiled
    """The four candidates of every segment into Y (rows above) from the segments' rows X. Candidate
    k = 2 * (delta index) + (phi0 + pi). The formulas of ph_quintic (_products_matrix, _pure_vector_axis,
    sqrt_rot, _least_energy_member), one segment at a time."""
    for i in range(X.shape[1]):
        p0, p1, p2, p3 = X[X_A0, i], X[X_A0 + 1, i], X[X_A0 + 2, i], X[X_A0 + 3, i]
        q0, q1, q2, q3 = X[X_A2, i], X[X_A2 + 1, i], X[X_A2 + 2, i], X[X_A2 + 3, i]
        # a0 i a2* = (sc; Sc) and a0 a2* = (ss; Ss)
        Sc0 = p0 * q0 + p1 * q1 - p2 * q2 - p3 * q3
        Sc1 = p1 * q2 + p2 * q1 + p0 * q3 + p3 * q0
        Sc2 = p1 * q3 + p3 * q1 - p0 * q2 - p2 * q0
        sc = p0 * q1 - p1 * q0 + p3 * q2 - p2 * q3
        Ss0 = p1 * q0 - p0 * q1 + p3 * q2 - p2 * q3
        Ss1 = p2 * q0 - p0 * q2 + p1 * q3 - p3 * q1
        Ss2 = p3 * q0 - p0 * q3 + p2 * q1 - p1 * q2
        ss = p0 * q0 + p1 * q1 + p2 * q2 + p3 * q3
        # the pure-vector axis delta0 (_pure_vector_axis)
        dx, dy, dz = X[X_DP, i], X[X_DP + 1, i], X[X_DP + 2, i]
        ra, rb = X[X_R0, i], X[X_R1, i]
        lam = ra * rb
        bc = Sc0 * dx + Sc1 * dy + Sc2 * dz
        bs = Ss0 * dx + Ss1 * dy + Ss2 * dz
        w = axis_fallback / (lam * (dx * dx + dy * dy + dz * dz))
        w = w if abs(w) < math.inf else 0.0
        il = 1.0 / lam if lam > 0.0 else 0.0
        Dx = (ss * ss - sc * sc) * il + (bc * bc - bs * bs) * w
        Dy = (-2.0 * il) * ss * sc + (2.0 * w) * bc * bs
        r = math.sqrt(Dx * Dx + Dy * Dy)
        pos = Dx >= 0.0
        x = r + Dx if pos else Dy
        y = Dy if pos else r - Dx
        nn = math.sqrt(x * x + y * y)
        ok = nn > 0.0
        c = x / nn if ok else 1.0
        s = y / nn if ok else 0.0
        # a2 e^{i delta0}; delta0 + pi negates it
        d0, d1, d2, d3 = c * q0 - s * q1, c * q1 + s * q0, c * q2 + s * q3, c * q3 - s * q2
        S0, S1, S2 = 10.0 * (Sc0 * c + Ss0 * s), 10.0 * (Sc1 * c + Ss1 * s), 10.0 * (Sc2 * c + Ss2 * s)
        tie = tie_weight / (ra + rb)
        bl, bm, bn = X[X_BASE, i], X[X_BASE + 1, i], X[X_BASE + 2, i]
        _delta_candidates(i, 0, bl + S0, bm + S1, bn + S2, p0, p1, p2, p3, d0, d1, d2, d3, tie, Y)
        _delta_candidates(i, 1, bl - S0, bm - S1, bn - S2, p0, p1, p2, p3, -d0, -d1, -d2, -d3, tie, Y)


@_compiled(inline=True)
def _delta_candidates(i, j, l, m, n, p0, p1, p2, p3, d0, d1, d2, d3, tie, Y):  # pragma: no cover - compiled
    """The candidates 2 j, 2 j + 1 (phi0, phi0 + pi) of segment i for delta j: alpha = (l, m, n) and A2's root
    +-a2d = (d0, d1, d2, d3) (see _candidate_rows)."""
    # Q i Q* = alpha (sqrt_rot)
    rr = math.sqrt(l * l + m * m + n * n)
    qv = rr + abs(l)
    qv2 = qv + qv
    kq = 1.0 / math.sqrt(qv2 if qv2 > 1e-300 else 1e-300)
    ta, tb, tc, td = qv * kq, 0.0, n * -kq, m * kq
    neg = l < 0.0
    t0, t1, t2, t3 = (tc if neg else ta), (td if neg else tb), (ta if neg else tc), (tb if neg else td)
    u0 = p0 * t0 + p1 * t1 + p2 * t2 + p3 * t3  # <a0, Q>, <a0 i, Q>, <A2's root, Q>, <A2's root i, Q>
    v0 = -p1 * t0 + p0 * t1 + p3 * t2 - p2 * t3
    u2 = d0 * t0 + d1 * t1 + d2 * t2 + d3 * t3
    v2 = -d1 * t0 + d0 * t1 + d3 * t2 - d2 * t3
    x, y = u0 + u2, v0 + v2  # <(a0 + a2d) e^{i phi0}, Q> = x cos + y sin: the maximum at atan2(y, x)
    hq = math.sqrt(x * x + y * y)
    ok = hq > 0.0
    c = x / hq if ok else 1.0
    s = y / hq if ok else 0.0
    # A0 = a0 e^{i phi0}, A2 = +-a2d e^{i phi0}, A1 = -(3/4)(A0 + A2) + Q / 4; phi0 + pi negates A0 and A2
    a00, a01, a02, a03 = c * p0 - s * p1, c * p1 + s * p0, c * p2 + s * p3, c * p3 - s * p2
    a20, a21, a22, a23 = c * d0 - s * d1, c * d1 + s * d0, c * d2 + s * d3, c * d3 - s * d2
    _candidate(i, 2 * j, 1.0, a00, a01, a02, a03, a20, a21, a22, a23, t0, t1, t2, t3, tie, Y)
    _candidate(i, 2 * j + 1, -1.0, a00, a01, a02, a03, a20, a21, a22, a23, t0, t1, t2, t3, tie, Y)


@_compiled(inline=True)
def _candidate(i, k, f, a00, a01, a02, a03, a20, a21, a22, a23, t0, t1, t2, t3, tie, Y):  # pragma: no cover
    """Candidate k's rows of segment i: A0 = f (a00, ...), A2 = f (a20, ...), A1 = -(3/4)(A0 + A2) + Q / 4, and the
    weight of its tie term (see _energy_rows)."""
    r = 12 * k
    A0 = (f * a00, f * a01, f * a02, f * a03)
    A2 = (f * a20, f * a21, f * a22, f * a23)
    A1 = (-0.75 * (A0[0] + A2[0]) + 0.25 * t0, -0.75 * (A0[1] + A2[1]) + 0.25 * t1,
          -0.75 * (A0[2] + A2[2]) + 0.25 * t2, -0.75 * (A0[3] + A2[3]) + 0.25 * t3)
    Y[r, i], Y[r + 1, i], Y[r + 2, i], Y[r + 3, i] = A0
    Y[r + 4, i], Y[r + 5, i], Y[r + 6, i], Y[r + 7, i] = A1
    Y[r + 8, i], Y[r + 9, i], Y[r + 10, i], Y[r + 11, i] = A2
    Y[_T + k, i] = tie


@_compiled()
def _energy_rows(Y, k, w, B, out):  # pragma: no cover - compiled
    """Candidate k's energies (N,) from the candidate rows Y by a Gauss rule: weights w (K,), B (K, 6) the values
    of b0, b1, b2 and their derivatives at its nodes (A(t) = sum b_j A_j; ph_quintic._gauss_rule):
    sum_n w_n (4 (W_j^2 + W_k^2) / |A|^6 + T[k] 4 W_0^2 / |A|^4) with W = A* A' at the nodes (bending energy plus
    the tie term T[k] (sigma' / sigma)^2, sigma' = 2 W_0), inf at a cusp (|A| = 0: 0 / 0)."""
    n, m = Y.shape[1], w.shape[0]
    r = 12 * k
    out[:] = 0.0
    for j in range(m):
        b0, b1, b2, e0, e1, e2, wj = B[j, 0], B[j, 1], B[j, 2], B[j, 3], B[j, 4], B[j, 5], w[j]
        for i in range(n):
            a0 = b0 * Y[r, i] + b1 * Y[r + 4, i] + b2 * Y[r + 8, i]  # A(t)
            a1 = b0 * Y[r + 1, i] + b1 * Y[r + 5, i] + b2 * Y[r + 9, i]
            a2 = b0 * Y[r + 2, i] + b1 * Y[r + 6, i] + b2 * Y[r + 10, i]
            a3 = b0 * Y[r + 3, i] + b1 * Y[r + 7, i] + b2 * Y[r + 11, i]
            d0 = e0 * Y[r, i] + e1 * Y[r + 4, i] + e2 * Y[r + 8, i]  # A'(t)
            d1 = e0 * Y[r + 1, i] + e1 * Y[r + 5, i] + e2 * Y[r + 9, i]
            d2 = e0 * Y[r + 2, i] + e1 * Y[r + 6, i] + e2 * Y[r + 10, i]
            d3 = e0 * Y[r + 3, i] + e1 * Y[r + 7, i] + e2 * Y[r + 11, i]
            w0 = a0 * d0 + a1 * d1 + a2 * d2 + a3 * d3  # the scalar, j and k parts of A* A'
            w2 = a0 * d2 - a2 * d0 + a1 * d3 - a3 * d1
            w3 = a0 * d3 - a3 * d0 + a2 * d1 - a1 * d2
            s = a0 * a0 + a1 * a1 + a2 * a2 + a3 * a3
            out[i] += wj * ((w2 * w2 + w3 * w3) / (s * s * s) + Y[_T + k, i] * (w0 * w0) / (s * s))
    for i in range(n):
        e = 4.0 * out[i]
        out[i] = e if e >= 0.0 else math.inf  # nan: a cusp


@_compiled()
def _choose(Y, factor, screen, screen_lo, full):  # pragma: no cover - compiled
    """Index (0-3) (N,) of each segment's candidate of least energy, by the rule of
    ph_quintic._least_energy_member.

    Most segments of smooth data are decided by candidate 0's screening estimate against lower bounds of the
    other three's from two of the screen's nodes (t = 0.17, 0.83, where their loops or near-cusps lie; partial
    sums of their estimates' nonnegative terms): where those exceed factor times candidate 0's (with a margin
    for round-off), the screen takes candidate 0. The other segments get the whole screen and, where it is not
    clear by the factor, the full rule on the candidates within the factor of the best estimate.
    """
    n = Y.shape[1]
    e0, lb = np.empty(n), np.empty(n)
    _energy_rows(Y, 0, screen[0], screen[1], e0)
    open_ = np.zeros(n, dtype=np.bool_)
    for k in range(1, 4):
        _energy_rows(Y, k, screen_lo[0], screen_lo[1], lb)
        for i in range(n):
            open_[i] |= not lb[i] > factor * (1.0 + 1e-9) * e0[i]
    best = np.zeros(n, dtype=np.int64)
    rest = np.flatnonzero(open_)
    m = rest.size
    if m == 0:
        return best
    Z = np.empty((_ROWS, m))  # the rows of the open segments
    for r in range(_ROWS):
        for c in range(m):
            Z[r, c] = Y[r, rest[c]]
    est, E = np.empty((4, m)), np.empty((4, m))
    est[0] = e0[rest]
    for k in range(1, 4):
        _energy_rows(Z, k, screen[0], screen[1], est[k])
    for k in range(4):
        _energy_rows(Z, k, full[0], full[1], E[k])
    for c in range(m):
        b = 0
        for k in range(1, 4):
            if est[k, c] < est[b, c]:
                b = k
        lim = factor * est[b, c]
        clear = True
        for k in range(4):
            if k != b and not est[k, c] > lim:
                clear = False
        if not clear:  # the full rule on the candidates within the factor (none if the best estimate is 0 or inf)
            within = est[b, c] < lim
            b = 0
            eb = E[0, c] if within and est[0, c] < lim else math.inf
            for k in range(1, 4):
                ek = E[k, c] if within and est[k, c] < lim else math.inf
                if ek < eb:
                    b, eb = k, ek
        best[rest[c]] = b
    return best


@_compiled()
def least_energy_members(X, root_scale, axis_fallback, tie_weight, factor, screen, screen_lo, full,
                         out):  # pragma: no cover - compiled
    """Writes A (N, 3, 4) of each segment's default member, times root_scale (N,), into ``out``.

    X (X_ROWS, N): the segments' rows (X_DP, ...: dp = p1 - p0, base = 120 dp - 15 (d0 + d1), a0, a2 =
    sqrt_rot(d0), sqrt_rot(d1), r0, r1 = |d0|, |d1|); the rule's constants (ph_quintic: _AXIS_FALLBACK, _TIE,
    _SCREEN) and its Gauss rules (w, M, Mh) (_SCREEN_RULE, _SCREEN_BOUND, _FULL_RULE).
    """
    n = X.shape[1]
    Y = np.empty((_ROWS, n))
    _candidate_rows(X, axis_fallback, tie_weight, Y)
    best = _choose(Y, factor, screen, screen_lo, full)
    for i in range(n):
        r, rs = 12 * best[i], root_scale[i]
        for m in range(3):
            for q in range(4):
                out[i, m, q] = Y[r + 4 * m + q, i] * rs
