"""DP-PH G1 Hermite construction (seed section 3) and the DP / DP-PH error (section 4)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planner.curves.dp_cubic import DPCubic
from planner.curves.dp_ph_hermite import (
    HermiteDataError,
    dp_ph_error,
    dp_ph_errors,
    dp_ph_hermite,
    polygon_parameters,
    seed_setting,
)
from planner.errors import NoSolutionError, PlannerError

cplx = st.tuples(st.floats(-3, 3), st.floats(-3, 3)).map(lambda p: complex(*p))
T = np.linspace(0, 1, 201)


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _same_curve(a: DPCubic, b: DPCubic, tol=1e-9):
    scale = 1 + np.abs(b.control_points).max()
    return np.abs(a.control_points - b.control_points).max() <= tol * scale


def _check_solution(c: DPCubic, p0, d0, p3, d3, mode):
    np.testing.assert_allclose(c.points([0.0, 1.0]), [p0, p3], atol=1e-12)
    assert c.is_ph(1e-9)
    if mode == "curve":
        tan = c.tangent([0.0, 1.0])
        # unit tangents to 1e-8: hypothesis found end tangents with a 6e-8 component where the construction's
        # round-off reaches 1e-9 (a0 = -1.895140209778151, a3 = -5.96e-08, dist = 1)
        np.testing.assert_allclose(tan[0], _unit(d0), atol=1e-8)
        np.testing.assert_allclose(tan[1], _unit(d3), atol=1e-8)
    else:
        lam, mu = polygon_parameters(c, d0, d3)
        assert lam > 0 and mu > 0
        p = c.control_points
        np.testing.assert_allclose(p[1], p0 + lam * _unit(d0), atol=1e-12)
        np.testing.assert_allclose(p[2], p3 - mu * _unit(d3), atol=1e-12)


# -- curve mode: completeness and correctness --------------------------------------------------------
@settings(max_examples=80, deadline=None)
@given(cplx, cplx)
def test_every_ph_cubic_is_found_from_its_own_g1_data(w0, w1):
    if abs(w0) < 0.1 or abs(w1) < 0.1 or abs(w0**2 + w0 * w1 + w1**2) < 0.1:
        return
    if abs((w0 * np.conj(w1)).imag) < 0.05 * abs(w0 * w1):
        return  # (nearly) straight: a whole family of lines fits, the uniform one is returned
    c = DPCubic.from_preimage(w0, w1, (0.5, 1.0))
    p0, p3 = c.points([0.0, 1.0])
    d0, d3 = c.derivative([0.0, 1.0])
    sols = dp_ph_hermite(p0, d0, p3, d3)
    assert 1 <= len(sols) <= 2
    for s in sols:
        _check_solution(s, p0, d0, p3, d3, "curve")
    assert any(_same_curve(s, c, 1e-7) for s in sols)
    assert [s.length for s in sols] == sorted(s.length for s in sols)


@settings(max_examples=60, deadline=None)
@given(st.floats(-np.pi, np.pi), st.floats(-np.pi, np.pi), st.floats(0.1, 10))
def test_random_g1_data_curve_mode(a0, a3, dist):
    p0, p3 = np.array([0.2, -0.1]), np.array([0.2 + dist, -0.1])
    d0, d3 = [np.cos(a0), np.sin(a0)], [np.cos(a3), np.sin(a3)]
    try:
        sols = dp_ph_hermite(p0, d0, p3, d3)
    except NoSolutionError:
        # PH cubics have no inflection: tangents strictly on the same side of the chord need one
        assert np.sin(a0) * np.sin(a3) > 0 or abs(a0) > np.pi / 2 or abs(a3) > np.pi / 2
        return
    assert len(sols) <= 2
    for s in sols:
        _check_solution(s, p0, d0, p3, d3, "curve")


def test_s_shaped_data_has_no_ph_cubic():
    with pytest.raises(NoSolutionError, match="inflection"):
        dp_ph_hermite([0, 0], [1, 1], [3, 0], [1, 1])


def test_straight_data_gives_the_line():
    (c,) = dp_ph_hermite([0, 0], [2, 1], [4, 2], [1, 0.5])
    np.testing.assert_allclose(c.points(T), np.outer(T, [4, 2]), atol=1e-14)


def test_symmetric_arc_has_the_predicted_solution():
    """theta = pi/3, rho = 1: Bezier legs 1/2, P' = w^2; the DP points are (3/4, -sqrt3/4), (0, sqrt3/2)."""
    s3 = np.sqrt(3)
    (c,) = dp_ph_hermite(*seed_setting(np.pi / 3, 1.0))
    np.testing.assert_allclose(c.control_points, [[1, 0], [3 / 4, -s3 / 4], [0, s3 / 2], [1 / 2, s3 / 2]], atol=1e-14)
    np.testing.assert_allclose(c.to_bezier()[1:3], [[1 / 2, 0], [1 / 4, s3 / 4]], atol=1e-14)
    assert np.isclose(c.length, 1.25)


# -- polygon mode (the seed's eq. 3.1 literally) ---------------------------------------------------
@settings(max_examples=60, deadline=None)
@given(cplx, cplx)
def test_polygon_mode_finds_every_ph_cubic_from_its_end_legs(w0, w1):
    if abs(w0) < 0.1 or abs(w1) < 0.1 or abs(w0 - w1) < 0.1 or abs(w0**2 + w0 * w1 + w1**2) < 0.1:
        return
    if abs((w0 * np.conj(w1)).imag) < 0.05 * abs(w0 * w1):
        return  # (nearly) straight: a whole family of lines fits
    c = DPCubic.from_preimage(w0, w1)
    p = c.control_points
    d0, d3 = p[1] - p[0], p[3] - p[2]
    sols = dp_ph_hermite(p[0], d0, p[3], d3, mode="polygon")
    assert 1 <= len(sols) <= 3
    for s in sols:
        _check_solution(s, p[0], d0, p[3], d3, "polygon")
    assert any(_same_curve(s, c, 1e-7) for s in sols)


@settings(max_examples=60, deadline=None)
@given(st.floats(0.05, np.pi - 0.05), st.floats(0.1, 10))
def test_seed_setting_never_has_a_solution_with_lambda_mu_at_most_one(theta, rho):
    """With P1 on [P0, O] and P2 on [O, P3] the polygon turns by less than pi: never PH."""
    p0, d0, p3, d3 = seed_setting(theta, rho)
    try:
        sols = dp_ph_hermite(p0, d0, p3, d3, mode="polygon")
    except NoSolutionError:
        return
    for s in sols:
        lam, mu = polygon_parameters(s, d0, d3)
        assert lam > 1 or mu / rho > 1  # the seed requires 0 <= lam, mu <= 1
        _check_solution(s, p0, d0, p3, d3, "polygon")


def test_seed_example_has_no_polygon_solution_and_its_numbers_are_inconsistent():
    p0, d0, p3, d3 = seed_setting(np.pi / 3, 1.0)
    with pytest.raises(NoSolutionError, match="polygon mode"):
        dp_ph_hermite(p0, d0, p3, d3, mode="polygon")
    # eq. (3.5) at theta = pi/3, rho = 1: 5 lam^2 + 8 lam - 4 = 0 -> lam = 2/5, as the seed says
    lam = max(np.roots([1 + 8 * np.cos(np.pi / 3), 7 + 9 - 16 * np.cos(np.pi / 3), 8 * np.cos(np.pi / 3) - 8]))
    assert np.isclose(lam, 0.4)
    # eq. (3.3) with rho = 1 gives mu = lam, so D2 = (1 - mu) P3 = (3/10, 3 sqrt3/10), not (1/5, sqrt3/5)
    assert not np.allclose((1 - lam) * p3, [1 / 5, np.sqrt(3) / 5])


@pytest.mark.parametrize("s0, s3", [(1, 1), (-1, 1), (1, -1), (-1, -1)])
def test_polygon_mode_straight_data_returns_a_line_without_reversal(s0, s3):
    (c,) = dp_ph_hermite([0, 0], [s0, 0], [3, 0], [s3, 0], mode="polygon")
    assert c.is_ph() and c.is_straight()
    lam, mu = polygon_parameters(c, [s0, 0], [s3, 0])
    assert lam > 0 and mu > 0
    np.testing.assert_allclose(c.points([0.0, 1.0]), [[0, 0], [3, 0]], atol=1e-15)


# -- error analysis (section 4) --------------------------------------------------------------------
@settings(max_examples=40, deadline=None)
@given(cplx, cplx, st.lists(st.floats(-1, 1), min_size=4, max_size=4))
def test_error_function_and_its_maximum(w0, w1, noise):
    if abs(w0) < 0.2 or abs(w1) < 0.2:
        return
    ph = DPCubic.from_preimage(w0, w1)
    p = ph.control_points.copy()
    p[1:3] += 0.3 * np.reshape(noise, (2, 2))
    dp = DPCubic(p)
    e = dp_ph_error(dp, ph)
    dense = e.distance(np.linspace(0, 1, 20001))
    assert e.max_error >= dense.max() - 1e-12
    assert e.max_error <= dense.max() + 1e-6 * (1 + dense.max())
    assert np.isclose(e.distance([e.t_max])[0], e.max_error, atol=1e-12)
    assert e.max_error <= e.bound + 1e-12
    n = e.squared_distance_poly()
    np.testing.assert_allclose(np.polynomial.polynomial.polyval(T, n), e.distance(T) ** 2, atol=1e-12)
    # n(t) = t^2 (1-t)^2 |A + B t|^2: double roots at 0 and 1
    assert abs(n[0]) < 1e-12 and abs(n[1]) < 1e-12
    dn = np.polynomial.polynomial.polyder(n)
    assert abs(np.polynomial.polynomial.polyval(1.0, n)) < 1e-12
    assert abs(np.polynomial.polynomial.polyval(1.0, dn)) < 1e-11


def test_errors_against_the_curves_own_end_data():
    dp = DPCubic([[1.0, 0.0], [0.7, 0.1], [0.2, 0.6], [0.5, 0.9]])
    errs = dp_ph_errors(dp)
    assert errs
    d = dp.derivative([0.0, 1.0])
    for e in errs:
        np.testing.assert_allclose(e.ph.tangent([0.0, 1.0]), d / np.linalg.norm(d, axis=1, keepdims=True), atol=1e-9)
        assert 0 < e.max_error <= e.bound


def test_error_needs_common_end_points():
    a = DPCubic([[0, 0], [1, 0], [2, 1], [3, 1]])
    b = DPCubic([[0, 0], [1, 0], [2, 1], [3, 2]])
    with pytest.raises(PlannerError, match="same end points"):
        dp_ph_error(a, b)


# -- bad input -------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "args, kw, msg",
    [
        (([0, 0], [0, 0], [1, 0], [1, 0]), {}, "d0 must not be the zero vector"),
        (([0, 0], [1, 0], [1, 0], [0, 0]), {}, "d3 must not be the zero vector"),
        (([0, 0], [1, 0], [0, 0], [1, 0]), {}, "p0 and p3 coincide"),
        (([0, 0, 0], [1, 0], [1, 0], [1, 0]), {}, r"p0 must have shape \(2,\)"),
        (([0, np.nan], [1, 0], [1, 0], [1, 0]), {}, "p0 must be finite"),
        (([0, 0], [1, 0], [1, 0], [1, 0]), {"mode": "bezier"}, "mode must be"),
        (([0, 0], "x", [1, 0], [1, 0]), {}, "d0 must be a numeric"),
    ],
)
def test_bad_hermite_data(args, kw, msg):
    with pytest.raises(HermiteDataError, match=msg):
        dp_ph_hermite(*args, **kw)


def test_bad_seed_setting():
    with pytest.raises(HermiteDataError, match="rho > 0"):
        seed_setting(1.0, -1.0)
