"""PH quintic splines (C1 and C2) and the G1 PH cubic spline through waypoints."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from scipy.integrate import quad
from scipy.interpolate import CubicSpline

from planner.curves.ph_core import batch_control_points
from planner.curves.ph_cubic_spline import fit_ph_cubic_spline
from planner.curves.ph_quintic import batch_hermite
from planner.curves.spline import fit_ph_spline
from planner.curves.tangents import chord_knots, cubic_spline_slopes
from planner.errors import PlannerError
from tests.conftest import waypoint_sets


def extent(p):
    return max(1.0, float(np.ptp(p, axis=0).max()))


@given(waypoint_sets())
@settings(max_examples=40, deadline=None)
def test_c1_spline_interpolates_and_is_c1(p):
    s = fit_ph_spline(p, continuity="C1")
    assert s.continuity == "C1" and s.n_segments == len(p) - 1
    assert s.interpolation_errors(p).max() <= 1e-13 * extent(p)
    assert s.tangent_jumps().max(initial=0) <= 1e-12
    assert np.allclose(s.knots, np.concatenate(([0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1)))))


@given(waypoint_sets(min_size=3, max_size=25))
@settings(max_examples=25, deadline=None)
def test_c2_spline_interpolates_and_is_curvature_continuous(p):
    s = fit_ph_spline(p, continuity="C2")
    c1 = fit_ph_spline(p, continuity="C1")
    assert s.continuity == "C2"
    assert s.interpolation_errors(p).max() <= 1e-12 * extent(p)
    assert s.tangent_jumps().max() <= 1e-11
    kmax = np.abs(s.curvature(np.linspace(s.knots[0], s.knots[-1], 400))).max()
    assert s.curvature_jumps().max() <= 1e-9 * max(1.0, kmax)
    # second derivative continuous in u, not only the curvature
    u = s.knots[1:-1]
    left = s._derivative_t(np.arange(s.n_segments - 1), np.ones(u.size), 2) / np.diff(s.knots)[:-1, None] ** 2
    right = s.derivative(u, 2)
    assert np.abs(left - right).max() <= 1e-9 * max(1.0, np.abs(right).max())
    # the C1 spline generally has curvature jumps: the C2 solve did something
    if len(p) >= 4:
        assert c1.curvature_jumps().max() > 1e3 * s.curvature_jumps().max()


@given(waypoint_sets(max_size=12))
@settings(max_examples=20, deadline=None)
def test_exact_length_and_inverse(p):
    s = fit_ph_spline(p, continuity="C1")
    ref = sum(
        quad(lambda u: np.linalg.norm(s.derivative(u)[0]), a, b, epsabs=1e-13, epsrel=1e-13, limit=200)[0]
        for a, b in zip(s.knots[:-1], s.knots[1:], strict=True)
    )
    assert s.length == pytest.approx(ref, rel=1e-11)
    sv = np.linspace(0, s.length, 257)
    u = s.parameter_at_length(sv)
    assert np.all(np.diff(u) >= -1e-13 * s.knots[-1])  # monotone up to round-off
    assert np.abs(s.arc_length(u) - sv).max() <= 1e-12 * s.length


@given(waypoint_sets(max_size=40))
@settings(max_examples=30, deadline=None)
def test_c1_segments_are_the_hermite_interpolants_of_the_cubic_spline_tangents(p):
    """The fitter builds each segment from shared, length-normalised tangent roots: with given free angles the
    same curves as batch_hermite on the Hermite data (h m_k, h m_k+1); by default members as close to a PH
    cubic (the CC measure |A0 - 2 A1 + A2|^2 agrees within the selection's tolerance)."""
    u = chord_knots(p)
    h = np.diff(u)[:, None]
    m = cubic_spline_slopes(u, p)
    data = (p[:-1], p[1:], h * m[:-1], h * m[1:])
    s = fit_ph_spline(p, continuity="C1", angles=(0.3, -1.2))
    ref = batch_control_points(batch_hermite(*data, angles=(0.3, -1.2)), p[:-1])
    assert np.abs(s.control_points - ref).max() <= 1e-12 * extent(p)
    s = fit_ph_spline(p, continuity="C1")
    A = batch_hermite(*data)
    cc = lambda A: ((A[:, 0] - 2 * A[:, 1] + A[:, 2]) ** 2).sum(axis=1)  # noqa: E731
    scale = 25 * h[:, 0] * (np.linalg.norm(m[:-1], axis=1) + np.linalg.norm(m[1:], axis=1)) / 4
    assert np.all(np.abs(cc(s.A) - cc(A)) <= 1e-9 * cc(A) + 1e-13 * scale)


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6, 40])
@pytest.mark.parametrize("dim", [2, 3])
def test_cubic_spline_slopes_are_scipys(n, dim):
    p = np.cumsum(np.random.default_rng(n).normal(size=(n, dim)), axis=0)
    u = chord_knots(p)
    m = cubic_spline_slopes(u, p)
    ref = CubicSpline(u, p)(u, 1) if n > 2 else np.tile((p[1] - p[0]) / u[1], (2, 1))
    assert m.shape == (n, dim)
    assert np.abs(m - ref).max() <= 1e-12 * np.abs(ref).max()


def test_given_tangents_are_honoured():
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 1.0]])
    t = np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 1], [0, -1, 0.0]])
    s = fit_ph_spline(p, t, continuity="C1")
    tan = s.tangent(s.knots)
    unit = t / np.linalg.norm(t, axis=1, keepdims=True)
    assert np.abs(tan - unit).max() < 1e-13
    # the spline leaves each waypoint with |dr/du| = 1 (u ~ arc length)
    assert np.allclose(np.linalg.norm(s.derivative(s.knots[:-1]), axis=1), 1.0)


def test_straight_line_is_reproduced_exactly():
    p = np.linspace([0, 0, 0], [1, 2, 3], 7) ** 1  # collinear, uneven spacing below
    p[3] += 0.1 * (p[4] - p[3])
    for c in ("C1", "C2"):
        s = fit_ph_spline(p, continuity=c)
        q = s.points(np.linspace(0, s.knots[-1], 101))
        assert np.abs(np.cross(q - p[0], p[-1] - p[0])).max() < 1e-12
        assert s.length == pytest.approx(np.linalg.norm(p[-1] - p[0]), rel=1e-13)


def test_circle_approximation_is_fourth_order_like_the_cubic_spline():
    def errors(n):
        th = np.linspace(0, 1.5 * np.pi, n)
        p = np.c_[np.cos(th), np.sin(th), np.zeros_like(th)]
        u = np.concatenate(([0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))))
        radial = lambda q: np.abs(np.linalg.norm(q[:, :2], axis=1) - 1).max()  # noqa: E731
        out = {"cubic": radial(CubicSpline(u, p)(np.linspace(0, u[-1], 4001)))}
        for c in ("C1", "C2"):
            s = fit_ph_spline(p, continuity=c)
            out[c] = radial(s.points(np.linspace(0, s.knots[-1], 4001)))
            assert s.length == pytest.approx(1.5 * np.pi, rel=1e-4)
        return out

    coarse, fine = errors(25), errors(49)
    for c in ("C1", "C2"):
        assert coarse[c] <= 1.2 * coarse["cubic"] and fine[c] <= 1.2 * fine["cubic"]
        assert coarse[c] / fine[c] > 12  # halving the step divides the error by ~16


def test_c2_with_end_tangents():
    p = np.array([[0, 0, 0], [1, 0.2, 0], [2, 0, 0.3], [3, 0.5, 0.2]])
    s = fit_ph_spline(p, end_tangents=([0, 1, 0], [1, 0, 0]))
    assert np.allclose(s.tangent([s.knots[0], s.knots[-1] - 1e-15]), [[0, 1, 0], [1, 0, 0]], atol=1e-9)


@given(waypoint_sets(max_size=15))
@settings(max_examples=20, deadline=None)
def test_ph_cubic_spline_interpolates_and_is_g1(p):
    s = fit_ph_cubic_spline(p)
    assert s.degree == 3 and s.continuity == "G1"
    assert s.interpolation_errors(p).max() <= 1e-12 * extent(p)
    assert s.tangent_angles().max(initial=0) <= 1e-10
    assert np.all(np.diff(s.waypoint_knots) > 0)


def test_ph_cubic_spline_of_a_helix():
    a, c = 1.0, 0.3
    th = np.linspace(0, 2 * np.pi, 40)
    p = np.c_[a * np.cos(th), a * np.sin(th), c * th]
    s = fit_ph_cubic_spline(p)
    assert s.length == pytest.approx(2 * np.pi * np.hypot(a, c), rel=1e-5)
    u = np.linspace(0, s.knots[-1], 1001)
    q = s.points(u)
    assert np.abs(np.hypot(q[:, 0], q[:, 1]) - a).max() < 1e-4


def test_ph_cubic_spline_splits_spans_without_ph_cubic():
    # a turn of ~180 degrees between two waypoints admits no PH cubic: the span must be split
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 0.05, 0.0], [0, 0.1, 0.02]])
    t = np.array([[1, 0, 0], [1, 0, 0], [-1, 0, 0], [-1, 0, 0]])
    s = fit_ph_cubic_spline(p, t)
    assert s.n_segments > 3 and s.waypoint_index is not None
    assert s.interpolation_errors(p).max() < 1e-12
    assert np.allclose(s.tangent(s.waypoint_knots[:-1]), t[:-1], atol=1e-10)


# -- bad input ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("fit", [fit_ph_spline, fit_ph_cubic_spline])
@pytest.mark.parametrize(
    "points, match",
    [
        ([[0, 0, 0]], "need at least 2 waypoints, got 1"),
        ([], "need at least 2 waypoints, got 0"),
        ([[0, 0], [1, 1]], "must have 3 coordinates per row, got 2"),
        ([[0, 0, 0], [1, 1]], "waypoint 1: waypoints row must have 3 coordinates"),
        ([[0, 0, 0], [1, 1, np.nan], [2, 0, 0]], "waypoint 1: coordinates must be finite"),
        ([[0, 0, 0], [1, 1, 1], [2, np.inf, 0]], "waypoint 2: coordinates must be finite"),
        ([[0, 0, 0], [1, 1, 1], [1, 1, 1], [2, 0, 0]], "waypoint 2: duplicates waypoint 1"),
        ([[0, 0, 0], ["a", 1, 1]], "waypoint 1: waypoints row is not numeric"),
    ],
)
def test_bad_waypoints(fit, points, match):
    with pytest.raises(PlannerError, match=match):
        fit(points)


@pytest.mark.parametrize("fit", [fit_ph_spline, fit_ph_cubic_spline])
@pytest.mark.parametrize(
    "tangents, match",
    [
        ([[1, 0, 0], [1, 0, 0]], "got 2 tangents for 3 waypoints"),
        ([[1, 0, 0], [0, 0, 0], [1, 0, 0]], "waypoint 1: tangent is the zero vector"),
        ([[1, 0, 0], [1, 0, 0], [np.nan, 0, 0]], "waypoint 2: tangent must be finite"),
        ([[1, 0], [1, 0], [1, 0]], "must have 3 coordinates per row"),
    ],
)
def test_bad_tangents(fit, tangents, match):
    p = [[0, 0, 0], [1, 0, 0], [2, 1, 0]]
    kwargs = {"continuity": "C1"} if fit is fit_ph_spline else {}
    with pytest.raises(PlannerError, match=match):
        fit(p, tangents, **kwargs)


def test_c2_refuses_interior_tangents_instead_of_dropping_them():
    with pytest.raises(PlannerError, match="C2 spline determines its interior tangents"):
        fit_ph_spline([[0, 0, 0], [1, 0, 0], [2, 1, 0]], [[1, 0, 0]] * 3, continuity="C2")


def test_unknown_continuity():
    with pytest.raises(PlannerError, match="continuity must be"):
        fit_ph_spline([[0, 0, 0], [1, 0, 0]], continuity="C3")


def test_errors_are_value_errors():
    with pytest.raises(ValueError):
        fit_ph_spline([[0, 0, 0]])


def test_arc_length_inversion_on_a_segment_with_very_uneven_speed():
    """Regression: sigma from 0.22 to 3.9 within one segment sent unguarded Newton steps out of [0, 1]."""
    p = np.array([[-0.16272144, -0.63291263, 0.48785187], [-0.08985681, -0.69781352, 0.53822378],
                  [-0.36712314, -0.91685036, 0.71922538], [-0.74547585, -0.69992272, 2.02854636],
                  [-1.00470313, -0.57523713, 2.7019045], [-1.03661261, -0.62284016, 2.68268321],
                  [-0.81965086, -0.47017288, 3.7836362], [-1.05426524, -0.66982744, 3.14232591],
                  [-0.18706014, -0.09480756, 1.8819351], [-0.36551348, 0.29030935, 1.50844634],
                  [0.22816608, 0.27411822, 1.2565288], [0.17494615, -0.18174167, 1.99970798]])
    s = fit_ph_spline(p, continuity="C1")
    speed = s.speed(np.linspace(0, s.knots[-1], 4001))
    assert speed.max() / speed.min() > 10
    sv = np.linspace(0, s.length, 2001)
    u = s.parameter_at_length(sv)
    assert np.abs(s.arc_length(u) - sv).max() < 1e-13 * s.length
    assert np.all(np.diff(u) > 0)
