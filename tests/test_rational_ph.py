"""Spatial rational PH curves in dual form (seed dual-rational-ph-curves.txt): examples and properties."""

from functools import cache

import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.polynomial import polynomial as P
from scipy.spatial.transform import Rotation

from planner.curves.rational_ph import (
    DualFormError,
    RationalPH,
    SingularParameterError,
    poly_gcd,
    stack,
    vder,
    wedge,
)
from planner.curves.rational_ph_families import (
    class3,
    class3_a00,
    class3_point_form,
    class3_quaternion,
    class3_v_R,
    class4,
    class5,
    class6,
)

t = sp.symbols("t", real=True)
R_ = sp.Rational


# -- an exact reference implementation (sympy, test-only) --------------------------------------------
def _qmul(p, q):
    p0, p1, p2, p3 = p
    q0, q1, q2, q3 = q
    return [
        p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
        p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
        p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
        p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0,
    ]


def sym_dual(A, f, g=1):
    """h, v, theta (monic gcd), v_R, L, P (wedge) for symbolic A (list of 4 polynomials in t)."""
    h = sp.Matrix([sp.expand(x) for x in _qmul(_qmul(A, [0, 1, 0, 0]), [A[0], -A[1], -A[2], -A[3]])[1:]])
    v = h.cross(h.diff(t)).applyfunc(sp.expand)
    theta = sp.Poly(sp.gcd_list(list(v)), t).monic().as_expr()
    vR = v.applyfunc(lambda x: sp.cancel(x / theta))
    L = [-f] + [sp.expand(g * x) for x in vR]
    M = sp.Matrix([[x, sp.diff(x, t), sp.diff(x, t, 2)] for x in L])
    Pw = [sp.expand((-1) ** (i + 1) * M.extract([j for j in range(4) if j != i], [0, 1, 2]).det()) for i in range(4)]
    return h, v, theta, vR, L, Pw


def sym_curve(Pw):
    return sp.Matrix([sp.cancel(Pw[i] / Pw[0]) for i in (1, 2, 3)])


def is_square_of_rational(expr):
    """True iff expr (a rational function of t) is the square of a rational function over R."""
    num, den = sp.fraction(sp.factor(sp.together(expr)))
    for part in (num, den):
        c, factors = sp.factor_list(part, t)
        if c < 0 or any(m % 2 for _, m in factors):
            return False
    return True


def coeffs(expr, n=None):
    c = [float(x) for x in sp.Poly(sp.expand(expr), t).all_coeffs()[::-1]]
    return np.pad(c, (0, 0 if n is None else n - len(c)))


def same_up_to_scale(a, b, rtol=1e-10):
    """Arrays equal up to one nonzero scalar factor; returns the factor (a ~ k b)."""
    a, b = np.ravel(a), np.ravel(b)
    k = (a @ b) / (b @ b)
    assert np.abs(a - k * b).max() <= rtol * np.abs(a).max(), (a, b)
    return k


def curve_scale(c: RationalPH, r_expr, ts):
    """The uniform scale k with c.points = k r_expr on ts (asserts it exists)."""
    ref = np.array([[float(x.subs(t, ti)) for x in r_expr] for ti in ts])
    return same_up_to_scale(c.points(ts), ref)


def A_of(c):
    return [sum(sp.nsimplify(c[j][i]) * t**j for j in range(len(c))) for i in range(4)]


# -- the seed's worked examples -------------------------------------------------------------------
TS = np.array([-1.7, -0.6, 0.3, 0.9, 1.4, 2.2])


@pytest.mark.parametrize(
    "a00, r_expr",
    [
        (
            R_(-5, 4),
            sp.Matrix([5 * t * (4 * t**2 - 11), 8 * t * (12 * t - 5), 16 * t * (3 * t + 5)]) / (-240 * (4 * t**2 + 5)),
        ),
        (-1, sp.Matrix([t * (t**2 - 4), 2 * t * (3 * t - 1), t * (3 * t + 4)]) / (-60 * (t**2 + 1))),
    ],
)
def test_class3_examples_eq45(a00, r_expr):
    """f = t^3, R = I, a10 = 0, a11 = 3, a20 = 2, a30 = 1, a00 = -5/4 or -1 (eq. 45)."""
    branch = -1 if a00 == R_(-5, 4) else 1
    assert np.isclose(class3_a00(0, 3, 2, 1, branch), float(a00))
    c = class3(0, 3, 2, 1, branch)
    assert c.curve_class == 3 and c.degree == 3
    k = curve_scale(c, r_expr, TS)
    assert np.isclose(k, 1.0)  # with the monic-theta convention the seed's constants come out exactly
    rp = r_expr.diff(t)
    assert is_square_of_rational(rp.dot(rp))  # PH: |r'| is rational
    # the curve's own data: v_R and P of Theorem 7 in closed form
    same_up_to_scale(c.v_R, class3_v_R(0, 3, 2, 1, branch))
    same_up_to_scale(np.pad(c.P, ((0, 0), (0, 4 - c.P.shape[1]))), class3_point_form(0, 3, 2, 1, branch))


def test_class4_example():
    """A = (t^2+2t+2, (-2t-2, -2t-2, 2t+2)), f = t^3: L = (-t^3; 16(t+1)^2, t^4, -(t+2)^4)."""
    A = [[2, -2, -2, 2], [2, -2, -2, 2], [1, 0, 0, 0]]
    c = RationalPH.from_dual(A, [0, 0, 0, 1])
    assert c.curve_class == 4
    same_up_to_scale(c.v_R, stack([coeffs(16 * (t + 1) ** 2), coeffs(t**4), coeffs(-((t + 2) ** 4))]))
    np.testing.assert_allclose(c.theta, [0, 2, 1], atol=1e-12)  # theta = t (t + 2) = nu_1 / 4 (eq. 43)
    L_seed = [-(t**3), 16 * (t + 1) ** 2, t**4, -((t + 2) ** 4)]
    M = sp.Matrix([[x, sp.diff(x, t), sp.diff(x, t, 2)] for x in L_seed])
    Pw = [sp.factor((-1) ** (i + 1) * M.extract([j for j in range(4) if j != i], [0, 1, 2]).det()) for i in range(4)]
    r_L = sym_curve(Pw)
    assert np.isclose(curve_scale(c, r_L, TS), 0.25)  # our v_R is 4 times the seed's
    # The seed's printed P: its curve is -1/2 times the curve of its own L, and its components share t^2,
    # so the curve has degree 4 (as ours), not 6.
    P_seed = [
        2048 * t**3 * (t + 2) ** 3,
        192 * t**4 * (t + 2) ** 2,
        128 * t**2 * (t + 2) ** 2 * (t**2 + 2 * t - 6),
        128 * t**4 * (t**2 + 6 * t + 6),
    ]
    r_P = sym_curve(P_seed)
    assert all(sp.simplify(a / b) == R_(-1, 2) for a, b in zip(r_P, r_L, strict=True))
    assert sp.degree(sp.gcd_list(P_seed), t) == 2 and c.degree == 4
    rp = r_L.diff(t)
    assert is_square_of_rational(rp.dot(rp))
    # psi = -3 / (32 t^2 (t+2)^4)
    ts = np.array([-3.0, -1.0, 0.5, 1.5])
    np.testing.assert_allclose(c.psi(ts), -3 / (32 * ts**2 * (ts + 2) ** 4), rtol=1e-12)


def test_class5_example():
    """A = (t^2 - t, (-t, -2, 2)), f = t^3 (Theorem 5 example, eq. 41)."""
    c = RationalPH.from_dual([[0, 0, -2, 2], [-1, -1, 0, 0], [1, 0, 0, 0]], [0, 0, 0, 1])
    assert c.curve_class == 5 and c.degree == 9
    np.testing.assert_allclose(c.h, stack([coeffs((t - 2) * (t**3 + 2 * t + 4)), coeffs(4 * t**2), coeffs(4 * (t - 2) * t)]))
    vR = stack([coeffs(32 * t**2), coeffs(8 * (t - 2) ** 2 * (t**3 - 2)), coeffs(-8 * t * (t**4 - t**3 + 8))])
    np.testing.assert_allclose(c.v_R, vR, atol=1e-9)  # equal, not only up to scale (gcd 1)
    P_seed = [
        -4096 * (-3 * t**4 + 2 * t**3 + 8) ** 2,
        -128 * t * (3 * t**8 - 6 * t**6 + 2 * t**5 - 48 * t**4 + 48 * t**3 - 16 * t**2 + 192),
        512 * t**3 * (3 * t**4 - t**3 + 8),
        512 * t**2 * (3 * t**5 - 4 * t**4 + 8 * t - 24),
    ]
    same_up_to_scale(c.P, stack([coeffs(x, 10) for x in P_seed]))
    psi = 3 * ((3 * t**5 + 96 * t - 32) * t**3 + 64) / (32 * (t**3 * (3 * t - 2) - 8) ** 3)
    np.testing.assert_allclose(c.psi(TS), [float(psi.subs(t, x)) for x in TS], rtol=1e-11)
    r = sym_curve(P_seed)
    rp = r.diff(t)
    assert is_square_of_rational(rp.dot(rp))


@cache
def _class6_symbolic():
    A = [sp.Integer(1), t + t**2, -(t**2), t + t**2]
    return sym_dual(A, 1 + t**3 - t**6)


def test_class6_example():
    """A = 1 + (i + k) t + (i - j + k) t^2, f = 1 + t^3 - t^6 (Theorem 3 example)."""
    c = RationalPH.from_dual([[1, 0, 0, 0], [0, 1, 0, 1], [0, 1, -1, 1]], [1, 0, 0, 1, 0, 0, -1])
    assert c.curve_class == 6 and c.degree == 12
    h, v, theta, vR, L, Pw = _class6_symbolic()
    assert theta == 1
    np.testing.assert_allclose(c.v, stack([coeffs(x, 7) for x in v]), atol=1e-12)
    np.testing.assert_allclose(c.v[0], coeffs(4 * t**2 * (t**4 + 6 * t**3 + 7 * t**2 + 4 * t + 2), 7), atol=1e-12)
    same_up_to_scale(c.P, stack([coeffs(x, 13) for x in Pw]))
    lam_t = 2 * t**6 + 3 * t**5 - 12 * t**3 - 9 * t**2 - 3 * t - 1
    num = 22 * t**12 + 42 * t**11 + 6 * t**10 + 559 * t**9 + 1152 * t**8 + 1035 * t**7 + 423 * t**6
    num += 81 * t**5 + 189 * t**4 + 547 * t**3 + 363 * t**2 + 96 * t + 5
    psi = R_(3, 8) * num / lam_t**3
    ts = np.array([-2.5, -1.0, 0.2, 0.8, 2.5])
    np.testing.assert_allclose(c.psi(ts), [float(psi.subs(t, x)) for x in ts], rtol=1e-11)
    sing = c.singular_points()
    np.testing.assert_allclose(sing.zeros, [-3.13475, -0.0676759], atol=1e-5)
    np.testing.assert_allclose(sing.poles, [-0.59708, 1.70123], atol=1e-5)
    assert sing.zero_at_infinity
    with pytest.raises(SingularParameterError, match="pole"):
        c.points([0.0, sing.poles[0]])


def test_class6_is_ph_symbolically():
    """r' = psi h exactly: (P0 Pv' - P0' Pv) x h = 0 identically and h . h = rho^2, so |r'| is rational;
    and psi of eq. (18) equals r' . h / rho^2 (checked exactly at a rational parameter)."""
    h, v, theta, vR, L, Pw = _class6_symbolic()
    P0, Pv = Pw[0], sp.Matrix(Pw[1:])
    num = Pv.diff(t) * P0 - Pv * sp.diff(P0, t)  # r' = num / P0^2
    assert num.cross(h).applyfunc(sp.expand) == sp.zeros(3, 1)
    A = [sp.Integer(1), t + t**2, -(t**2), t + t**2]
    rho = sp.expand(sum(a**2 for a in A))
    assert sp.expand(h.dot(h) - rho**2) == 0
    f = 1 + t**3 - t**6
    h1, h2, h3 = h.diff(t), h.diff(t, 2), h.diff(t, 3)
    lam = sp.Matrix.hstack(h, h1, h2).det()
    D1 = sp.Matrix.hstack(h, h2, h3).det()
    D2 = sp.Matrix.hstack(h1, h2, h3).det()
    psi = sp.diff(f * D1 / lam**2 + sp.diff(sp.diff(f, t) / lam, t), t) + f * D2 / lam**2  # eq. (18)
    x0 = R_(3, 10)
    lhs = psi.subs(t, x0)
    rhs = (num.dot(h) / (P0**2 * rho**2)).subs(t, x0)
    assert sp.nsimplify(lhs - rhs) == 0


# -- generic properties on random family members ---------------------------------------------------
def _well_conditioned(c: RationalPH, ts, kappa_max=1e4):
    """Parameters where P0 and lambda are far from their (real or nearly real complex) roots:
    sum |c_k t^k| / |p(t)| <= kappa_max (near such roots eq. (18) and P lose digits to cancellation)."""
    keep = np.ones(ts.shape, bool)
    for p in (c.P[0], c.lam):
        keep &= P.polyval(np.abs(ts), np.abs(p)) < kappa_max * np.abs(P.polyval(ts, p))
        roots = P.polyroots(p)
        keep &= (np.abs(ts[:, None] - roots[None, :]) > 0.05).all(axis=1)  # e.g. t = 0 next to a pole
    return ts[keep]


def _check_ph(c: RationalPH, rtol=1e-8):
    """r' from P (quotient rule) against psi R h of eq. (18), |r'| = |psi| rho, unit tangent, and the
    osculating-plane identities. Eq. (18) sums terms that cancel: members close to degenerate (A nearly
    sharing a factor) lose digits there, hence the looser rtol the hypothesis tests use."""
    ts = _well_conditioned(c, np.linspace(-1.5, 1.5, 31))
    if ts.size == 0:
        return
    d = c.derivative(ts)
    hd = c.hodograph(ts)
    scale = np.linalg.norm(d, axis=1)
    assert (np.linalg.norm(d - hd, axis=1) <= rtol * scale + 1e-12 * scale.max()).all()  # r' = psi R h
    np.testing.assert_allclose(c.speed(ts), scale, rtol=rtol, atol=1e-12 * scale.max())  # |r'| = |psi| rho
    tan = c.tangent(ts)
    np.testing.assert_allclose(np.linalg.norm(tan, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(tan * scale[:, None], d, atol=rtol * scale.max())
    # osculating planes: L^(l) . P = 0 for l = 0, 1, 2 (seed eq. 6)
    Pt = np.stack([P.polyval(ts, row) for row in c.P], axis=1)
    for ell in range(3):
        Lt = np.stack([P.polyval(ts, row) for row in vder(c.L, ell)], axis=1)
        mag = np.einsum("ni,ni->n", np.abs(Lt), np.abs(Pt))
        assert (np.abs(np.einsum("ni,ni->n", Lt, Pt)) <= 1e-9 * mag + 1e-12 * mag.max()).all()


param = st.floats(-2, 2, allow_nan=False, allow_subnormal=False)
quat = st.tuples(param, param, param, param).map(np.array)


@settings(max_examples=15, deadline=None)
@given(param, st.floats(2.0, 3.5), st.floats(-0.5, 0.5), st.floats(-0.5, 0.5), st.sampled_from([1, -1]),
       st.lists(param, min_size=4, max_size=4), st.integers(0, 2**31))
def test_random_class3(a10, a11, a20, a30, branch, f, seed):
    if a20**2 + a30**2 < 1e-2 or max(abs(x) for x in f) < 0.1:
        return
    R = Rotation.random(random_state=seed).as_matrix()
    try:
        c = class3(a10, a11, a20, a30, branch, f=f, R=R)
    except DualFormError as exc:  # f in the span of the components of v_R: all planes through a point
        assert "degenerate dual form" in str(exc)
        return
    assert c.curve_class == 3 and c.degree == 3
    same_up_to_scale(class3(a10, a11, a20, a30, branch).v_R, class3_v_R(a10, a11, a20, a30, branch), rtol=1e-8)
    _check_ph(c, rtol=1e-6)


@settings(max_examples=15, deadline=None)
@given(quat, param, param, st.lists(param, min_size=5, max_size=5), st.integers(0, 2**31))
def test_random_class4(A1, c0, c1, f, seed):
    if abs(A1[1]) < 0.2 or A1[2] ** 2 + A1[3] ** 2 < 0.04 or abs(f[4]) < 0.1:
        return
    if np.linalg.norm(c0 * np.eye(4)[0] + c1 * A1) < 0.1:
        return  # A0 ~ 0: A nearly has the common factor t (degenerate, excluded by the theorem)
    try:
        c = class4(A1, c0, c1, f=f, R=Rotation.random(random_state=seed).as_matrix())
    except DualFormError as exc:  # f in the span of v_R's components (a point) or A with a common factor
        assert "degenerate dual form" in str(exc) or "share the factor" in str(exc)
        return
    assert c.curve_class == 4 and c.degree <= 6
    assert len(c.theta) == 3  # the quadratic divisor nu_1 of Theorem 6
    _check_ph(c, rtol=1e-6)


@settings(max_examples=15, deadline=None)
@given(quat, param, param, st.lists(param, min_size=6, max_size=6), st.integers(0, 2**31))
def test_random_class5(A0, a01, a11, f, seed):
    if A0[2] ** 2 + A0[3] ** 2 < 0.04 or abs(a11) < 0.2 or abs(f[5]) < 0.1:
        return  # also keeps A0 away from 0 (A = t (A1 + t) has a common factor)
    try:
        c = class5(A0, a01, a11, f=f, R=Rotation.random(random_state=seed).as_matrix())
    except DualFormError as exc:
        assert "degenerate dual form" in str(exc) or "share the factor" in str(exc)
        return
    assert c.curve_class == 5 and c.degree <= 9
    _check_ph(c, rtol=1e-6)


@settings(max_examples=15, deadline=None)
@given(quat, quat, quat, st.lists(param, min_size=7, max_size=7), st.integers(0, 2**31))
def test_random_class6(A0, A1, A2, f, seed):
    if np.linalg.norm(A2) < 0.3 or np.linalg.norm(A1) < 0.3 or abs(f[6]) < 0.1:
        return
    try:
        c = class6(A0, A1, A2, f=f, R=Rotation.random(random_state=seed).as_matrix())
    except DualFormError as exc:
        assert "degenerate dual form" in str(exc) or "share the factor" in str(exc) or "vanishes" in str(exc)
        return
    assert c.degree <= 12 and c.curve_class <= 6
    if c.lam.size < 7 or abs(c.lam[-1]) < 1e-3 * np.abs(c.lam).max():
        return  # lambda nearly drops degree (roots near infinity): a near-degenerate A, not tested here
    _check_ph(c, rtol=1e-5)  # eq. (18) cancels near almost-real complex poles (seen: 7e-7 relative)


def test_generic_members_have_the_theorems_class_and_degree():
    """Class m and degree 3 (m - 2) (Theorems 5-7, class 6) for generic parameters."""
    rng = np.random.default_rng(2024)
    for _ in range(5):
        c3 = class3(rng.normal(), rng.uniform(2, 3), *rng.uniform(-0.5, 0.5, 2), f=rng.normal(size=4))
        c4 = class4(rng.normal(size=4), *rng.normal(size=2), f=rng.normal(size=5))
        c5 = class5(rng.normal(size=4), *rng.normal(size=2), f=rng.normal(size=6))
        c6 = class6(*rng.normal(size=(3, 4)), f=rng.normal(size=7))
        for m, c in ((3, c3), (4, c4), (5, c5), (6, c6)):
            assert (c.curve_class, c.degree) == (m, 3 * (m - 2))
            _check_ph(c)


def test_rotation_R_rotates_the_curve():
    A = [[0.3, -0.2, 1.0, 0.4], [0.5, 1.0, -0.3, 0.2], [1, 0, 0, 0]]
    f = [0.2, -1.0, 0.5, 0.3, 0.1, 0.0, -0.7]
    R = Rotation.from_rotvec([0.3, -1.1, 0.4]).as_matrix()
    ts = np.linspace(-1, 1, 9)
    a, b = RationalPH.from_dual(A, f), RationalPH.from_dual(A, f, R=R)
    np.testing.assert_allclose(b.points(ts), a.points(ts) @ R.T, rtol=1e-10, atol=1e-12)


def test_lemma2_constant_quaternion_rotates_and_scales():
    """A -> Q A gives r_Q = R(Q) r / |Q|^4 (Lemma 2)."""
    from planner.curves.rational_ph import qpoly_mul
    from planner.rotations import quaternion_to_matrix

    A = np.array([[0.3, -0.2, 1.0, 0.4], [0.5, 1.0, -0.3, 0.2], [1, 0, 0, 0]])
    Q = np.array([0.7, -0.4, 1.2, 0.5])
    f = [1.0, 0.0, 0.5, -1.0]
    ts = np.linspace(-1, 1, 9)
    a = RationalPH.from_dual(A, f)
    b = RationalPH.from_dual(qpoly_mul(Q[None, :], A), f)
    expected = a.points(ts) @ quaternion_to_matrix(Q).T / np.dot(Q, Q) ** 2
    np.testing.assert_allclose(b.points(ts), expected, rtol=1e-9, atol=1e-12)


def test_theorem4_linear_A_gives_a_reparametrized_cubic():
    """Linear A, cubic f, linear g: the denominator is g^3 (mapped to infinity by eq. 32)."""
    A = [[0.4, 1.0, 0.7, -0.3], [1, 0, 0, 0]]
    g = [0.5, 1.5]
    c = RationalPH.from_dual(A, [0.3, -1.0, 0.2, 0.8], g=g)
    assert c.curve_class == 3 and c.degree == 3
    same_up_to_scale(c.P[0], P.polypow(g, 3))
    _check_ph(c)


# -- polynomial gcd ---------------------------------------------------------------------------------
def test_poly_gcd():
    a = P.polymul([1, 1], [2, 0, 1])  # (t + 1)(t^2 + 2)
    b = P.polymul(P.polymul([1, 1], [1, 1]), [-3, 1])  # (t + 1)^2 (t - 3)
    c = P.polymul([1, 1], [0, 0, 0, 5])  # 5 t^3 (t + 1)
    g, q = poly_gcd([a, b, np.zeros(1), c])
    np.testing.assert_allclose(g, [1, 1], atol=1e-12)
    np.testing.assert_allclose(q[0], [2, 0, 1], atol=1e-12)
    np.testing.assert_allclose(q[2], [0], atol=0)
    g, _ = poly_gcd([P.polymul([1, 1], [1, 1]), P.polymul(P.polymul([1, 1], [1, 1]), [2, 1])])
    np.testing.assert_allclose(g, [1, 2, 1], atol=1e-9)  # a repeated factor
    g, _ = poly_gcd([[1, 2, 3], [4, 0, 1, 1]])
    np.testing.assert_allclose(g, [1.0])
    with pytest.raises(DualFormError, match="zero polynomials"):
        poly_gcd([np.zeros(3)])


def test_wedge_is_orthogonal_to_its_arguments():
    rng = np.random.default_rng(3)
    L = rng.normal(size=(4, 5))
    W = wedge(L)
    for ell in range(3):
        d = np.pad(vder(L, ell), ((0, 0), (0, 5)))
        s = sum(P.polymul(d[i], W[i]) for i in range(4))
        assert np.abs(s).max() <= 1e-10 * np.abs(W).max()


# -- bad input -------------------------------------------------------------------------------------
GOOD_A = [[0.3, -0.2, 1.0, 0.4], [0.5, 1.0, -0.3, 0.2], [1, 0, 0, 0]]


@pytest.mark.parametrize(
    "A, f, kw, msg",
    [
        ([[1, 0, 0, 0]], [1], {}, "degree >= 1"),
        ([[1, 0, 0]], [1], {}, r"shape \(k\+1, 4\)"),
        ([[1, 0, 0, np.nan], [0, 1, 0, 0]], [1], {}, "non-finite coefficient A"),
        ([[1, 0, 0, 0], [0, 0, 0, 1]], [1, 1], {}, "det\\(h, h', h''\\) vanishes"),
        ([[1, 0, 0, 0], [1, 1, 0, 0], [0, 1, 0, 0]], [1], {}, "share the factor"),  # (1 + t)(1 + t i)
        (GOOD_A, [0, 0, 0], {}, "f is the zero polynomial"),
        (GOOD_A, [1, np.inf], {}, "f has a non-finite coefficient at index 1"),
        (GOOD_A, [1], {"g": [0.0]}, "g is the zero polynomial"),
        (GOOD_A, [1], {"R": np.diag([1.0, 1.0, -1.0])}, "rotation matrix"),
        (GOOD_A, [1], {"R": np.eye(2)}, "3x3"),
        (GOOD_A, "abc", {}, "f must be"),
    ],
)
def test_bad_dual_data(A, f, kw, msg):
    with pytest.raises(DualFormError, match=msg):
        RationalPH.from_dual(A, f, **kw)


def test_bad_family_parameters():
    with pytest.raises(DualFormError, match=r"a11\^4 >= 16"):
        class3_quaternion(0.0, 1.0, 2.0, 1.0)
    with pytest.raises(DualFormError, match="branch"):
        class3_a00(0.0, 3.0, 2.0, 1.0, branch=0)
    with pytest.raises(DualFormError, match="a11 != 0"):
        class4([1.0, 0.0, 1.0, 1.0], 0.5, 1.0)
    with pytest.raises(DualFormError, match="a20"):
        class5([1.0, 2.0, 0.0, 0.0], 0.3, 1.0)


def test_singular_parameters_raise():
    c = RationalPH.from_dual([[2, -2, -2, 2], [2, -2, -2, 2], [1, 0, 0, 0]], [0, 0, 0, 1])  # P0 ~ t (t+2)^3
    for bad in (0.0, -2.0):
        with pytest.raises(SingularParameterError, match=f"t\\[1\\] = {bad!r} is a pole"):
            c.points([1.0, bad])
    with pytest.raises(SingularParameterError, match="not finite"):
        c.points([np.nan])
    assert np.isfinite(c.points([-2.0 + 1e-3, 1e-3])).all()
