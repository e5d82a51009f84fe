"""Frames along whole paths: continuity across segments, closed paths, prescribed rolls, tool axes."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from planner.curves import fit_ph_cubic_spline, fit_ph_spline
from planner.errors import PlannerError, WaypointError
from planner.frames.metrics import angular_velocity, max_twist_deg, twist_angles
from planner.frames.path import frame_field
from planner.frames.tool import ToolAxisWarning, tool_frames

RNG = np.random.default_rng(11)
WAYPOINTS = np.cumsum(RNG.normal(size=(10, 3)), axis=0)
PATH = fit_ph_spline(WAYPOINTS)


def interior(path, per=15):
    """Parameters strictly inside the segments (finite differences must not straddle a joint)."""
    return (path.knots[:-1, None] + np.diff(path.knots)[:, None] * np.linspace(0.05, 0.95, per)).ravel()


@pytest.mark.parametrize("method", ["rmf", "er", "grm"])
def test_frames_are_continuous_across_segments(method):
    f = frame_field(PATH, method)
    k = PATH.knots[1:-1]
    left = f.frames(k - 1e-9 * np.diff(PATH.knots)[:-1])
    right = f.frames(k)
    assert np.abs(left - right).max() < 1e-7
    F = f.frames(np.linspace(0, PATH.knots[-1], 500))
    assert np.abs(np.einsum("nji,njk->nik", F, F) - np.eye(3)).max() < 1e-14


def test_path_rmf_is_rotation_minimizing_everywhere():
    f = frame_field(PATH, "rmf")
    u = interior(PATH)
    w = angular_velocity(f.frames, u)
    along = np.abs(np.einsum("ni,ni->n", w, PATH.tangent(u)))
    assert (along <= 1e-9 * np.linalg.norm(w, axis=1)).all()


def test_rmf_on_a_ph_cubic_spline_is_rotation_minimizing():
    cubic = fit_ph_cubic_spline(WAYPOINTS)
    f = frame_field(cubic, "rmf")
    u = interior(cubic)
    w = angular_velocity(f.frames, u)
    assert (np.abs(np.einsum("ni,ni->n", w, cubic.tangent(u))) <= 1e-9 * np.linalg.norm(w, axis=1)).all()


def test_grm_path_twist_equals_per_segment_figures_when_small():
    smooth = fit_ph_spline(np.c_[np.cos(np.linspace(0, 3, 12)), np.sin(np.linspace(0, 3, 12)), np.linspace(0, 1, 12)])
    g = frame_field(smooth, "grm")
    r = frame_field(smooth, "rmf")
    u = np.linspace(0, smooth.knots[-1], 3001)
    total = max_twist_deg(g.frames(u), r.frames(u))
    assert total < 0.5
    assert total <= sum(s.max_twist_deg for s in g.grm_frames) + 1e-6


def test_start_frame_is_used():
    F0 = frame_field(PATH, "rmf").frames([0.0])[0]
    c, s = np.cos(0.4), np.sin(0.4)
    start = F0 @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    f = frame_field(PATH, "rmf", start=start)
    assert np.abs(f.frames([0.0])[0] - start).max() < 1e-15
    u = np.linspace(0, PATH.knots[-1], 50)
    assert np.allclose(twist_angles(f.frames(u), frame_field(PATH, "rmf").frames(u)), 0.4, atol=1e-12)


def test_closed_path_spreads_the_closing_twist_evenly():
    th = np.linspace(0, 2 * np.pi, 31)
    p = np.c_[np.cos(th), np.sin(th), 0.3 * np.sin(2 * th)]
    p[-1] = p[0]
    tang = np.c_[-np.sin(th), np.cos(th), 0.6 * np.cos(2 * th)]
    path = fit_ph_spline(p, tang, continuity="C1")
    base = frame_field(path, "rmf")
    closed = frame_field(path, "rmf", closed=True)
    ends = closed.frames(path.knots[[0, -1]])
    assert np.abs(ends[0] - ends[1]).max() < 1e-12
    u = np.linspace(0, path.knots[-1], 400)
    extra = np.unwrap(twist_angles(closed.frames(u), base.frames(u)))
    s = path.arc_length(u)
    assert np.allclose(extra, extra[-1] * s / path.length, atol=1e-12)  # linear in arc length
    assert abs(extra[-1]) <= np.pi


def test_prescribed_rolls_are_met_with_uniform_twist_between_them():
    targets = {0: np.array([0, 0, 1.0]), 4: np.array([1.0, 0, 0]), 9: np.array([0, 1.0, 0])}
    f = frame_field(PATH, "rmf", prescribed=targets)
    F = f.frames(PATH.waypoint_knots[list(targets)])
    for j, v in enumerate(targets.values()):
        t = F[j, :, 0]
        w = v - (v @ t) * t
        assert np.linalg.norm(F[j, :, 1] - w / np.linalg.norm(w)) < 1e-12
    # between prescriptions the extra twist rate is constant and at most pi per interval
    base = frame_field(PATH, "rmf")
    u = np.linspace(PATH.waypoint_knots[4], PATH.waypoint_knots[9], 200)
    extra = np.unwrap(twist_angles(f.frames(u), base.frames(u)))
    s = PATH.arc_length(u)
    rate = np.diff(extra) / np.diff(s)
    assert np.allclose(rate, rate[0], rtol=1e-9, atol=1e-12)
    assert abs(extra[-1] - extra[0]) <= np.pi + 1e-12


def test_juttler_and_double_reflection_on_whole_paths():
    cubic = fit_ph_cubic_spline(WAYPOINTS)
    u = np.linspace(0, cubic.knots[-1], 4001)
    exact = frame_field(cubic, "rmf").frames(u)
    jut = frame_field(cubic, "juttler").frames(u)
    assert np.abs(np.einsum("nji,njk->nik", jut, jut) - np.eye(3)).max() < 1e-12
    assert np.abs(jut[:, :, 0] - cubic.tangent(u)).max() < 1e-12
    assert max_twist_deg(jut, exact) < 2.0  # rational approximation; exact at the start
    k = cubic.knots[1:-1]  # C0 at the joints
    field = frame_field(cubic, "juttler")
    assert np.abs(field.frames(k - 1e-10) - field.frames(k)).max() < 1e-6
    dr = frame_field(PATH, "double-reflection")
    u = np.linspace(0, PATH.knots[-1], 20001)
    assert max_twist_deg(dr.frames(u), frame_field(PATH, "rmf").frames(u)) < 1e-6
    assert np.abs(dr.frames(u[::-1])[::-1] - dr.frames(u)).max() < 1e-12  # order of the samples is irrelevant


def test_path_frame_errors():
    with pytest.raises(PlannerError, match="method must be one of"):
        frame_field(PATH, "frenet")
    with pytest.raises(PlannerError, match="no such waypoint"):
        frame_field(PATH, prescribed={12: [0, 0, 1]})
    with pytest.raises(PlannerError, match="parallel to the path tangent"):
        frame_field(PATH, prescribed={0: PATH.tangent([0.0])[0]})
    with pytest.raises(PlannerError, match="closed=True but the path ends"):
        frame_field(PATH, closed=True)
    with pytest.raises(PlannerError, match="needs a PH quintic spline"):
        frame_field(fit_ph_cubic_spline(WAYPOINTS), "grm")
    with pytest.raises(PlannerError, match="needs a G1 PH cubic spline"):
        frame_field(PATH, "juttler")


# -- tool axes given by the CAD data (tool_frames, deprecated: it keeps working for one release) -----------

_DEPRECATED = pytest.mark.filterwarnings("ignore:planner.frames.tool_frames is deprecated:DeprecationWarning")

TH = np.linspace(0, np.pi, 25)
SPRAY_PATH = fit_ph_spline(np.c_[np.cos(TH), np.sin(TH), 0.2 * TH])
AXES = -np.c_[np.cos(TH), np.sin(TH), 0.3 * np.sin(TH)]  # minus the (tilted) surface normal


@_DEPRECATED
@pytest.mark.parametrize("method", ["exact", "rational"])
def test_tool_frames_follow_the_axis_and_do_not_spin_about_it(method):
    tf = tool_frames(SPRAY_PATH, AXES, method)
    u = interior(SPRAY_PATH, 9)
    F = tf.frames(u)
    assert np.abs(np.einsum("nji,njk->nik", F, F) - np.eye(3)).max() < 1e-13
    z = tf.axis(u)
    tol = 1e-12 if method == "exact" else 2e-4
    assert np.linalg.norm(F[:, :, 2] - z, axis=1).max() < tol
    zw = tf.frames(SPRAY_PATH.waypoint_knots)[:, :, 2]
    unit = AXES / np.linalg.norm(AXES, axis=1, keepdims=True)
    assert np.linalg.norm(zw - unit, axis=1).max() < tol  # the CAD axes are met at the waypoints
    w = angular_velocity(tf.frames, u)
    spin = np.abs(np.einsum("ni,ni->n", w, F[:, :, 2])) / np.linalg.norm(w, axis=1)
    assert spin.max() < (1e-9 if method == "exact" else 1e-2)


@_DEPRECATED
def test_tool_frame_starts_along_the_direction_of_travel():
    F = tool_frames(SPRAY_PATH, AXES).frames(SPRAY_PATH.knots[:1])[0]
    t = SPRAY_PATH.tangent(SPRAY_PATH.knots[:1])[0]
    assert F[:, 0] @ t > 0.99 and abs(F[:, 0] @ F[:, 2]) < 1e-15


@_DEPRECATED
def test_axis_flip_is_an_error_naming_the_waypoint():
    flipped = AXES.copy()
    flipped[7:] *= -1
    with pytest.raises(WaypointError, match="waypoint 7: tool axis turns 1[0-9.]+ deg from waypoint 6"):
        tool_frames(SPRAY_PATH, flipped)


@_DEPRECATED
def test_axis_along_travel_warns_with_the_waypoint():
    axes = AXES.copy()
    axes[3] = SPRAY_PATH.tangent(SPRAY_PATH.waypoint_knots[3:4])[0]
    axes[2] = 0.5 * (axes[1] + axes[3])
    axes[4] = 0.5 * (axes[3] + axes[5])
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        tool_frames(SPRAY_PATH, axes)
    msgs = [str(r.message) for r in rec if issubclass(r.category, ToolAxisWarning)]
    assert any(m.startswith("waypoint 3: tool axis within") for m in msgs)
    assert any(issubclass(r.category, DeprecationWarning) and "planner.cam.axis_field" in str(r.message) for r in rec)


@_DEPRECATED
@pytest.mark.parametrize(
    "axes, match",
    [
        (AXES[:-1], "got 24 tangents for 25 waypoints"),
        (np.vstack((AXES[:5], [[0, 0, 0]], AXES[6:])), "waypoint 5: tangent is the zero vector"),
        (np.vstack((AXES[:2], [[np.nan, 0, 1]], AXES[3:])), "waypoint 2: tangent must be finite"),
    ],
)
def test_tool_axis_bad_input(axes, match):
    with pytest.raises(WaypointError, match=match):
        tool_frames(SPRAY_PATH, axes)
