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


# -- the default member against dense brute force --------------------------------------------------------


def _cc(A):
    """CC value |A0 - 2 A1 + A2|^2 (N,) of stacked quintics A (N, 3, 4)."""
    return ((A[:, 0] - 2 * A[:, 1] + A[:, 2]) ** 2).sum(axis=1)


def _cc_best_phase(p0, p1, d0, d1, delta):
    """min over phi0 of the CC value of the member with phi2 - phi0 = delta, from the explicit member at phi0 = 0:
    A0 + A2 = X e^{i phi0} and |A0 - 2 A1 + A2| = |5 X e^{i phi0} - Q| / 2 with Q = 4 A1 + 3 (A0 + A2), phase-free."""
    A = batch_hermite(p0, p1, d0, d1, (np.zeros_like(delta), delta))
    X = A[:, 0] + A[:, 2]
    Q = 4 * A[:, 1] + 3 * X
    Xi = np.stack((-X[:, 1], X[:, 0], X[:, 3], -X[:, 2]), axis=1)  # X i
    best = np.hypot((X * Q).sum(axis=1), (Xi * Q).sum(axis=1))  # max over phi0 of <X e^{i phi0}, Q>
    return (25 * (X * X).sum(axis=1) + (Q * Q).sum(axis=1) - 10 * best) / 4


def _brute_force_cc(p0, p1, d0, d1, grid=1024, iterations=60):
    """The minimum over the family of the CC value, by a grid of phi2 - phi0 and golden sections around its
    best point; the CC value of every candidate comes from the explicit member (``angles``)."""
    n = p0.shape[0]
    g = np.arange(grid) * (2 * np.pi / grid)
    rep = [np.repeat(x, grid, axis=0) for x in (p0, p1, d0, d1)]
    F = _cc_best_phase(*rep, np.tile(g, n)).reshape(n, grid)
    lo = g[F.argmin(axis=1)] - 2 * np.pi / grid
    hi = lo + 4 * np.pi / grid
    r = (np.sqrt(5) - 1) / 2
    for _ in range(iterations):
        m1, m2 = hi - r * (hi - lo), lo + r * (hi - lo)
        left = _cc_best_phase(p0, p1, d0, d1, m1) < _cc_best_phase(p0, p1, d0, d1, m2)
        lo, hi = np.where(left, lo, m1), np.where(left, m2, hi)
    return np.minimum(F.min(axis=1), _cc_best_phase(p0, p1, d0, d1, (lo + hi) / 2))


def _hermite_data_of_spline(p):
    """The Hermite data of fit_ph_spline's C1 segments: tangents of the not-a-knot cubic spline, chord knots."""
    from planner.curves.tangents import chord_knots, cubic_spline_slopes

    u = chord_knots(p)
    h = np.diff(u)[:, None]
    m = cubic_spline_slopes(u, p)
    return p[:-1], p[1:], h * m[:-1], h * m[1:]


#: The default's CC value may exceed the brute-force minimum by 1e-9 of itself (the relative accuracy the
#: Newton convergence test asks for, 3e-10) plus 1e-13 of the data scale 25 (|d0| + |d1|) / 4: the CC
#: value's terms are about that scale, so this is some 500 ulps of them, the level at which a flat minimum
#: (CC - min ~ (delta - delta*)^4) stops being resolvable by any search, brute force included.
CC_RTOL, CC_ATOL = 1e-9, 1e-13


def _assert_no_worse_than_brute_force(p0, p1, d0, d1):
    A = batch_hermite(p0, p1, d0, d1)
    ref = _brute_force_cc(p0, p1, d0, d1)
    scale = 25 * (np.linalg.norm(d0, axis=1) + np.linalg.norm(d1, axis=1)) / 4
    excess = _cc(A) - ref
    assert np.all(excess <= CC_RTOL * ref + CC_ATOL * scale), (excess / scale).max()
    return excess / scale


def test_default_member_matches_dense_brute_force_on_random_hermite_data():
    rng = np.random.default_rng(2024)
    n = 300
    p1, d0, d1 = rng.normal(size=(3, n, 3))
    d0 *= rng.uniform(0.1, 3.0, size=(n, 1))  # uneven tangent lengths too
    _assert_no_worse_than_brute_force(np.zeros((n, 3)), p1, d0, d1)


@pytest.mark.parametrize("noise", [0.0, 1e-4, 3e-3, 3e-2])
def test_default_member_matches_dense_brute_force_on_spline_tangents(noise):
    """Smooth waypoints (a wavy helix, 5 mm apart), then jittered: flat minima and rough ones."""
    s = np.linspace(0.0, 6 * np.pi, 300)
    p = np.c_[0.25 * np.cos(s), 0.25 * np.sin(s) + 0.05 * np.sin(3 * s), 0.02 * s]
    p += np.random.default_rng(7).normal(scale=noise, size=p.shape)
    _assert_no_worse_than_brute_force(*_hermite_data_of_spline(p))


def test_smooth_waypoints_need_no_grid_search(monkeypatch):
    """On smooth data every segment is certified by the fast path (the global grid search never runs)."""
    import planner.curves.ph_quintic as ph

    def forbidden(cc):
        raise AssertionError(f"grid search on {cc.P.shape[1]} segments")

    monkeypatch.setattr(ph, "_cc_grid_starts", forbidden)
    for n in (100, 1000):
        s = np.linspace(0.0, 6 * np.pi, n)
        p = np.c_[0.25 * np.cos(s), 0.25 * np.sin(s) + 0.05 * np.sin(3 * s), 0.02 * s]
        batch_hermite(*_hermite_data_of_spline(p + np.random.default_rng(42).normal(scale=1e-6, size=p.shape)))


def test_rough_data_falls_back_to_the_grid_search(monkeypatch):
    import planner.curves.ph_quintic as ph

    calls = []
    search = ph._cc_grid_starts
    monkeypatch.setattr(ph, "_cc_grid_starts", lambda cc: calls.append(cc.P.shape[1]) or search(cc))
    rng = np.random.default_rng(3)
    p1, d0, d1 = rng.normal(size=(3, 50, 3))
    batch_hermite(np.zeros((50, 3)), p1, d0, d1)
    assert calls and 0 < calls[0] <= 50


@given(quaternions(), quaternions())
@settings(max_examples=60, deadline=None)
def test_fibre_distance_identity(A, B):
    """The certificate's identity: for u = A i A*, v = B i B* and F = min over phi |A e^{i phi} - B|^2,
    |u - v|^2 = F (2 (|u| + |v|) - F)."""
    phi = np.linspace(0, 2 * np.pi, 20001)
    Ae = np.stack((np.cos(phi) * A[0] - np.sin(phi) * A[1], np.cos(phi) * A[1] + np.sin(phi) * A[0],
                   np.cos(phi) * A[2] + np.sin(phi) * A[3], np.cos(phi) * A[3] - np.sin(phi) * A[2]), axis=1)
    F = ((Ae - B) ** 2).sum(axis=1).min()
    u, v = (PHQuintic.from_quaternions(q, q, q).derivative(0.0)[0] for q in (A, B))  # q i q*
    S = np.linalg.norm(u) + np.linalg.norm(v)
    scale = S * S
    assert abs(((u - v) ** 2).sum() - F * (2 * S - F)) <= 1e-6 * scale  # F from a grid of 20001 phases


@pytest.mark.parametrize("seed", range(4))
def test_alpha_start_is_the_global_minimum_of_the_alpha_criterion(seed):
    """The trust-region start min |Sc cos + Ss sin - w|^2 against a dense grid: exact where the minimum is flat
    (w near the tip of the ellipse S, where Newton in delta would be slow), near the global minimizer elsewhere
    (the root of the secular equation from a lower bound of it; Newton on the CC measure follows)."""
    from planner.curves.ph_quintic import _PRODUCTS, _alpha_start, sqrt_rot

    rng = np.random.default_rng(seed)
    n = 400
    a0, a2 = (sqrt_rot(rng.normal(size=(3, n)))[0] for _ in range(2))
    R = _PRODUCTS @ (a0[:, None] * a2[None]).reshape(16, n)
    Sc, Ss = R[:3], R[4:7]
    w = rng.normal(size=(3, n)) * rng.uniform(0, 2, size=n)
    # flat cases: w at (or just inside or outside) the tip of the ellipse S, where the minimum is quartic
    tip = np.where(rng.random(n) < 0.5, 1.0, -1.0) * (Sc * R[3] + Ss * R[7]) / np.hypot(R[3], R[7])
    flat = rng.random(n) < 0.5
    w[:, flat] = (tip * (1 + rng.normal(scale=1e-3, size=n)))[:, flat]
    with np.errstate(all="ignore"):
        c, s, _ = _alpha_start(R[3], R[7], (Sc * w).sum(0), (Ss * w).sum(0), R[3] ** 2 + R[7] ** 2)
    T = ((Sc * c + Ss * s - w) ** 2).sum(0)
    g = np.linspace(0, 2 * np.pi, 20001)
    Tg = ((Sc[:, None] * np.cos(g)[:, None] + Ss[:, None] * np.sin(g)[:, None] - w[:, None]) ** 2).sum(0)
    scale = (Sc**2 + Ss**2 + w**2).sum(0)
    excess = (T - Tg.min(axis=0)) / scale
    assert np.allclose(c * c + s * s, 1, atol=1e-14)
    assert excess[flat].max() <= 1e-12  # the grid's own error there is ~ (2 pi / 20000)^4 ~ 1e-14
    best = g[Tg.argmin(axis=0)]
    assert np.abs(np.angle((c + 1j * s) * np.exp(-1j * best))).max() <= 0.25
