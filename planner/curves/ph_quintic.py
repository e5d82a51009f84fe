"""Spatial Pythagorean-hodograph quintics from quadratic quaternion polynomials.

A(t) = (1-t)^2 A0 + 2(1-t)t A1 + t^2 A2 (quaternions), hodograph r'(t) = A(t) i A*(t), speed
sigma(t) = |A(t)|^2 (grm seed, sections 2.1-2.2). Everything here is exact polynomial algebra: the arc
length is a quintic polynomial in t, so lengths and their inversion need no quadrature.

The functions prefixed ``batch_`` work on stacks of quintics (A of shape (..., 3, 4)); the spline
fitters use them to build thousands of segments at numpy speed. :class:`PHQuintic` is the
one-segment view with the documented public API. The default member of the Hermite family (C1 Hermite
interpolation, and so the C1 and C2 splines) is chosen by a rule that respects the data's geometry
(issue 12): see :func:`batch_hermite`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.curves.ph_curve import PHSegment
from planner.errors import PlannerError
from planner.validation import ArgumentError, check_vector, finite_floats

try:  # the member rule compiled (built at install where a C compiler is; see pyproject.toml), else its numpy version
    from planner.curves import _hermite_member
except ImportError:  # pragma: no cover - an install without a C compiler
    _hermite_member = None  # type: ignore[assignment]

# ---------------------------------------------------------------------------------------------
# C1 Hermite interpolation (Farouki's family with two free angles)
# ---------------------------------------------------------------------------------------------

#: Weight of the fallback axis in :func:`_pure_vector_axis` (relative, squared): it decides the axis only where
#: the end tangents are antiparallel to about 1e-6 (|sigma| below about 1e-6 |a0| |a2|).
_AXIS_FALLBACK = 1e-12
#: Composite Gauss-Legendre rule of the bending energy of the four candidates (see bending_energies): nodes on
#: each of the pieces of [0, 1]. The energy of a candidate near a cusp is a sharp peak; on 5e4 rough random
#: planar data 8 x 8 nodes rank the candidates as 64 x 16 nodes do wherever their energies differ by 1e-3
#: (6 x 8 too, 4 x 8 not: 3 differ).
_GL_NODES, _GL_PIECES = 8, 8
_FLIP = np.array([2, 3, 0, 1])
#: Right multiplication by 1, i, j, k on component rows: (q u)[c] = _RSIGN[u, c] q[_RPERM[u, c]].
_RPERM = np.array([[0, 1, 2, 3], [1, 0, 3, 2], [2, 3, 0, 1], [3, 2, 1, 0]])
_RSIGN = np.array([[1.0, 1.0, 1.0, 1.0], [-1.0, 1.0, 1.0, -1.0], [-1.0, -1.0, 1.0, 1.0], [-1.0, 1.0, -1.0, 1.0]])
_IPERM, _ISIGN = _RPERM[1], _RSIGN[1][:, None]  # q i on rows: <B i, Q> = sum B[_IPERM] Q _ISIGN


def _products_matrix() -> np.ndarray:
    """(10, 16): rows (vec, scalar) of p i q* and of p q*, and the j, k parts of p* q, from the 16 products p_k q_l
    (row 4 k + l)."""
    M = np.zeros((10, 16))
    terms = (  # (row, k, l, sign)
        [(0, 0, 0, 1), (0, 1, 1, 1), (0, 2, 2, -1), (0, 3, 3, -1), (1, 1, 2, 1), (1, 2, 1, 1), (1, 0, 3, 1)]
        + [(1, 3, 0, 1), (2, 1, 3, 1), (2, 3, 1, 1), (2, 0, 2, -1), (2, 2, 0, -1)]
        + [(3, 0, 1, 1), (3, 1, 0, -1), (3, 3, 2, 1), (3, 2, 3, -1)]
        + [(4, 1, 0, 1), (4, 0, 1, -1), (4, 3, 2, 1), (4, 2, 3, -1), (5, 2, 0, 1), (5, 0, 2, -1), (5, 1, 3, 1)]
        + [(5, 3, 1, -1), (6, 3, 0, 1), (6, 0, 3, -1), (6, 2, 1, 1), (6, 1, 2, -1)]
        + [(7, 0, 0, 1), (7, 1, 1, 1), (7, 2, 2, 1), (7, 3, 3, 1)]
        + [(8, 0, 2, 1), (8, 2, 0, -1), (8, 3, 1, -1), (8, 1, 3, 1), (9, 0, 3, 1), (9, 3, 0, -1), (9, 1, 2, -1)]
        + [(9, 2, 1, 1)]
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


#: OpenBLAS runs a matrix product with m n k above 4 * 65536 on all cores; on a loaded machine waking the threads
#: costs far more than the product (a 1000-waypoint C1 fit took 9 ms instead of 0.6 at a load of 2.6 on 2 cores),
#: so _mm cuts larger products into column blocks below that size.
_BLAS_ONE_THREAD = 262_144


def _mm(M: np.ndarray, X: np.ndarray) -> np.ndarray:
    """M @ X (m, N) for M (m, k), X (k, N), on one thread (column blocks of at most _BLAS_ONE_THREAD / (m k))."""
    m, k = M.shape
    n = X.shape[1]
    step = max(1, _BLAS_ONE_THREAD // (m * k))
    if n <= step:
        return M @ X
    out = np.empty((m, n))
    for a in range(0, n, step):
        np.matmul(M, X[:, a:a + step], out=out[:, a:a + step])
    return out


def _dot(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Row-wise inner products (N,) of component rows."""
    return np.einsum("ij,ij->j", p, q)


#: Where |sigma|^2 / (|a0|^2 |a2|^2) (the squared cosine of half the angle between the end tangents) is below this,
#: the fallback axis joins the blend of :func:`_pure_vector_axis`, with a weight fading to 0 at it (tangents more
#: than 143 degrees apart); above it the axis is sigma's alone.
_AXIS_FADE = 0.1


def _pure_vector_axis(R, r0, r1, dp):
    """(cos, sin) (N,) of the delta = phi2 - phi0 (defined up to pi) at which A0 i A2* is a pure vector.

    R (10, N): the vector and scalar parts of a0 i a2* (Sc, sc) and of a0 a2* (Ss, ss), rows 0-7 of
    _PRODUCTS (8-9 unused here); r0, r1 = |a0|^2, |a2|^2 (lam = r0 r1),
    dp = p1 - p0 (3, N). The quaternion a0 i (a2 e^{i delta})* = (sc cos + ss sin) + S(delta) has the scalar part
    sigma.z with sigma = (sc, ss), z = (cos delta, sin delta): it vanishes on the axis z = +-sigma_perp. Where the
    end tangents are antiparallel sigma = 0 and every delta qualifies; there the axis maximizing |<S(delta), dp>|
    (b = (<Sc, dp>, <Ss, dp>)) decides. Both axes are blended sign-free, on doubled angles (an axis z ~ -z is the
    point (x^2 - y^2, 2 x y)), the second with the weight _AXIS_FALLBACK (fading out as |sigma|^2 / lam rises to
    _AXIS_FADE), so that the result is a continuous function of the data wherever the blend is nonzero. Both axes
    are carried onto themselves by every isometry of the data (rotations; the reflections that fix planar data or
    map mirror-symmetric data onto their reversal), and so is the weight (|sigma| is invariant), so their blend
    is too. The sign of z is that of the half angle: cos delta >= 0 where |ss| >= |sc|, sin delta > 0 elsewhere.
    A zero end tangent (r0 or r1 = 0: a2 e^{i delta} or a0 is 0 for every delta) gives delta = 0.

    The formulas run on operands scaled by powers of two (:func:`_even_exponent`): |a0|^2 and |a2|^2 into [0.5, 2),
    sigma and the products R with the root of their product, dp by its largest component's. Such a scaling is exact,
    so every product, sum, quotient and root is rounded as without it wherever that neither under- nor overflows
    (the members of 2d3a501 and before, bit for bit: the moves' durations and the exports stay byte-identical),
    and none under- or overflows whatever the tangents' and the chord's sizes (a chord 1e-160 of the tangents, or a
    tangent 1e-320 of the chord, gave 0 * inf = nan; |sigma|^2 could underflow).
    Call under np.errstate(divide="ignore", invalid="ignore").
    """
    e0, e1 = _even_exponent(r0), _even_exponent(r1)
    r0, r1 = np.ldexp(r0, -e0), np.ldexp(r1, -e1)
    R = np.ldexp(R[:8], -((e0 + e1) // 2))
    lam = r0 * r1
    sc, ss = R[3], R[7]
    s2 = sc * sc + ss * ss
    k = 1.0 / np.sqrt(s2)
    np.copysign(k, np.where(np.abs(ss) >= np.abs(sc), -ss, sc), out=k)  # the sign of the half angle (see above)
    c, s = -ss * k, sc * k
    near = np.flatnonzero(~((s2 >= _AXIS_FADE * lam) & (s2 > 0.0)))
    if near.size:
        c[near], s[near] = _blended_axis(R[:, near], lam[near], dp[:, near], s2[near])
    return c, s


def _even_exponent(x):
    """The even exponents e (N,) (int) with x 2^-e in [0.5, 2) for positive finite x (N,); 0 for 0, inf or nan."""
    e = np.frexp(x)[1] & ~1
    return np.where(np.isfinite(x), e, 0)


def _blended_axis(R, lam, dp, s2):
    """:func:`_pure_vector_axis` where |sigma|^2 < _AXIS_FADE lam: sigma's axis blended with b's (see there); R, lam
    and s2 as scaled there, dp (3, N) scaled here (a zero tangent has neither axis: (1, 0))."""
    dp = np.ldexp(dp, -_even_exponent(np.abs(dp).max(axis=0)))
    sc, ss = R[3], R[7]
    bc, bs = _dot(R[:3], dp), _dot(R[4:7], dp)
    w = _AXIS_FALLBACK * (1.0 - s2 / (_AXIS_FADE * lam)) / (lam * _dot(dp, dp))
    w = np.where(np.isfinite(w), w, 0.0)
    il = np.where(lam > 0, 1.0 / lam, 0.0)
    Dx = (ss * ss - sc * sc) * il + (bc * bc - bs * bs) * w  # doubled angle of sigma_perp = (-ss, sc) ...
    Dy = (-2.0 * il) * ss * sc + (2.0 * w) * bc * bs  # ... and of b
    r = np.hypot(Dx, Dy)
    # half angle: (r + Dx, Dy) ~ z for Dx >= 0 and (Dy, r - Dx) ~ z otherwise (no cancellation either way)
    pos = Dx >= 0
    x, y = np.where(pos, r + Dx, Dy), np.where(pos, Dy, r - Dx)
    n = np.hypot(x, y)
    ok = n > 0  # no axis at all: d1 antiparallel to d0 and p1 - p0 along them (a straight hairpin), or a zero tangent
    return np.where(ok, x / n, 1.0), np.where(ok, y / n, 0.0)


def _member(a0, a2d, Q, c0, s0) -> np.ndarray:
    """A (3, 4, N) of the member A0 = a0 e^{i phi0}, A2 = a2d e^{i phi0}, A1 = -(3/4)(A0 + A2) + Q / 4
    (Farouki's solution of the end-point condition), c0, s0 = cos, sin phi0."""
    A = np.empty((3,) + a0.shape)
    _times_e_i(np.stack((a0, a2d), axis=1), c0, s0, A[::2].transpose(1, 0, 2))  # A0 and A2 in one pass
    np.multiply(A[0] + A[2], -0.75, out=A[1])
    A[1] += 0.25 * Q
    return A


def _energy_matrices(nodes: int, pieces: int = 1) -> tuple[np.ndarray, ...]:
    """Weights (K,) of the composite Gauss-Legendre rule on [0, 1] (``pieces`` equal pieces, ``nodes`` each) and
    the matrices that map the inner products of A0, A1, A2 to the values at its K nodes of sigma = |A|^2 (K, 6
    products g00 g01 g02 g11 g12 g22, g_jk = <A_j, A_k>) and of a vector part of A* A' (K, 3 products of that
    part, u01 u02 u12 with u_jk = <A_j u, A_k> = -u_kj for u = j or k)."""
    x, wx = np.polynomial.legendre.leggauss(nodes)
    t = ((0.5 * (x + 1.0))[None] + np.arange(pieces)[:, None]).ravel() / pieces
    w = np.tile(wx, pieces) / (2.0 * pieces)
    b = np.stack(((1 - t) ** 2, 2 * t * (1 - t), t * t), axis=1)  # A(t) = sum b_j A_j
    db = np.stack((-2 * (1 - t), 2 - 4 * t, 2 * t), axis=1)  # A'(t) = sum db_j A_j
    Ms = np.zeros((t.size, 6))
    for q, (j, k) in enumerate(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))):
        Ms[:, q] = (1.0 if j == k else 2.0) * b[:, j] * b[:, k]  # g_jk appears as jk and kj
    Mw = np.zeros((t.size, 3))
    for q, (j, k) in enumerate(((0, 1), (0, 2), (1, 2))):  # <A u, A'> = sum b_j db_k u_jk, u_kj = -u_jk, u_jj = 0
        Mw[:, q] = b[:, j] * db[:, k] - b[:, k] * db[:, j]
    return w, Ms, Mw


_FULL_RULE = _energy_matrices(_GL_NODES, _GL_PIECES)
#: The screening rule of _least_energy_member (2 x 4 nodes): a candidate whose estimate is below 1 / _SCREEN of
#: the others' is taken without the full rule (on 1e5 rough random planar data: no difference from the full
#: rule; a 3-node rule with a factor 3 differed on 1 %).
_SCREEN_RULE = _energy_matrices(4, 2)
_SCREEN = 10.0
#: Full-rule energies within this factor of the least are equal: the first candidate of them is taken. Data with a
#: symmetry (mirror-symmetric, or carried onto their reversal by a rotation) have candidates related by it, of equal
#: energy: which one round-off made the least differed between the compiled and the numpy rule, and so did the C2
#: spline started from them (5.64 against 5.60 on waypoints along a line that turn back). Round-off of the energies
#: is about 1e-15 of them.
_EQUAL = 1e-12
#: Weight of the tie term int dt / sigma (see _energies_at_nodes): above the round-off of a straight member's energy
#: (W's round-off squared, about 1e-32 of the scale 1 / |p1 - p0|), below any bend's (a bend of 1e-10 of the chord
#: has an energy of about 1e-20 of it).
_TIE = 1e-24


def bending_energies(A: np.ndarray) -> np.ndarray:
    """Bending energy integral of kappa^2 ds (M,) of PH quintics A (3, 4, M) (coefficients, component rows),
    by the composite Gauss-Legendre rule _GL_PIECES x _GL_NODES (a cusp at a node counts as infinite energy).

    With r' = A i A*: sigma = |A|^2 and r'' = 2 vec(A' i A*), so kappa^2 sigma = |r' x r''|^2 / sigma^5
    = 4 (W_j^2 + W_k^2) / |A|^6 with W = A* A' (its j, k parts are r'' across the tangent, in the frame of A:
    a sum of squares, free of the cancellation of |A|^2 |A'|^2 - <A, A'>^2 - <A i, A'>^2). W_u = <A u, A'> and
    sigma are quadratic forms in A0, A1, A2, so their values at the nodes are matrix products of inner products.
    """
    A0, A1, A2 = A
    g = np.stack((_dot(A0, A0), _dot(A0, A1), _dot(A0, A2), _dot(A1, A1), _dot(A1, A2), _dot(A2, A2)))
    u = np.empty((3, 2) + A0.shape[1:])  # u01, u02, u12 for u = j, k
    for k, U in enumerate((2, 3)):
        A0u, A1u = A0[_RPERM[U]] * _RSIGN[U][:, None], A1[_RPERM[U]] * _RSIGN[U][:, None]
        u[0, k], u[1, k], u[2, k] = _dot(A0u, A1), _dot(A0u, A2), _dot(A1u, A2)
    w, Ms, Mw = _FULL_RULE
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return _energies_at_nodes(_mm(Ms, g), _mm(Mw, u.reshape(3, -1)), w, tie=0.0)


def _energies_at_nodes(S: np.ndarray, Y: np.ndarray, w: np.ndarray, tie: float = _TIE) -> np.ndarray:
    """4 int kappa^2 sigma dt (M,) by a Gauss rule of weights w (K,) from the values at its nodes of sigma (S (K, M))
    and of W_j, W_k (W = A* A'; Y (K, 2 M), W_j of the M curves then W_k): 4 (W_j^2 + W_k^2) / sigma^3 (see
    :func:`bending_energies`), plus ``tie`` times int dt / sigma, which breaks ties of the energy (straight
    members, of zero energy) towards the most even parametric speed (int dt / sigma >= 1 / int sigma dt, equal
    for a constant speed; a momentary stop makes it infinite). S and Y are overwritten (no temporaries: they
    would be fresh pages). A cusp at a node (sigma = 0) gives an infinite energy. Call under np.errstate."""
    m = S.shape[1]
    np.abs(S, out=S)  # sigma = |A|^2 >= 0 but for round-off: near a cusp W^2 / |sigma|^3 ~ 1 / |sigma| is huge
    np.divide(1.0, S, out=S)
    Y *= Y
    L = Y[:, :m]
    L += Y[:, m:]
    np.multiply(S, S, out=Y[:, m:])
    Y[:, m:] *= S  # 1 / sigma^3
    L *= Y[:, m:]
    E = w @ L
    E *= 4.0
    if tie:
        E += tie * (w @ S)
    E[~(E >= 0.0)] = np.inf  # nan (0 * inf) at a cusp
    return E


#: Two nodes of the screening rule (t = 0.17, 0.83) with their weights, rows of its matrices: lower bounds of
#: its estimates (see _screen).
_SCREEN_BOUND = tuple(m[[1, 6]] for m in _SCREEN_RULE)
#: The full rule's nodes on the pieces 0, 1, 6, 7 of 8 (t < 1/4, t > 3/4) with their weights, rows of its
#: matrices: lower bounds of its energies (see _rank_close).
_FULL_BOUND = tuple(m[np.r_[0:16, 48:64]] for m in _FULL_RULE)


def _estimates(g, u, cols, rule) -> np.ndarray:
    """Energy estimates plus tie terms (M,) of the candidates in columns ``cols`` (M,) of g (6, C), u (3, 2, C) by
    ``rule`` (weights and matrices of :func:`_energy_matrices`, or a subset of its nodes)."""
    w, Ms, Mw = rule
    return _energies_at_nodes(_mm(Ms, g[:, cols]), _mm(Mw, u[:, :, cols].reshape(3, -1)), w)


#: Segments per block of _least_energy_member: its temporaries (about 60 kB per 100 segments) stay small enough to
#: be reused from the allocator's free lists instead of being fresh pages each time (10000 segments in one
#: block took twice as long, half of it page faults).
_BLOCK = 2048


def _least_energy_member(dp, base, a0, a2, r0, r1) -> np.ndarray:
    """A (3, 4, N) of the default member (see :func:`_least_energy_block`), in blocks of _BLOCK segments."""
    n = dp.shape[1]
    if n <= _BLOCK:
        return _least_energy_block(dp, base, a0, a2, r0, r1)
    A = np.empty((3, 4, n))
    for a in range(0, n, _BLOCK):
        b = slice(a, a + _BLOCK)
        A[..., b] = _least_energy_block(dp[:, b], base[:, b], a0[:, b], a2[:, b], r0[b], r1[b])
    return A


def _least_energy_block(dp, base, a0, a2, r0, r1) -> np.ndarray:
    """A (3, 4, N) of the default member (see :func:`batch_hermite`): of the four members with A0 i A2* a pure
    vector, the one of least bending energy.

    The candidates are delta in {delta0, delta0 + pi} (``_pure_vector_axis``) and, for each, phi0 at the maximum
    of <A0 + A2, Q> and phi0 + pi. Their energies E = 4 int (W_j^2 + W_k^2) / sigma^3 dt (see
    :func:`bending_energies`) follow from the inner products g_jk = <A_j, A_k> (sigma) and <A_j u, A_k> (u = j, k:
    W_j, W_k) of A0, A1, A2, themselves from a few inner products of a0, a2, Q (A1 = -(3/4)(A0 + A2) + Q/4,
    <A0, A0> = |d0|, ...). The common phase e^{i phi0} of A0, A1, A2 does not change the curve, so the candidates
    are built as a0, a2 e^{i delta}, A1 e^{-i phi0}. The rule: a coarse Gauss rule (_SCREEN_RULE) screens them;
    where one candidate's estimate is below 1 / _SCREEN of the other three's (smooth data: the others have cusps
    or loops) it is taken; elsewhere the composite rule of :func:`bending_energies` decides among the candidates
    within _SCREEN of the best estimate. Ties of the energy (straight members) go to the most even parametric speed
    (a _TIE weight of int dt / sigma, see :func:`_energies_at_nodes`).

    The work is cut without changing the choice (tests/test_member_selection.py checks it against the rule as
    first written, whose integrand cancelled: the same member, or one of no larger energy): most segments are
    decided by candidate 0's estimate and lower bounds of the others' (see :func:`_screen`), and where the full
    rule decides, the screen's best is confirmed by lower bounds of the others' full-rule energies (see
    :func:`_rank_close`).
    """
    n = dp.shape[1]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        # a0 i a2*, a0 a2* (vector, scalar) and the j, k parts of a0* a2
        R = _mm(_PRODUCTS, np.multiply(a0[:, None], a2[None]).reshape(16, n))
        c, s = _pure_vector_axis(R, r0, r1, dp)
        X = np.empty((8, 4, n))  # a0 u and a2d u for u = 1, i, j, k, a2d = a2 e^{i delta0} (delta0 + pi negates it)
        np.multiply(a0[_RPERM], _RSIGN[..., None], out=X[:4])
        a2d = a2 * c
        a2d += a2[_IPERM] * (_ISIGN * s)  # a2 cos + (a2 i) sin
        np.multiply(a2d[_RPERM], _RSIGN[..., None], out=X[4:])
        S = R[:3] * c
        S += R[4:7] * s
        S *= 10.0
        alpha = np.empty((3, 2, n))  # per delta (delta0, delta0 + pi): Farouki's alpha = base + 10 S(delta)
        np.add(base, S, out=alpha[:, 0])
        np.subtract(base, S, out=alpha[:, 1])
        Qf, qq = sqrt_rot(alpha.reshape(3, 2 * n))
        Q = Qf.reshape(4, 2, n)
        uv = np.einsum("vcn,ckn->vkn", X, Q)  # <a0 u, Q>, <a2d u, Q> per delta (8, 2, N)
        uv[4:, 1] *= -1.0  # a2 e^{i (delta0 + pi)} = -a2d
        x, y = uv[0] + uv[4], uv[1] + uv[5]  # <(a0 + a2d) e^{i phi0}, Q> = x cos + y sin: the maximum at atan2(y, x)
        ih = 1.0 / np.sqrt(x * x + y * y)
        c0, s0 = x * ih, y * ih
        if not np.isfinite(ih).all():  # x = y = 0: every phi0 alike
            ok = np.isfinite(ih)
            c0, s0 = np.where(ok, c0, 1.0), np.where(ok, s0, 0.0)
        # the candidates' inner products, k = 2 * (delta index) + (phi0 + pi) (the flip negates A0, A2 and so the
        # products with Q): g (6, 2, 2, N) = <A_j, A_k> (00 01 02 11 12 22), w (3, 2, 2, 2, N) = <A_j u, A_k>
        # (01 02 12) for u = j, k, of a0, a2 e^{i delta}, A1 e^{-i phi0} (Q e^{-i phi0} in A1)
        P = c0 * uv[0::4]  # <A0, Q>, <A2, Q> at phi0 (2, 2, N)
        P += s0 * uv[1::4]
        P *= 0.25
        Z = np.empty((2, 2, 2, n))  # <a0 u, Q e^{-i phi0}>, <a2d u, ..> (u = j, k): u e^{i phi0} = u cos -+ (k, j) sin
        np.multiply(c0, uv[2::4], out=Z[0])
        Z[0] -= s0 * uv[3::4]
        np.multiply(c0, uv[3::4], out=Z[1])
        Z[1] += s0 * uv[2::4]
        Z *= 0.25
        g = np.empty((6, 2, 2, n))
        g[0], g[5] = r0, r1
        G = R[7] * c  # <A0, A2> = <a0, a2 e^{i delta}>
        G -= R[3] * s
        g[2, 0] = G
        np.negative(G, out=g[2, 1, 0])
        g[2, 1, 1] = g[2, 1, 0]
        b01 = -0.75 * (r0 + g[2, :, 0])  # <A0, A1> = -3/4 (|A0|^2 + <A0, A2>) + <A0, Q> / 4, <A1, A2> alike
        b12 = -0.75 * (r1 + g[2, :, 0])
        np.add(b01, P[0], out=g[1, :, 0])
        np.subtract(b01, P[0], out=g[1, :, 1])
        np.add(b12, P[1], out=g[4, :, 0])
        np.subtract(b12, P[1], out=g[4, :, 1])
        T = 2.0 * g[2, :, 0]
        T += r0 + r1  # |A0 + A2|^2
        b11 = 0.5625 * T  # |A1|^2 = 9/16 |A0 + A2|^2 - 3/8 <A0 + A2, Q> + |Q|^2 / 16
        Pm = 1.5 * (P[0] + P[1])
        np.subtract(b11, Pm, out=g[3, :, 0])
        np.add(b11, Pm, out=g[3, :, 1])
        g[3] += (0.0625 * qq.reshape(2, n))[:, None]
        w = np.empty((3, 2, 2, 2, n))
        Eu = np.empty((2, n))  # <a0 u, a2 e^{i delta0}> for u = j, k: e^{-i delta} u = u cos + (k, -j) sin
        np.multiply(R[8], c, out=Eu[0])
        Eu[0] += R[9] * s
        np.multiply(R[9], c, out=Eu[1])
        Eu[1] -= R[8] * s
        w[1, :, 0] = Eu[:, None]
        np.negative(Eu[:, None], out=w[1, :, 1, 0:1])
        w[1, :, 1, 1] = w[1, :, 1, 0]
        b = -0.75 * w[1, :, :, 0]  # <A0 u, A1> = -3/4 <A0 u, A2> + <A0 u, Q> / 4, <A1 u, A2> = ... - <A2 u, Q> / 4
        np.add(b, Z[:, 0], out=w[0, :, :, 0])
        np.subtract(b, Z[:, 0], out=w[0, :, :, 1])
        np.subtract(b, Z[:, 1], out=w[2, :, :, 0])
        np.add(b, Z[:, 1], out=w[2, :, :, 1])
        cusp = np.flatnonzero((r0 == 0.0) | (r1 == 0.0))
        if cusp.size:  # a zero end tangent: the candidates' reduced curves decide (see _reduced_products)
            g[..., cusp], w[..., cusp] = _reduced_products(g[..., cusp], w[..., cusp], r0[cusp] == 0.0, r1[cusp] == 0.0)
        best = _screen(g.reshape(6, 4 * n), w.reshape(3, 2, 4 * n), n)
    j, fl = best // 2, best % 2
    sign = 1.0 - 2.0 * fl
    cols = np.arange(n)
    return _member(a0, a2d * (1.0 - 2.0 * j), Q[:, j, cols], sign * c0[j, cols], sign * s0[j, cols])


#: The Bernstein coefficients (rows) of the reduced factor B of A (see _reduced_products) in terms of A0, A1, A2:
#: A2 = 0 (a zero tangent at the end): A = (1 - t) B, B = (1 - t) A0 + 2 t A1; A0 = 0: A = t B, B = 2 (1 - t) A1 + t A2;
#: both: A = 2 t (1 - t) A1, B = 2 A1 (B linear, written as a quadratic: (B0, (B0 + B1) / 2, B1)).
_REDUCE = {
    (False, True): np.array([[1.0, 0.0, 0.0], [0.5, 1.0, 0.0], [0.0, 2.0, 0.0]]),
    (True, False): np.array([[0.0, 2.0, 0.0], [0.0, 1.0, 0.5], [0.0, 0.0, 1.0]]),
    (True, True): np.array([[0.0, 2.0, 0.0], [0.0, 2.0, 0.0], [0.0, 2.0, 0.0]]),
}
#: Index pairs of the six inner products g (00 01 02 11 12 22) and of the three u (01 02 12).
_G_PAIRS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
_U_PAIRS = ((0, 1), (0, 2), (1, 2))


def _reduced_products(g, w, z0, z1):
    """The candidates' inner products g (6, ..., M) and w (3, 2, ..., M) (as _least_energy_block builds them) of
    segments with a zero end tangent, replaced by those of their reduced curves; z0, z1 (M,) say which tangents are
    zero (at t = 0, at t = 1; at least one per segment).

    A zero tangent at t = 1 makes A2 = 0, so A = (1 - t) B with B linear: the curve has a cusp there, every
    non-straight member an infinite bending energy and every member an infinite int dt / sigma (the tie term), so
    that a Gauss rule's values are decided by its nodes nearest the cusp and by round-off (a straight member that
    stops on the way was taken for one that does not, and the compiled and numpy rules differed). The common factor
    (1 - t)^2 of sigma carries no choice: the candidates are compared by their reduced curves, of hodograph B i B*,
    whose energies and tie terms are finite (B written as a quadratic with the coefficients _REDUCE). Both are
    quadratic forms, so the reduced products are T G T^T of those of A0, A1, A2 (G symmetric from g, U antisymmetric
    from w).
    """
    g, w = g.copy(), w.copy()
    for (e0, e1), T in _REDUCE.items():
        cols = np.flatnonzero((z0 == e0) & (z1 == e1))
        if not cols.size:
            continue
        G = np.empty((3, 3) + g.shape[1:-1] + (cols.size,))
        U = np.zeros((3, 3) + w.shape[1:-1] + (cols.size,))
        for q, (a, b) in enumerate(_G_PAIRS):
            G[a, b] = G[b, a] = g[q][..., cols]
        for q, (a, b) in enumerate(_U_PAIRS):
            U[a, b] = w[q][..., cols]
            U[b, a] = -U[a, b]
        G = np.einsum("ja,kb,ab...->jk...", T, T, G)
        U = np.einsum("ja,kb,ab...->jk...", T, T, U)
        for q, (a, b) in enumerate(_G_PAIRS):
            g[q][..., cols] = G[a, b]
        for q, (a, b) in enumerate(_U_PAIRS):
            w[q][..., cols] = U[a, b]
    return g, w


def _screen(g, u, n) -> np.ndarray:
    """The best candidate (N,) (index 0-3) from the candidates' inner products g (6, 4N) and u (3, 2, 4N) (columns
    k N + segment): the screening rule's choice where one candidate's estimate is below
    1 / _SCREEN of the other three's, :func:`_rank_close` elsewhere.

    Most segments of smooth data are decided by candidate 0's estimate and lower bounds of the other three's
    from two of the screening rule's eight nodes (t = 0.17, 0.83, where their loops or near-cusps lie), each a
    part of their estimate's sum of nonnegative terms: where those exceed _SCREEN times candidate 0's (with a
    margin for round-off) the screen would take candidate 0. The other segments get the whole screen.
    """
    E0 = _estimates(g, u, slice(0, n), _SCREEN_RULE)
    lb = _estimates(g, u, slice(n, 4 * n), _SCREEN_BOUND).reshape(3, n)
    best = np.zeros(n, dtype=np.intp)
    rest = np.flatnonzero(~(lb > (_SCREEN * (1.0 + 1e-9)) * E0).all(axis=0))
    if rest.size:  # the whole screen: the other three's estimates
        m = rest.size
        cols = (np.arange(4)[:, None] * n + rest).ravel()
        g, u = g[:, cols], u[:, :, cols]
        est = np.empty((4, m))
        est[0] = E0[rest]
        est[1:] = _estimates(g, u, slice(m, 4 * m), _SCREEN_RULE).reshape(3, m)
        b = np.argmin(est, axis=0)
        sub = np.arange(m)
        eb = est[b, sub]
        others = est.copy()
        others[b, sub] = np.inf
        bad = np.flatnonzero(~(others.min(axis=0) > _SCREEN * eb))
        if bad.size:
            b[bad] = _rank_close(g, u, est, b, bad, m)
        best[rest] = b
    return best


def _rank_close(g, u, est, best, bad, n) -> np.ndarray:
    """The best candidate (index 0-3) of each segment ``bad`` among those within _SCREEN of the best screening
    estimate, by the full rule.

    The screen's best is confirmed without the full rule on the others where its full-rule energy is below lower
    bounds of theirs: their full rule's terms on the pieces 0, 1, 6, 7 of its 8 (t < 1/4 and t > 3/4, where their
    loops or near-cusps lie; part of the same sum of nonnegative terms). Elsewhere the full rule decides.
    """
    m = bad.size
    cols = np.arange(m)
    b, eb = best[bad], est[best[bad], bad]
    k, col = np.nonzero(est[:, bad] < _SCREEN * eb)
    kc = k * n + bad[col]  # the candidates' columns
    E = np.full((4, m), np.inf)
    E[b, cols] = _estimates(g, u, b * n + bad, _FULL_RULE)
    o = k != b[col]
    low = np.full((4, m), np.inf)
    low[k[o], col[o]] = _estimates(g, u, kc[o], _FULL_BOUND)
    has_b = np.zeros(m, dtype=bool)
    has_b[col[~o]] = True  # the best is a candidate unless its estimate is 0 or infinite (then none is)
    redo = np.flatnonzero(~(has_b & (low.min(axis=0) > E[b, cols] * (1.0 + 1e-9))))
    if redo.size:  # the full rule on those segments' candidates
        pick = np.isin(col, redo) & o
        E[k[pick], col[pick]] = _estimates(g, u, kc[pick], _FULL_RULE)
        E[:, redo[~has_b[redo]]] = np.inf
        b[redo] = np.argmax(E[:, redo] <= E[:, redo].min(axis=0) * (1.0 + _EQUAL), axis=0)
    return b


def _least_energy_compiled(dp, base, a0, a2, r0, r1, root_scale=None) -> np.ndarray:
    """A (N, 3, 4) of the default member (arguments as :func:`_least_energy_member` takes them), times
    ``root_scale`` (N,) if given, by the compiled rule (planner/curves/_hermite_member.c: the arithmetic of
    :func:`_least_energy_block` one segment at a time, with its constants and Gauss rules)."""
    n = dp.shape[1]
    X = np.empty((16, n))  # the rows the kernel reads: dp, base, a0, a2, |d0|, |d1|
    X[:3], X[3:6], X[6:10], X[10:14], X[14], X[15] = dp, base, a0, a2, r0, r1
    scale = np.ones(n) if root_scale is None else np.ascontiguousarray(root_scale, dtype=float)
    out = np.empty((n, 3, 4))
    assert _hermite_member is not None
    _hermite_member.least_energy_members(X, scale, out, _SCREEN, _TIE, _AXIS_FALLBACK, _AXIS_FADE, _EQUAL,
                                         _SCREEN_RULE, _SCREEN_BOUND, _FULL_RULE, _FULL_BOUND)
    return out


def hermite_rows(dp, d0, d1, a0, a2, r0, r1, angles=None, root_scale=None) -> np.ndarray:
    """batch_hermite on component rows: dp = p1 - p0, d0, d1 (3, N), a0, a2 = sqrt_rot(d0), sqrt_rot(d1)
    (4, N) and r0, r1 = |d0|, |d1|; returns A (N, 3, 4), multiplied by ``root_scale`` (N,) if given (the
    interpolant of data scaled by h is h times the curve, sqrt(h) times A, with the same free angles)."""
    n = dp.shape[1]
    base = 120.0 * dp - 15.0 * (d0 + d1)  # Farouki: alpha = base + 5 (A0 i A2* + A2 i A0*)
    if angles is None and _hermite_member is not None:
        return _least_energy_compiled(dp, base, a0, a2, r0, r1, root_scale)
    if angles is None:
        A = _least_energy_member(dp, base, a0, a2, r0, r1)
    else:
        ang = finite_floats(angles, "angles", ((2,), (2, None)))
        if ang.ndim == 2 and ang.shape[1] not in (1, n):
            raise ArgumentError("angles", f"must be (phi0, phi2), each one angle or one per segment ({n}), "
                                          f"got shape {ang.shape}")
        phi0 = np.broadcast_to(ang[0], (n,))
        delta = np.broadcast_to(ang[1], (n,)) - phi0
        a2d = _times_e_i(a2, np.cos(delta), np.sin(delta))
        Q = sqrt_rot(base + 10.0 * _i_product(a0, a2d))[0]  # Farouki: (3A0+4A1+3A2) i (..)* = alpha
        A = _member(a0, a2d, Q, np.cos(phi0), np.sin(phi0))
    out = np.empty((n, 3, 4))
    if root_scale is None:
        out[...] = A.transpose(2, 0, 1)
    else:
        np.multiply(A.transpose(2, 0, 1), root_scale[:, None, None], out=out)
    return out


def batch_hermite(p0, p1, d0, d1, angles=None) -> np.ndarray:
    """Quaternion coefficients A (N, 3, 4) of PH quintics with r(0)=p0, r(1)=p1, r'(0)=d0, r'(1)=d1.

    Inputs have shape (N, 3). With ``angles`` = (phi0, phi2) (scalars or (N,) arrays) the member
    A0 = sqrt|d0| n(d0) e^{i phi0}, A2 = sqrt|d1| n(d1) e^{i phi2}, A1 = -(3/4)(A0 + A2) + Q/4 with
    Q i Q* = 120 (p1 - p0) - 15 (d0 + d1) + 5 (A0 i A2* + A2 i A0*) and Q's phase fixed to 0 (the common
    phase of A0, A1, A2 does not change the curve) is returned (Farouki, al-Kandari, Sakkalis 2002).

    With ``angles=None`` (the default member) the rule is:

    1. Four distinguished members: those where A0 i A2* is a pure vector (zero scalar part). That fixes
       delta = phi2 - phi0 up to pi in closed form (the scalar part is sigma.(cos delta, sin delta), see
       :func:`_pure_vector_axis`); for each delta, phi0 is where |A0 - 2 A1 + A2| (the CC measure of Farouki,
       Giannelli, Manni, Sestini 2008) is extremal, a sinusoid in phi0 with two extremes phi0, phi0 + pi.
    2. Of the four, the one of least bending energy integral of kappa^2 ds (the criterion of Farouki 1996,
       "The elastic bending energy of Pythagorean-hodograph curves", CAGD 13), by Gauss-Legendre quadrature of
       kappa^2 sigma = 4 (W_j^2 + W_k^2) / |A|^6, W = A* A' (a sum of squares: a nearly straight member's energy
       carries no cancellation, so the choice on nearly straight data is the least energy, not round-off).
       Ties (straight members, of zero energy) go to the most even parametric speed (least int dt / sigma).

    The rule runs compiled (planner/curves/_hermite_member.c, one pass per segment) where the install built it,
    else as numpy array operations (:func:`_least_energy_member`; a C1 fit then takes about twice as long): the same
    members to round-off (tests/test_member_selection.py).

    Why these four: the curve depends on the data alone, not on coordinates, and every isometry of the data
    carries them onto themselves. For data in a plane (p1 - p0, d0, d1 coplanar) they are exactly the four
    planar PH quintic interpolants of Farouki and Neff (1995, "Hermite interpolation by Pythagorean hodograph
    quintics", Math. Comp. 64), so step 2 returns their "good" interpolant, planar in that plane; for
    mirror-symmetric data (p1 = M p0, d1 = -M d0 for a reflection M) they are the four symmetric members, so
    the curve is symmetric; for collinear data (d0, d1, p1 - p0 along one direction) the straight segment is
    one of them, with zero energy. Rotations, translations, uniform scaling and reflections of the data move
    the curve alike (a reflection maps A to n A j, which keeps the scalar part of A0 i A2* zero).

    Why not the global CC minimum (FGMS 2008, this function's rule until issue 12): on planar or symmetric
    data its minimum is generically attained by a mirror pair of non-planar or non-symmetric members, and
    which one is returned is a tie-break; near such data the choice jumps between the pair. The rule here is
    a continuous function of the data away from ties of the four energies (nearly planar data give nearly
    planar curves). It keeps fourth-order approximation of smooth curves (tests/test_curves_symmetry.py: on a
    helix its error is within 1.3 times the CC member's and falls as h^4); it does not reproduce a PH cubic
    whose data are not planar, as the CC rule does.

    Degenerate data: where d1 is antiparallel to d0 every delta qualifies and the axis maximizing
    |<A0 i A2*, p1 - p0>| is used (blended continuously, see :func:`_pure_vector_axis`); with p1 - p0 also
    along d0 the data are invariant under rotations about that line, which no curve leaving it can be, and
    delta = 0 of the internal square roots is returned. A zero end tangent (d0 or d1 = 0: the curve stops there, a
    cusp) leaves two distinct candidates, compared by their curves with the common factor of the cusp divided out
    (see :func:`_reduced_products`); on collinear data the straight one that does not stop on the way is chosen.
    The axis is computed from sigma and b relative to their largest values, so that any ratio of the tangents' and
    the chord's sizes a float holds gives a finite member.
    """
    p0, p1, d0, d1 = (np.asarray(x, dtype=float) for x in (p0, p1, d0, d1))
    n = p0.shape[0]
    rows = np.empty((3, 3, n))  # p1 - p0, d0, d1 on contiguous rows
    np.subtract(p1.T, p0.T, out=rows[0])
    rows[1], rows[2] = d0.T, d1.T
    # the interpolant of the data divided by 4^k is the curve divided by 4^k (A by 2^k, the same angles; exact in
    # floating point): each segment's data are brought to magnitudes of about 1, where the squares in its
    # energies neither overflow nor underflow
    k = np.frexp(np.abs(rows).max(axis=(0, 1)))[1] // 2
    rows *= np.ldexp(1.0, -2 * k)
    a, r = sqrt_rot(rows[1:].transpose(1, 0, 2).reshape(3, 2 * n))
    return hermite_rows(rows[0], rows[1], rows[2], a[:, :n], a[:, n:], r[:n], r[n:], angles, np.ldexp(1.0, k))


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
        ``angles=(phi0, phi2)`` (radians) selects a member explicitly (relative to internal square roots of d0,
        d1: not a geometric choice). The default (None) depends on the data alone: of the four members where
        A0 i A2* is a pure vector, the one of least bending energy (see :func:`batch_hermite` for the rule, its
        literature and why). What users may rely on, each to round-off: rotating, translating, uniformly
        scaling or reflecting the data moves the curve alike; data in a plane give a curve in that plane, the
        planar "good" interpolant (least bending energy of the four planar PH quintic interpolants of Farouki
        and Neff 1995); collinear data (p1 - p0, d0, d1 along one direction) give the straight segment; data
        symmetric about a plane (p1 = M p0, d1 = -M d0) give a curve symmetric about it.
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
