"""PH quintics: the PH property, exact arc length, Hermite interpolation, the seed's example."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

from planner import bernstein
from planner.curves.ph_quintic import PHQuintic, batch_hermite
from planner.errors import PlannerError
from tests.conftest import finite, quaternions

vec3 = st.lists(finite, min_size=3, max_size=3).map(np.array)
nonzero3 = vec3.filter(lambda v: np.linalg.norm(v) > 0.1)

SEED_A = ((0, 1, 0, 2), (0, 2, 1, -1), (0, 3, -2, -1))


def power(coeffs):
    """Power-basis coefficients of a scalar Bernstein polynomial."""
    return bernstein.to_power(coeffs)


@given(quaternions(), quaternions(), quaternions())
@settings(max_examples=60, deadline=None)
def test_ph_property_as_polynomials(A0, A1, A2):
    """|r'(t)|^2 and sigma(t)^2 agree coefficient by coefficient (degree 8), to round-off."""
    c = PHQuintic.from_quaternions(A0, A1, A2)
    h = c.hodograph_coeffs
    lhs = sum(np.convolve(power(h[:, k]), power(h[:, k])) for k in range(3))
    sig = power(c.sigma_coeffs)
    rhs = np.convolve(sig, sig)
    scale = np.abs(rhs).max()
    assert np.abs(lhs - rhs).max() <= 1e-13 * scale


@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")
@given(quaternions(), quaternions(), quaternions(), vec3)
@settings(max_examples=12, deadline=None)
def test_arc_length_matches_adaptive_quadrature(A0, A1, A2, p0):
    c = PHQuintic.from_quaternions(A0, A1, A2, p0)
    ref, err = quad(lambda t: np.linalg.norm(c.derivative(t)[0]), 0, 1, epsabs=1e-14, epsrel=1e-14, limit=200)
    assert c.length == pytest.approx(ref, rel=1e-12)
    t = np.array([0.1, 0.37, 0.8])
    part = [quad(lambda s: np.linalg.norm(c.derivative(s)[0]), 0, ti, epsabs=1e-14, epsrel=1e-14)[0] for ti in t]
    assert np.allclose(c.arc_length(0, t), part, rtol=1e-12, atol=1e-14)


def test_seed_example_arc_length_is_17_over_3():
    c = PHQuintic.from_quaternions(*SEED_A)
    assert abs(c.length - 17 / 3) < 4 * np.finfo(float).eps * 17 / 3
    assert c.arc_length(0.0, 1.0) == pytest.approx(17 / 3, rel=1e-15)


def test_control_points_start_at_p0_and_hodograph_ends_are_A_i_Astar():
    c = PHQuintic.from_quaternions(*SEED_A, p0=(1.0, 2.0, 3.0))
    assert np.array_equal(c.control_points[0], [1.0, 2.0, 3.0])
    # A0 = j + 2k: A0 i A0* = (u^2+v^2-p^2-q^2, 2(uq+vp), 2(vq-up)) with (u,v,p,q) = (0,1,0,2)
    assert np.allclose(c.derivative(0.0)[0], [1 - 4, 0, 4])
    assert np.allclose(c.speed([0.0, 1.0]), [5.0, 14.0])


@given(quaternions(), quaternions(), quaternions())
@settings(max_examples=30, deadline=None)
def test_parameter_at_length_inverts_arc_length(A0, A1, A2):
    c = PHQuintic.from_quaternions(A0, A1, A2)
    s = np.linspace(0, c.length, 101)
    t = c.parameter_at_length(s)
    assert np.all(np.diff(t) > 0)
    assert np.abs(c.arc_length(0, t) - s).max() <= 1e-13 * c.length
    assert abs(t[0]) < 1e-14 and abs(t[-1] - 1.0) < 1e-14


@given(vec3, vec3, nonzero3, nonzero3)
@settings(max_examples=80, deadline=None)
def test_hermite_end_conditions(p0, p1, d0, d1):
    c = PHQuintic.hermite(p0, p1, d0, d1)
    scale = max(1.0, np.abs([p0, p1]).max(), np.abs([d0, d1]).max())
    assert np.abs(c.points([0, 1]) - [p0, p1]).max() <= 1e-13 * scale
    assert np.abs(c.derivative([0, 1]) - [d0, d1]).max() <= 1e-13 * scale


@given(vec3, nonzero3, nonzero3, st.floats(-np.pi, np.pi), st.floats(-np.pi, np.pi))
@settings(max_examples=40, deadline=None)
def test_every_member_of_the_hermite_family_interpolates(p1, d0, d1, phi0, phi2):
    c = PHQuintic.hermite(np.zeros(3), p1, d0, d1, angles=(phi0, phi2))
    scale = max(1.0, np.abs(p1).max(), np.abs([d0, d1]).max())
    assert np.abs(c.points([0, 1]) - [np.zeros(3), p1]).max() <= 1e-13 * scale
    assert np.abs(c.derivative([0, 1]) - [d0, d1]).max() <= 1e-13 * scale


def test_hermite_family_has_two_free_angles():
    p0, p1, d0, d1 = np.zeros(3), np.array([1.0, 0.5, 0.2]), np.array([1.0, 0.0, 0.3]), np.array([0.2, 1.0, 0.0])
    a = PHQuintic.hermite(p0, p1, d0, d1, angles=(0.0, 0.0))
    b = PHQuintic.hermite(p0, p1, d0, d1, angles=(0.0, 1.0))
    c = PHQuintic.hermite(p0, p1, d0, d1, angles=(1.0, 1.0))  # same phase difference, other Q phase
    t = np.linspace(0, 1, 9)
    assert np.abs(a.points(t) - b.points(t)).max() > 1e-3
    assert np.abs(a.points(t) - c.points(t)).max() > 1e-3


@given(quaternions(), quaternions(), vec3)
@settings(max_examples=40, deadline=None)
def test_default_member_reproduces_a_ph_cubic(A0, A2, p0):
    """The ordinary cubic Hermite interpolant of PH cubic data is PH: the default must reproduce it."""
    cubic = PHQuintic.from_quaternions(A0, 0.5 * (A0 + A2), A2, p0)  # A linear: a PH cubic, elevated
    # straight lines are degenerate (the measure's minimum is a cusp, found to ~sqrt(eps) only)
    h = cubic.hodograph_coeffs
    assume(np.linalg.norm(np.cross(h[0], h[4])) + np.linalg.norm(np.cross(h[0], h[2])) > 1e-3 * np.abs(h).max() ** 2)
    d0, d1 = cubic.derivative([0.0, 1.0])
    p1 = cubic.points(1.0)[0]
    c = PHQuintic.hermite(p0, p1, d0, d1)
    t = np.linspace(0, 1, 11)
    assert np.abs(c.points(t) - cubic.points(t)).max() <= 1e-8 * max(1.0, np.abs(cubic.control_points).max())


def test_default_member_minimizes_the_cc_measure():
    """|A0 - 2 A1 + A2| of the default is no larger than any member on a 72 x 72 grid of angles."""
    rng = np.random.default_rng(7)
    grid = np.linspace(-np.pi, np.pi, 72, endpoint=False)
    a, b = (g.ravel() for g in np.meshgrid(grid, grid))
    for _ in range(5):
        p1, d0, d1 = rng.normal(size=(3, 3))
        c = PHQuintic.hermite(np.zeros(3), p1, d0, d1)
        best = np.linalg.norm(c.A[0] - 2 * c.A[1] + c.A[2])
        n = a.size
        A = batch_hermite(np.zeros((n, 3)), np.tile(p1, (n, 1)), np.tile(d0, (n, 1)), np.tile(d1, (n, 1)), (a, b))
        brute = np.linalg.norm(A[:, 0] - 2 * A[:, 1] + A[:, 2], axis=1).min()
        assert best <= brute * (1 + 1e-9)


def test_curvature_and_torsion_of_a_planar_curve():
    # A in span{1, k} gives a planar (z = 0) hodograph: zero torsion
    c = PHQuintic.from_quaternions((1, 0, 0, 0.2), (0.8, 0, 0, 0.9), (0.3, 0, 0, 1.2))
    t = np.linspace(0, 1, 21)
    assert np.abs(c.points(t)[:, 2]).max() == 0.0
    assert np.abs(c.torsion(t)).max() < 1e-12
    # curvature of a planar curve: |x'y'' - y'x''| / |r'|^3
    d1, d2 = c.derivative(t), c.derivative(t, 2)
    ref = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / np.linalg.norm(d1, axis=1) ** 3
    assert np.allclose(c.curvature(t), ref, rtol=1e-12)
    assert np.allclose(np.linalg.norm(c.tangent(t), axis=1), 1.0, atol=1e-15)


def test_torsion_of_the_seed_curve_against_finite_differences_free_formula():
    c = PHQuintic.from_quaternions(*SEED_A)
    t = np.linspace(0.05, 0.95, 7)
    d1, d2, d3 = c.derivative(t), c.derivative(t, 2), c.derivative(t, 3)
    ref = np.linalg.det(np.stack((d1, d2, d3), axis=1)) / np.linalg.norm(np.cross(d1, d2), axis=1) ** 2
    assert np.allclose(c.torsion(t), ref, rtol=1e-12)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(p0=(0, 0), p1=(1, 0, 0), d0=(1, 0, 0), d1=(1, 0, 0)), "p0 must have shape"),
        (dict(p0=(0, 0, 0), p1=(1, 0, np.nan), d0=(1, 0, 0), d1=(1, 0, 0)), "p1 must be finite"),
        (dict(p0=(0, 0, 0), p1=(1, 0, 0), d0=(0, 0, 0), d1=(1, 0, 0)), "d0 must not be the zero vector"),
        (dict(p0=(0, 0, 0), p1=(1, 0, 0), d0=(1, 0, 0), d1=(0, 0, 0)), "d1 must not be the zero vector"),
        (dict(p0=(0, 0, 0), p1=(1, 0, 0), d0=(1, 0, 0), d1=(1, 0, 0), angles=(0.0,)), "angles"),
    ],
)
def test_hermite_bad_input(kwargs, match):
    with pytest.raises(PlannerError, match=match):
        PHQuintic.hermite(**kwargs)


def test_parameter_at_length_out_of_range():
    c = PHQuintic.from_quaternions(*SEED_A)
    with pytest.raises(PlannerError, match=r"s\[1\] = 6.0 is outside"):
        c.parameter_at_length([1.0, 6.0])
