"""Tolerance-bounded PH fitting of CAM passes (planner.cam.fidelity).

The deviation is checked independently of the fit's own measure: both polylines are sampled every
micrometre and compared with k-d trees in both directions (Hausdorff distance; the sampling adds at
most (0.5 um)^2 / (2 d) to a distance d, a few nanometres here).
"""

from __future__ import annotations

import io

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from planner.cam import CamInputError, fit_pass, fit_passes, split_passes
from planner.curves import fit_ph_spline
from planner.io import read_toolpath
from tests.cam_excerpts import NX_HEAD
from tests.conftest import waypoint_sets

TOL = 1e-5


def sample_polyline(P: np.ndarray, step: float) -> np.ndarray:
    seg = np.diff(P, axis=0)
    n = np.maximum(np.ceil(np.linalg.norm(seg, axis=1) / step).astype(int), 1)
    parts = [P[i] + np.linspace(0.0, 1.0, k, endpoint=False)[:, None] * seg[i] for i, k in enumerate(n)]
    return np.vstack(parts + [P[-1:]])


def hausdorff(path, P: np.ndarray, step: float) -> float:
    """Two-sided Hausdorff distance between a path and a polyline, both sampled every ``step``."""
    s = np.linspace(0.0, path.length, max(2, int(np.ceil(path.length / step)) + 1))
    A = path.points(path.parameter_at_length(s))
    B = sample_polyline(P, step)
    return max(cKDTree(B).query(A)[0].max(), cKDTree(A).query(B)[0].max())


def nx_first_pass() -> np.ndarray:
    """NX lines 14-53: a 90-degree arc (r = 16 mm, 13 chords), a straight run, another arc."""
    tp = read_toolpath(io.StringIO(NX_HEAD), format="apt")
    return split_passes(tp).passes[0].points


def test_straight_arc_straight_excerpt_within_tolerance():
    P = nx_first_pass()
    fit = fit_pass(P, TOL)
    # the linearised arcs' chords are 0.029 mm from the circle: a curve through the points that
    # followed the circle would be 3 tolerances away from the polyline; knots pull it onto the chords
    assert fit.knots_added > 0
    assert fit.max_deviation <= TOL
    measured = hausdorff(fit.path, P, 1e-6)
    assert measured <= TOL + 1e-8
    assert fit.max_deviation == pytest.approx(measured, abs=2e-7)
    assert fit.path.interpolation_errors(P).max() <= 1e-15
    assert fit.path.tangent_jumps().max() <= 1e-12  # C1 across the inserted knots too
    # a spline forced through the same points overshoots past the straight run by 0.117 mm
    forced = fit_ph_spline(P, continuity="C1")
    assert hausdorff(forced, P, 1e-5) > 10 * TOL


def test_straight_run_is_exactly_straight_and_never_overshot():
    P = nx_first_pass()
    path = fit_pass(P, TOL).path
    # the run: CAM points 13..22 (lines 29-39) on the line z = 0.240 m, x = const
    k0, k1 = path.waypoint_knots[13], path.waypoint_knots[22]
    on_run = path.points(np.linspace(k0, k1, 20001))
    assert np.abs(on_run[:, 2] - 0.240).max() <= 1e-15
    assert np.abs(on_run[:, 1] - P[13, 1]).max() <= 1e-14  # round-off of coordinates near 1.2 m
    # the arcs join the run tangentially from above: the path never dips below the line
    everywhere = path.points(np.linspace(0.0, path.knots[-1], 200001))
    assert everywhere[:, 2].min() >= 0.240 - 1e-15
    assert np.allclose(path.tangent(np.array([k0, k1])), [[-1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]], atol=1e-12)


def test_collinear_points_give_the_line_without_knots():
    P = np.array([[0.0, 0.0, 0.0], [0.01, 0.02, 0.0], [0.015, 0.03, 0.0], [0.05, 0.1, 0.0]]) + [0.1, 0.2, 0.3]
    fit = fit_pass(P, TOL)
    assert fit.knots_added == 0 and fit.straight_chords == 3
    assert fit.max_deviation <= 1e-15
    assert fit.path.length == pytest.approx(np.linalg.norm(P[-1] - P[0]), rel=1e-14)


def test_finely_linearised_circle_keeps_circle_tangents():
    r, n = 0.02, 60
    phi = np.linspace(0.0, np.pi, n)  # sagitta r (1 - cos(pi / 2 (n - 1))) = 7e-6 r << tolerance
    P = np.column_stack((r * np.cos(phi), r * np.sin(phi), np.zeros(n)))
    fit = fit_pass(P, TOL)
    assert fit.knots_added == 0
    tangents = fit.path.tangent(fit.path.waypoint_knots[1:-1])
    exact = np.column_stack((-np.sin(phi[1:-1]), np.cos(phi[1:-1]), np.zeros(n - 2)))
    assert np.abs(tangents - exact).max() <= 1e-12  # Bessel's estimate is exact for equal chords
    assert hausdorff(fit.path, P, 1e-6) <= TOL


@settings(max_examples=12, deadline=None)
@given(waypoint_sets(min_size=2, max_size=12), st.floats(min_value=1e-4, max_value=1e-2))
def test_random_polylines_within_tolerance(points, tolerance):
    P = points * 0.05  # steps of 2.5 to 100 mm
    fit = fit_pass(P, tolerance)
    assert fit.max_deviation <= tolerance
    assert hausdorff(fit.path, P, tolerance / 20) <= tolerance * 1.01
    assert fit.path.interpolation_errors(P).max() <= 1e-12


def test_several_passes_fitted_together_equal_one_by_one():
    P = nx_first_pass()
    Q = P[::-1][:20] + [0.0, 0.01, 0.0]
    both = fit_passes([P, Q], TOL)
    for fit, pts in zip(both, (P, Q), strict=True):
        alone = fit_pass(pts, TOL)
        assert np.array_equal(fit.path.knots, alone.path.knots)
        assert np.abs(fit.path.control_points - alone.path.control_points).max() <= 1e-15


@pytest.mark.parametrize(
    ("points", "tolerance", "message"),
    [
        ([[0, 0, 0], [1, 0, 0]], 0.0, "tolerance must be a positive length"),
        ([[0, 0, 0], [1, 0, 0]], float("nan"), "tolerance must be a positive length"),
        ([[0, 0, 0]], TOL, r"pass 0: needs at least two points"),
        ([[0, 0, 0], [1, 0, 0], [1, 0, 0]], TOL, "pass 0, point 2: equals the previous point"),
        ([[0, 0, 0], [1, np.nan, 0]], TOL, "pass 0, point 1: not finite"),
    ],
)
def test_bad_input_is_named(points, tolerance, message):
    with pytest.raises(CamInputError, match=message):
        fit_pass(np.array(points, dtype=float), tolerance)
