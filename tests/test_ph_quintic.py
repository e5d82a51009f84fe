"""PH quintics: the PH property, exact arc length, Hermite interpolation, the seed's example."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
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


# -- the default member (issue 12; the geometric guarantees are in tests/test_curves_symmetry.py) --------------


def _energy(A, pieces=64, nodes=16):
    """Bending energy (N,) of quintics A (N, 3, 4) by a fine composite Gauss rule on r', r'' (independent of the
    quaternion shortcut of the module)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    t = ((x[None] + 1) / 2 + np.arange(pieces)[:, None]).ravel() / pieces
    w = np.tile(w, pieces) / (2 * pieces)
    out = []
    for a in A:
        c = PHQuintic.from_quaternions(*a)
        d1, d2 = c.derivative(t), c.derivative(t, 2)
        out.append((w * (np.linalg.norm(np.cross(d1, d2), axis=1) ** 2 / np.linalg.norm(d1, axis=1) ** 5)).sum())
    return np.array(out)


def test_default_member_is_a_pure_vector_member_of_least_energy():
    """A0 i A2* of the default has no scalar part, and flipping phi0 by pi (the other member with the same
    delta and the CC measure's other extreme) never lowers the bending energy."""
    rng = np.random.default_rng(11)
    n = 200
    p1, d0, d1 = rng.normal(size=(3, n, 3))
    A = batch_hermite(np.zeros((n, 3)), p1, d0, d1)
    A0, A2 = A[:, 0], A[:, 2]
    A0i = np.stack((-A0[:, 1], A0[:, 0], A0[:, 3], -A0[:, 2]), axis=1)
    assert np.abs((A0i * A2).sum(axis=1)).max() <= 1e-12 * np.abs(A).max() ** 2  # scalar of A0 i A2* = <A0 i, A2>
    flipped = np.stack((-A0, 0.5 * (4 * A[:, 1] + 3 * (A0 + A2)) - A[:, 1], -A2), axis=1)  # A1' = Q / 2 - A1
    c = PHQuintic.from_quaternions(*flipped[0])
    assert np.allclose(c.points([0.0, 1.0]), [[0, 0, 0], p1[0]])
    assert np.allclose(c.derivative([0.0, 1.0]), [d0[0], d1[0]])
    E, Ef = _energy(A), _energy(flipped)
    assert np.all(E <= Ef * (1 + 1e-3))


def test_default_member_is_fourth_order_on_a_helix():
    """Hermite data sampled from a helix at spacing h: the interpolant's error falls as h^4 (as the ordinary cubic
    Hermite interpolant's), within 1.5 times the cubic's error."""
    def helix(t):
        return np.c_[np.cos(t), np.sin(t), 0.3 * t]

    def dhelix(t):
        return np.c_[-np.sin(t), np.cos(t), 0.3 * np.ones_like(t)]

    ts = np.linspace(0, 1, 41)
    errors = []
    for h in (0.4, 0.2, 0.1, 0.05):
        t0 = np.arange(0.0, 6.0, h)
        p0, p1, d0, d1 = helix(t0), helix(t0 + h), h * dhelix(t0), h * dhelix(t0 + h)
        A = batch_hermite(p0, p1, d0, d1)
        pts = np.stack([PHQuintic.from_quaternions(*a, p0=q).points(ts) for a, q in zip(A, p0, strict=True)])
        ref = np.stack([helix(a + ts * h) for a in t0])
        H = np.stack(((1 + 2 * ts) * (1 - ts) ** 2, ts * (1 - ts) ** 2, ts**2 * (3 - 2 * ts), ts**2 * (ts - 1)), axis=1)
        cubic = np.einsum("tk,nkd->ntd", H, np.stack((p0, d0, p1, d1), axis=1))
        errors.append((np.abs(pts - ref).max(), np.abs(cubic - ref).max()))
    e = np.array(errors)
    assert np.all(e[:, 0] <= 1.5 * e[:, 1])
    rates = np.log2(e[:-1, 0] / e[1:, 0])
    assert rates.min() > 3.8, rates
