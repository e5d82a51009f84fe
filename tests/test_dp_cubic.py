"""DP cubics (seed dp-ph-cubic-construction.md, section 2) and the derived PH condition on the DP polygon."""

import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

from planner import bernstein
from planner.curves.dp_cubic import (
    DPCubic,
    NotPHError,
    dp_basis,
    ph_condition,
    ph_polygon_residuals,
    polygon_geometry,
)
from planner.errors import PlannerError

coord = st.floats(-5, 5, allow_nan=False)
polygons = st.lists(st.tuples(coord, coord), min_size=4, max_size=4).map(np.array)
cplx = st.tuples(st.floats(-3, 3), st.floats(-3, 3)).map(lambda p: complex(*p))
T = np.linspace(0, 1, 41)


def _random_ph(w0, w1, p0=(0.3, -0.2)):
    return DPCubic.from_preimage(w0, w1, p0)


# -- the basis and the Bezier conversion ---------------------------------------------------------
def test_dp_basis_is_the_seeds_and_a_nonnegative_partition_of_unity():
    t = sp.symbols("t")
    seed = [(1 - t) ** 3, t * (1 - t) * (2 - t), t * (1 - t) * (1 + t), t**3]
    x = np.linspace(0, 1, 13)
    expected = np.array([[float(b.subs(t, xi)) for b in seed] for xi in x])
    np.testing.assert_allclose(dp_basis(x), expected, atol=1e-15)
    np.testing.assert_allclose(dp_basis(x).sum(axis=1), 1.0, atol=1e-15)
    assert (dp_basis(x) >= 0).all()


def test_bezier_conversion_is_exact_symbolically():
    """D_1 = (2/3) B_1 + (1/3) B_2 and D_2 = (1/3) B_1 + (2/3) B_2 (shared/DESIGN.md)."""
    t = sp.symbols("t")
    B1, B2 = 3 * t * (1 - t) ** 2, 3 * t**2 * (1 - t)
    assert sp.expand(t * (1 - t) * (2 - t) - (sp.Rational(2, 3) * B1 + sp.Rational(1, 3) * B2)) == 0
    assert sp.expand(t * (1 - t) * (1 + t) - (sp.Rational(1, 3) * B1 + sp.Rational(2, 3) * B2)) == 0


@settings(max_examples=40, deadline=None)
@given(polygons)
def test_points_agree_with_the_bezier_form_and_round_trip(p):
    c = DPCubic(p)
    np.testing.assert_allclose(c.points(T), bernstein.evaluate(c.to_bezier(), T), atol=1e-12)
    np.testing.assert_allclose(DPCubic.from_bezier(c.to_bezier()).control_points, p, atol=1e-12)
    np.testing.assert_allclose(
        c.derivative(T), bernstein.evaluate(c.hodograph(), T), atol=1e-11 * (1 + np.abs(p).max())
    )
    np.testing.assert_allclose(c.points([0.0, 1.0]), p[[0, 3]], atol=1e-14)


def test_end_tangent_is_not_along_the_first_dp_leg():
    """With this basis P'(0) = 3 D0 + D1 (why the seed's tangent-line construction fails)."""
    p = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    c = DPCubic(p)
    np.testing.assert_allclose(c.derivative([0.0])[0], 3 * (p[1] - p[0]) + (p[2] - p[1]), atol=1e-15)


# -- the PH condition: derived, then proven by the PH property itself --------------------------------
def test_condition_is_the_bezier_ph_condition_symbolically():
    """3 D0 D2 + D1 (D0 + D2) = 3 (L1 L3 - L2^2) identically, and w^2 legs satisfy it."""
    d0, d1, d2, w0, w1 = sp.symbols("d0 d1 d2 w0 w1")
    L1, L2, L3 = d0 + d1 / 3, d1 / 3, d2 + d1 / 3
    assert sp.expand(3 * d0 * d2 + d1 * (d0 + d2) - 3 * (L1 * L3 - L2**2)) == 0
    legs = {d0: w0 * (w0 - w1) / 3, d1: w0 * w1, d2: w1 * (w1 - w0) / 3}
    assert sp.expand((3 * d0 * d2 + d1 * (d0 + d2)).subs(legs)) == 0


def test_preimage_legs_give_hodograph_w_squared_symbolically():
    t = sp.symbols("t", real=True)
    a0, b0, a1, b1 = sp.symbols("a0 b0 a1 b1", real=True)
    w0, w1 = a0 + sp.I * b0, a1 + sp.I * b1
    legs = [w0 * (w0 - w1) / 3, w0 * w1, w1 * (w1 - w0) / 3]
    p = [0, legs[0], legs[0] + legs[1], legs[0] + legs[1] + legs[2]]
    basis = [(1 - t) ** 3, t * (1 - t) * (2 - t), t * (1 - t) * (1 + t), t**3]
    P = sum(pi * bi for pi, bi in zip(p, basis, strict=True))
    w = w0 * (1 - t) + w1 * t
    assert sp.expand(sp.diff(P, t) - w**2) == 0


@settings(max_examples=60, deadline=None)
@given(cplx, cplx)
def test_random_ph_cubics_satisfy_the_polygon_condition(w0, w1):
    if abs(w0) < 0.05 or abs(w1) < 0.05 or abs(w0 - w1) < 0.05:
        return  # degenerate legs: the scale-free residuals are ill-conditioned there
    c = _random_ph(w0, w1)
    assert c.is_ph()
    assert c.ph_condition_residual() < 1e-12
    assert c.satisfies_ph_condition()
    r1, r2 = ph_polygon_residuals(c.control_points)
    assert abs(r1) < 1e-12 and abs(r2) < 1e-12
    if not c.is_straight(1e-6):
        _, (th1, th2) = polygon_geometry(c.control_points)
        assert th1 * th2 > 0 and abs(th1 + th2) > np.pi - 1e-9  # turns by more than a half turn


@settings(max_examples=60, deadline=None)
@given(cplx, cplx, st.tuples(coord, coord))
def test_random_polygons_satisfying_the_condition_are_ph(d0, d1, p0):
    if abs(d0) < 0.05 or abs(d1) < 0.05:
        return
    s = -(1 / d0 + 3 / d1)  # 1/D0 + 3/D1 + 1/D2 = 0
    if abs(s) < 1e-2 or abs(1 / s) > 100:
        return
    d2 = 1 / s
    z = np.cumsum([complex(*p0), d0, d1, d2])
    c = DPCubic(np.stack((z.real, z.imag), axis=1))
    assert c.ph_residual() < 1e-11
    assert c.satisfies_ph_condition(1e-11)
    np.testing.assert_allclose(c.speed(T), bernstein.evaluate(c.sigma(), T), rtol=1e-10, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(polygons)
def test_condition_and_ph_property_agree_on_random_polygons(p):
    c = DPCubic(p)
    if np.linalg.norm(c.legs, axis=1).min() < 1e-3:
        return
    # consistent with margins (the two residuals scale differently near straight lines)
    assert not (c.is_ph(1e-12) and not c.satisfies_ph_condition(1e-5))
    assert not (c.satisfies_ph_condition(1e-12) and not c.is_ph(1e-5))


def test_generic_polygon_is_not_ph():
    c = DPCubic([[0.0, 0.0], [1.0, 0.2], [2.0, 1.5], [2.5, 3.0]])
    assert c.ph_residual() > 1e-4
    assert not c.satisfies_ph_condition()
    with pytest.raises(NotPHError, match="not of the form"):
        c.preimage()


def test_geometric_form_is_the_complex_condition():
    """(1/D0 + 3/D1 + 1/D2) e^{i phi1} l0 l1 l2 = l1 (l2 cos th1 + l0 cos th2) + 3 l0 l2
    + i l1 (l2 sin th1 - l0 sin th2): the length/angle form is the complex condition."""
    rng = np.random.default_rng(7)
    for _ in range(50):
        p = rng.normal(size=(4, 2))
        (l0, l1, l2), _ = polygon_geometry(p)
        r1, r2 = ph_polygon_residuals(p)
        d0, d1, d2 = (p[1:] - p[:-1]) @ np.array([1, 1j])
        lhs = (1 / d0 + 3 / d1 + 1 / d2) * np.exp(1j * np.angle(d1)) * l0 * l1 * l2
        rhs = r2 * (l0 * l1 + l1 * l2 + l0 * l2) + 1j * r1 * (l0 + l2) * l1
        assert abs(lhs - rhs) <= 1e-12 * (1 + abs(lhs))
        q = (1 / d0 + 3 / d1 + 1 / d2) * d0 * d1 * d2
        assert abs(ph_condition(p) - q) <= 1e-12 * (1 + abs(q))


def test_straight_lines():
    fwd = DPCubic([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [4.0, 4.0]])
    assert fwd.is_straight() and fwd.is_ph() and fwd.satisfies_ph_condition()
    assert fwd.ph_condition_residual() > 1e-3  # PH through case (a), not (b)
    assert np.isclose(fwd.length, 4 * np.sqrt(2))
    back = DPCubic([[0.0, 0.0], [3.0, 0.0], [-2.0, 0.0], [1.0, 0.0]])  # reverses on [0, 1]
    assert back.is_straight() and not back.is_ph() and not back.satisfies_ph_condition()


# -- the seed's statements -------------------------------------------------------------------------
def test_seed_example_polygons_are_not_ph():
    """Section 3 example: D1 = (3/5, 0), D2 = (1/5, sqrt3/5) (printed) or (3/10, 3 sqrt3/10) (eq. 3.3)."""
    s3 = np.sqrt(3)
    for d2 in ([1 / 5, s3 / 5], [3 / 10, 3 * s3 / 10]):
        c = DPCubic([[1, 0], [3 / 5, 0], d2, [1 / 2, s3 / 2]])
        assert c.ph_residual() > 1e-3
        assert not c.satisfies_ph_condition()


def test_seed_condition_is_not_the_ph_condition():
    """The seed: equal angles and 4 |D1 D2|^2 = 9 |D0 D1| |D2 D3| -- wrong both ways."""
    # a polygon satisfying the seed's condition: l0 = 1, l2 = 4, l1 = 3 sqrt(4)/2 = 3, equal angles 1 rad
    th = 1.0
    d = [1.0, 3.0 * np.exp(1j * th), 4.0 * np.exp(2j * th)]
    z = np.cumsum([0.0, *d])
    seed_ok = DPCubic(np.stack((z.real, z.imag), axis=1))
    (l0, l1, l2), (th1, th2) = polygon_geometry(seed_ok.control_points)
    assert np.isclose(th1, th2) and np.isclose(4 * l1**2, 9 * l0 * l2)
    assert seed_ok.ph_residual() > 1e-3
    # a PH cubic violating it
    ph = DPCubic.from_preimage(1.0 + 0.5j, 0.3 - 1.0j)
    (l0, l1, l2), (th1, th2) = polygon_geometry(ph.control_points)
    assert ph.is_ph() and not np.isclose(th1, th2) and not np.isclose(4 * l1**2, 9 * l0 * l2)


# -- arc length ------------------------------------------------------------------------------------
@settings(max_examples=20, deadline=None)
@given(cplx, cplx)
def test_exact_arc_length(w0, w1):
    if abs(w0) + abs(w1) < 0.1:
        return
    c = _random_ph(w0, w1)
    ref, _ = quad(lambda t: c.speed(t)[0], 0, 1, epsabs=1e-13, epsrel=1e-13, limit=200)
    assert abs(c.length - ref) <= 1e-11 * max(ref, 1)
    np.testing.assert_allclose(c.speed(T), bernstein.evaluate(c.sigma(), T), atol=1e-12 * (1 + ref))
    half, _ = quad(lambda t: c.speed(t)[0], 0, 0.5, epsabs=1e-13, epsrel=1e-13, limit=200)
    assert abs(float(c.arc_length(0.5)) - half) <= 1e-11 * max(ref, 1)


# -- bad input -------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "bad, msg",
    [
        (np.zeros((3, 2)), r"shape \(4, 2\)"),
        (np.zeros((4, 3)), r"shape \(4, 2\)"),
        ([[0, 0], [1, np.nan], [2, 0], [3, 0]], "control point 1 is not finite"),
        ([["a", 0]] * 4, "numeric"),
    ],
)
def test_bad_control_points(bad, msg):
    with pytest.raises(PlannerError, match=msg):
        DPCubic(bad)


def test_bad_bezier_points():
    with pytest.raises(PlannerError, match="Bezier control points"):
        DPCubic.from_bezier(np.zeros((5, 2)))
