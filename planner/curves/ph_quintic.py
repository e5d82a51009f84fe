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

# ---------------------------------------------------------------------------------------------
# C1 Hermite interpolation (Farouki's family with two free angles)
# ---------------------------------------------------------------------------------------------

#: Weight of the fallback axis in :func:`_pure_vector_axis` (relative, squared): it decides the axis only where
#: the end tangents are antiparallel to about 1e-6 (|sigma| below about 1e-6 |a0| |a2|).
_AXIS_FALLBACK = 1e-12
#: Composite Gauss-Legendre rule of the bending energy of the four candidates (see _least_energy_member): nodes
#: on each of the pieces of [0, 1]. The energy of a candidate near a cusp is a sharp peak; on 5e4 rough random
#: planar data 8 x 8 nodes rank the candidates as 64 x 16 nodes do wherever their energies differ by 1e-3
#: (6 x 8 too, 4 x 8 not: 3 differ).
_GL_NODES, _GL_PIECES = 8, 8
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


def _pure_vector_axis(Sc, Ss, sc, ss, lam, dp):
    """(cos, sin) (N,) of the delta = phi2 - phi0 (defined up to pi) at which A0 i A2* is a pure vector.

    The quaternion a0 i (a2 e^{i delta})* = (sc cos + ss sin) + S(delta) has the scalar part sigma.z with
    sigma = (sc, ss), z = (cos delta, sin delta): it vanishes on the axis z = +-sigma_perp. Where the end
    tangents are antiparallel sigma = 0 and every delta qualifies; there the axis maximizing |<S(delta), dp>|
    (b = (<Sc, dp>, <Ss, dp>)) decides. Both axes are blended sign-free, on doubled angles (an axis z ~ -z
    is the point (x^2 - y^2, 2 x y)), the second with the weight _AXIS_FALLBACK, so that the result is a
    continuous function of the data wherever the blend is nonzero. Both axes are carried onto themselves by
    every isometry of the data (rotations; the reflections that fix planar data or map mirror-symmetric data
    onto their reversal), so their blend is too. lam = |a0|^2 |a2|^2, dp = p1 - p0 (3, N). Call under
    np.errstate(divide="ignore", invalid="ignore").
    """
    bc, bs = _dot(Sc, dp), _dot(Ss, dp)
    w = _AXIS_FALLBACK / (lam * _dot(dp, dp))  # the caller ignores division by zero (errstate)
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
    return np.where(ok, x / n, 1.0), np.where(ok, y / n, 0.0)


def _member(a0, a2d, Q, c0, s0) -> np.ndarray:
    """A (3, 4, N) of the member A0 = a0 e^{i phi0}, A2 = a2d e^{i phi0}, A1 = -(3/4)(A0 + A2) + Q / 4
    (Farouki's solution of the end-point condition), c0, s0 = cos, sin phi0."""
    A = np.empty((3,) + a0.shape)
    _times_e_i(np.stack((a0, a2d), axis=1), c0, s0, A[::2].transpose(1, 0, 2))  # A0 and A2 in one pass
    np.multiply(A[0] + A[2], -0.75, out=A[1])
    A[1] += 0.25 * Q
    return A


def _gauss_rule(nodes: int, pieces: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Weights w (K,) of the composite Gauss-Legendre rule on [0, 1] (``pieces`` equal pieces, ``nodes`` each) and
    B (K, 6): the Bernstein basis of A(t) = b0 A0 + b1 A1 + b2 A2 and its derivative (b0, b1, b2, b0', b1', b2')
    at the K nodes."""
    x, wx = np.polynomial.legendre.leggauss(nodes)
    t = ((0.5 * (x + 1.0))[None] + np.arange(pieces)[:, None]).ravel() / pieces
    w = np.tile(wx, pieces) / (2.0 * pieces)
    B = np.stack(((1 - t) ** 2, 2 * t * (1 - t), t * t, -2 * (1 - t), 2 - 4 * t, 2 * t), axis=1)
    return w, B


_FULL_RULE = _gauss_rule(_GL_NODES, _GL_PIECES)
#: The screening rule of _least_energy_member (2 x 4 nodes): a candidate whose estimate is below 1 / _SCREEN of
#: the others' is taken without the full rule (on 1e5 rough random planar data: no difference from the full
#: rule; a 3-node rule with a factor 3 differed on 1 %).
_SCREEN_RULE = _gauss_rule(4, 2)
_SCREEN = 10.0
#: Weight of the speed-evenness term that breaks ties of the bending energy (see _least_energy_member): far
#: below the round-off of any curved member's energy, far above a straight member's (round-off squared).
_TIE = 1e-15


#: Two nodes of the screening rule (t = 0.17, 0.83, where the other candidates' loops or near-cusps lie) with
#: their weights: partial sums of an estimate's nonnegative terms, lower bounds of it.
_SCREEN_BOUND = (_SCREEN_RULE[0][[1, 6]], _SCREEN_RULE[1][[1, 6]])


def _least_energy_member(dp, base, a0, a2, r0, r1, root_scale=None) -> np.ndarray:
    """A (N, 3, 4) of the default member (see :func:`batch_hermite`), times ``root_scale`` (N,) if given: of the
    four members with A0 i A2* a pure vector, the one of least bending energy.

    The candidates are delta in {delta0, delta0 + pi} (``_pure_vector_axis``) and, for each, phi0 at the maximum
    of <A0 + A2, Q> and phi0 + pi. Their energies E = int kappa^2 ds = 4 int (W_j^2 + W_k^2) / |A|^6 dt with
    W = A* A' (r' = A i A*, sigma = |A|^2, r'' = 2 vec(A' i A*): kappa^2 sigma = (|r''|^2 - sigma'^2) / sigma^3
    = 4 (|A|^2 |A'|^2 - <A, A'>^2 - <A i, A'>^2) / |A|^6, and |A|^2 |A'|^2 = |W|^2 with W's scalar and i parts
    <A, A'> and <A i, A'>, so the difference is W_j^2 + W_k^2 without cancellation: a straight member gets 0
    to round-off squared) by Gauss rules on A(t), A'(t). The rule: a coarse rule (_SCREEN_RULE, 2 x 4 nodes)
    screens them; where one candidate's estimate is below 1 / _SCREEN of the other three's (smooth data: the
    others have cusps or loops) it is taken; elsewhere the composite rule _FULL_RULE (8 x 8 nodes) decides among
    the candidates within _SCREEN of the best estimate. A cusp at a node counts as infinite energy. Ties of the
    energy (straight members: the segment itself and the same line with a stop, all of zero energy) go to the
    most even parametric speed: _TIE int (sigma' / sigma)^2 dt / (|d0| + |d1|) joins the energy (a stop makes
    it large; the CC measure |A0 - 2 A1 + A2|^2, the tie-break before, preferred a member with a stop, whose
    tangent is undefined there and whose round-off wiggle has a curvature peak).

    Computed by the compiled kernel of :mod:`planner.curves.hermite_member`; tests/test_member_selection.py
    checks it against the rule as first written in numpy (which lost the straight members' zero energy to
    cancellation, so that its choice on near-straight segments rested on round-off).
    """
    from planner.curves import hermite_member as hm  # numba: imported when first needed

    n = dp.shape[1]
    X = np.empty((hm.X_ROWS, n))
    X[hm.X_DP:hm.X_DP + 3], X[hm.X_BASE:hm.X_BASE + 3] = dp, base
    X[hm.X_A0:hm.X_A0 + 4], X[hm.X_A2:hm.X_A2 + 4] = a0, a2
    X[hm.X_R0], X[hm.X_R1] = r0, r1
    out = np.empty((n, 3, 4))
    scale = np.ones(n) if root_scale is None else np.ascontiguousarray(root_scale, dtype=float)
    hm.least_energy_members(X, scale, _AXIS_FALLBACK, _TIE, _SCREEN, _SCREEN_RULE, _SCREEN_BOUND, _FULL_RULE, out)
    return out


def hermite_rows(dp, d0, d1, a0, a2, r0, r1, angles=None, root_scale=None) -> np.ndarray:
    """batch_hermite on component rows: dp = p1 - p0, d0, d1 (3, N), a0, a2 = sqrt_rot(d0), sqrt_rot(d1)
    (4, N) and r0, r1 = |d0|, |d1|; returns A (N, 3, 4), multiplied by ``root_scale`` (N,) if given (the
    interpolant of data scaled by h is h times the curve, sqrt(h) times A, with the same free angles)."""
    n = dp.shape[1]
    base = 120.0 * dp - 15.0 * (d0 + d1)  # Farouki: alpha = base + 5 (A0 i A2* + A2 i A0*)
    if angles is None:
        return _least_energy_member(dp, base, a0, a2, r0, r1, root_scale)
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
       "The elastic bending energy of Pythagorean-hodograph curves", CAGD 13; Gauss-Legendre quadrature);
       between members of equal energy (straight ones), the one of most even parametric speed.

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
    delta = 0 of the internal square roots is returned.
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
