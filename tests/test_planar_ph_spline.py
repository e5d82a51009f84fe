"""G1 planar PH cubic spline from DP-PH Hermite pieces, as a constant-z path."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad

from planner.curves.planar_ph_spline import PlanarPHSpline, fit_planar_ph_spline
from planner.errors import NoSolutionError, PlannerError, WaypointError

pts = st.lists(
    st.tuples(st.floats(-10, 10), st.floats(-10, 10)), min_size=2, max_size=9, unique=True
).map(np.array)


def _spread(p):
    d = np.linalg.norm(np.diff(p, axis=0), axis=1)
    return d.min() > 1e-2 * max(np.ptp(p, axis=0).max(), 1e-9)


def _reverses(wp, cos_max=-0.95):
    ch = np.diff(np.asarray(wp, float)[:, :2], axis=0)
    n = np.linalg.norm(ch, axis=1)
    cos = np.einsum("ij,ij->i", ch[:-1], ch[1:]) / (n[:-1] * n[1:])
    return bool(cos.size and cos.min() < cos_max)


def _check_path(s: PlanarPHSpline, wp, z):
    scale = 1 + np.abs(wp).max()
    assert s.interpolation_errors(wp).max() <= 1e-12 * scale
    # G1 to round-off; near a hairpin the pieces end in near-cusps and the guarantee is 1e-6 rad
    assert s.tangent_jumps().max(initial=0) <= (1e-6 if _reverses(wp) else 1e-9)
    u = np.linspace(s.knots[0], s.knots[-1], 301)
    r = s.points(u)
    assert r.shape == (301, 3) and np.all(r[:, 2] == z)
    assert np.allclose(np.linalg.norm(s.tangent(u), axis=1), 1)
    for seg in s.segments:
        assert seg.is_ph(1e-9)
    # left and right unit tangents agree at every break
    b = s.breaks[1:-1]
    if b.size:
        k = np.arange(1, s.n_segments)
        left = s.bezier[k - 1, 3] - s.bezier[k - 1, 2]
        right = s.bezier[k, 1] - s.bezier[k, 0]
        left /= np.linalg.norm(left, axis=1, keepdims=True)
        right /= np.linalg.norm(right, axis=1, keepdims=True)
        assert np.abs(left - right).max() <= (1e-6 if _reverses(wp) else 1e-9)


@settings(max_examples=30, deadline=None)
@given(pts, st.floats(-2, 2))
def test_random_waypoints(wp, z):
    if not _spread(wp):
        return
    try:
        s = fit_planar_ph_spline(wp, z=z)
    except (WaypointError, NoSolutionError) as exc:
        # only a (nearly) reversing path may be refused: the chord turns by almost pi somewhere
        assert _reverses(wp), str(exc)
        assert "revers" in str(exc) or "hairpin" in str(exc) or "subdivisions" in str(exc)
        return
    _check_path(s, wp, z)
    np.testing.assert_allclose(s.knots, np.concatenate(([0], np.cumsum(np.linalg.norm(np.diff(wp, axis=0), axis=1)))))
    assert s.n_segments >= len(wp) - 1


@settings(max_examples=15, deadline=None)
@given(pts)
def test_exact_arc_length_and_its_inverse(wp):
    if not _spread(wp) or _reverses(wp):
        return
    s = fit_planar_ph_spline(wp)
    ref = sum(
        quad(lambda u: np.linalg.norm(s.derivative(u)[0]), a, b, epsabs=1e-13, epsrel=1e-13, limit=200)[0]
        for a, b in zip(s.breaks[:-1], s.breaks[1:], strict=True)
    )
    assert abs(s.length - ref) <= 1e-10 * ref
    sl = np.linspace(0, s.length, 57)
    u = s.parameter_at_length(sl)
    np.testing.assert_allclose(s.arc_length(u), sl, atol=1e-11 * s.length)
    u_mid = 0.5 * (s.breaks[:-1] + s.breaks[1:])
    sp_ = np.linalg.norm(s.derivative(u_mid), axis=1)
    np.testing.assert_allclose(s.speed(u_mid), sp_, rtol=1e-10, atol=1e-12 * sp_.max())


def test_given_tangents_are_respected():
    wp = np.array([[0, 0], [1, 0.3], [2, 0], [3, -0.4]], float)
    tan = np.array([[1, 1], [1, 0], [1, -1], [1, 0]], float)
    s = fit_planar_ph_spline(wp, tan)
    expected = tan / np.linalg.norm(tan, axis=1, keepdims=True)
    np.testing.assert_allclose(s.tangent(s.knots)[:, :2], expected, atol=1e-9)
    _check_path(s, wp, 0.0)


def test_s_shaped_span_is_split_at_its_inflection():
    wp = np.array([[0, 0], [3, 0]], float)
    s = fit_planar_ph_spline(wp, [[1, 1], [1, 1]])  # needs an inflection: no single PH cubic
    assert s.n_segments >= 2
    _check_path(s, wp, 0.0)
    k = s.curvature(np.linspace(0.01, 2.99, 200))
    assert k.min() < 0 < k.max()


def test_circle_samples():
    a = np.linspace(0, 2 * np.pi, 13)
    wp = np.stack((np.cos(a), np.sin(a)), axis=1)
    s = fit_planar_ph_spline(wp, np.stack((-np.sin(a), np.cos(a)), axis=1))
    assert s.n_segments == 12
    r = s.points(np.linspace(0, s.knots[-1], 2001))[:, :2]
    assert np.abs(np.linalg.norm(r, axis=1) - 1).max() < 1e-3  # a PH cubic arc is close to the circle
    assert abs(s.length - 2 * np.pi) < 1e-3


def test_three_d_waypoints_at_constant_height():
    wp = np.array([[0, 0, 0.7], [1, 0.5, 0.7], [2, 0.2, 0.7], [3, 1.0, 0.7]])
    s = fit_planar_ph_spline(wp)
    assert s.z == 0.7
    _check_path(s, wp, 0.7)


def test_straight_waypoints():
    wp = np.array([[0, 0], [1, 1], [2.5, 2.5]], float)
    s = fit_planar_ph_spline(wp)
    r = s.points(np.linspace(0, s.knots[-1], 50))
    assert np.abs(r[:, 0] - r[:, 1]).max() < 1e-12
    assert np.isclose(s.length, 2.5 * np.sqrt(2))


# -- bad input -------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "wp, kw, msg",
    [
        ([[0, 0]], {}, "at least 2 waypoints"),
        ([[0, 0, 0], [1, 0, 0], [2, 1, 0.5]], {}, "waypoint 2: z = 0.5 differs"),
        ([[0, 0], [1, 1], [1, 1]], {}, "waypoint 2: duplicates waypoint 1"),
        ([[0, 0], [np.nan, 1]], {}, "waypoint 1: coordinates must be finite"),
        ([[0, 0], [1, 1]], {"tangents": [[1, 0]]}, "got 1 tangents for 2 waypoints"),
        ([[0, 0], [1, 1]], {"tangents": [[1, 0], [0, 0]]}, "waypoint 1: tangent is the zero vector"),
        ([[0, 0], [1, 1]], {"tangents": [[1, 0, 0], [1, 0, 1]]}, "waypoint 1: tangent .* leaves the plane"),
        ([[0, 0, 0, 0], [1, 1, 1, 1]], {}, "3 coordinates"),
        ([[0, 0], [1, 1]], {"z": np.inf}, "z must be finite"),
    ],
)
def test_bad_waypoints(wp, kw, msg):
    with pytest.raises(WaypointError, match=msg):
        fit_planar_ph_spline(wp, **kw)


def test_bad_evaluation_arguments():
    s = fit_planar_ph_spline([[0, 0], [1, 0.5], [2, 0]])
    with pytest.raises(PlannerError, match=r"u\[1\] = 9.0 is outside"):
        s.points([0.0, 9.0])
    with pytest.raises(PlannerError, match=r"s\[0\] = -1.0 is outside"):
        s.parameter_at_length([-1.0])
    with pytest.raises(PlannerError, match="max_depth"):
        fit_planar_ph_spline([[0, 0], [1, 0.5]], max_depth=-1)


def test_hairpin_is_refused_clearly():
    with pytest.raises((WaypointError, NoSolutionError), match="revers|hairpin"):
        fit_planar_ph_spline([[0, 1], [0, 0], [0, 2]])


def test_unsplittable_span_names_it():
    with pytest.raises(NoSolutionError, match="span from waypoint 0 to 1"):
        fit_planar_ph_spline([[0, 0], [3, 0]], [[1, 1], [1, 1]], max_depth=0)


def test_planar_spline_is_a_first_class_path_for_the_planner():
    from planner.frames import frame_field

    th = np.linspace(0, 2.5, 12)
    p = np.c_[np.cos(th), 0.5 * np.sin(2 * th), np.full(12, 0.3)]
    planar = fit_planar_ph_spline(p)
    path = planar.to_ph_spline()
    u = np.linspace(0, path.knots[-1], 400)
    assert np.abs(path.points(u) - planar.points(u)).max() < 1e-14
    assert path.length == pytest.approx(planar.length, rel=1e-14)
    assert path.interpolation_errors(p).max() < 1e-14
    F = frame_field(path, "rmf").frames(u)  # the RMF of a planar curve keeps the plane normal
    assert np.abs(np.abs(F[:, 2, 2]) - 1.0).max() < 1e-12
