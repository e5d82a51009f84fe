"""Spherical biarc approximation (seed juttler-..., section 5) and the RMM along it."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from planner.errors import ConvergenceError, PlannerError
from planner.frames.spherical_arc import geodesic_distance, rotate
from planner.frames.spherical_biarc import biarcs, fit_spherical_biarcs, sample_tangents


def curve(t):
    a = 0.3 + 2.5 * t
    b = 4 * t + np.sin(3 * t)
    return np.stack((np.sin(a) * np.cos(b), np.sin(a) * np.sin(b), np.cos(a)), axis=1)


def dcurve(t):
    a, da = 0.3 + 2.5 * t, 2.5
    b, db = 4 * t + np.sin(3 * t), 4 + 3 * np.cos(3 * t)
    return np.stack((np.cos(a) * np.cos(b) * da - np.sin(a) * np.sin(b) * db,
                     np.cos(a) * np.sin(b) * da + np.sin(a) * np.cos(b) * db, -np.sin(a) * da), axis=1)


def distance_to_chain(spline, x, t):
    """Great-circle distance of points x (n, 3) at parameters t to the chain: exact distance to the
    arcs near t, an upper bound of the distance to the whole chain."""
    m = len(spline.arcs)
    idx = np.clip(np.searchsorted(spline.knots, t, side="right") - 1, 0, m - 1)
    return np.min([spline.arcs.distance(np.clip(idx + k, 0, m - 1), x) for k in range(-3, 4)], axis=0)


def distance_to_polyline(x, poly):
    """Chordal distance of points x (n, 3) to a dense polyline (the two segments at the nearest vertex)."""
    near = np.clip(cKDTree(poly).query(x)[1], 1, poly.shape[0] - 2)
    best = np.full(x.shape[0], np.inf)
    for a, b in ((poly[near - 1], poly[near]), (poly[near], poly[near + 1])):
        d = b - a
        s = np.clip(np.einsum("ij,ij->i", x - a, d) / np.einsum("ij,ij->i", d, d), 0, 1)
        best = np.minimum(best, np.linalg.norm(x - a - s[:, None] * d, axis=1))
    return best


def assert_g1_chain(spline, tol=1e-10):
    arcs = spline.arcs
    m = len(arcs)
    assert np.abs(arcs.end[:-1] - arcs.start[1:]).max() < tol
    t_end = arcs.tangent(np.arange(m), arcs.angle)
    t_start = arcs.tangent(np.arange(m), np.zeros(m))
    assert np.abs(t_end[:-1] - t_start[1:]).max() < tol


@pytest.mark.parametrize("tol", [1e-2, 1e-4, 1e-6, 1e-8])
def test_callable_meets_tolerance_both_ways(tol):
    spline = fit_spherical_biarcs(curve, tol, dz=dcurve)
    assert spline.max_error <= tol
    assert len(spline.arcs) % 2 == 0
    dense_t = np.linspace(0, 1, 4001)
    assert distance_to_chain(spline, curve(dense_t), dense_t).max() <= tol
    # the other way: chain points are within tol of the curve (dense polyline of the curve)
    chain_pts = spline.points(np.linspace(0, 1, 1501))
    poly = curve(np.linspace(0, 1, 40001))
    assert distance_to_polyline(chain_pts, poly).max() <= tol + 1e-9
    assert_g1_chain(spline)
    # the chain is parameterized to follow z: the point at t is near z(t), not only near the curve
    assert geodesic_distance(spline.points(dense_t), curve(dense_t)).max() <= 3 * tol
    # Hermite data: the chain interpolates z and the direction of z' at the even knots
    th = spline.hermite_knots
    assert np.abs(spline.arcs.start[::2] - curve(th[:-1])).max() < 1e-14
    d = dcurve(th[:-1])
    d -= np.einsum("ij,ij->i", d, curve(th[:-1]))[:, None] * curve(th[:-1])
    tangents = spline.arcs.tangent(np.arange(0, len(spline.arcs), 2), np.zeros(len(spline.arcs) // 2))
    assert np.abs(tangents - d / np.linalg.norm(d, axis=1, keepdims=True)).max() < 1e-12


def test_finite_difference_tangents_and_arc_count_order():
    counts = [len(fit_spherical_biarcs(curve, tol).arcs) for tol in (1e-4, 1e-6)]
    # biarcs approximate with error O(h^3): 100x smaller tolerance needs about 100^(1/3) = 4.6x more arcs
    assert 3.0 < counts[1] / counts[0] < 7.0


def test_sampled_input_meets_tolerance_on_samples():
    ts = np.linspace(0, 1, 3000) ** 1.3
    z = curve(ts)
    spline = fit_spherical_biarcs(z, 1e-6, t=ts)
    assert spline.max_error <= 1e-6
    assert distance_to_chain(spline, z, ts).max() <= 1e-6
    assert set(spline.hermite_knots) <= set(ts)
    assert_g1_chain(spline)


def test_circle_samples_give_arcs_of_that_circle():
    axis = np.array([0.3, -0.4, 0.866])
    axis /= np.linalg.norm(axis)
    start = np.cross(axis, [1.0, 0, 0])
    start = 0.6 * start / np.linalg.norm(start) + 0.8 * axis
    ang = np.linspace(0, 2.5, 200)
    z = rotate(np.tile(axis, (200, 1)), ang, np.tile(start, (200, 1)))
    tangents = sample_tangents(z)
    exact = np.cross(axis, z)
    assert np.abs(tangents - exact / np.linalg.norm(exact, axis=1, keepdims=True)).max() < 1e-10
    spline = fit_spherical_biarcs(z, 1e-9)
    assert np.abs(spline.arcs.axis - axis).max() < 1e-8
    assert spline.max_error < 1e-12


def test_biarc_end_tangent_is_g1():
    rng = np.random.default_rng(0)
    p0, p1 = rng.normal(size=(2, 50, 3))
    p0 /= np.linalg.norm(p0, axis=1, keepdims=True)
    p1 = p0 + 0.5 * p1
    p1 /= np.linalg.norm(p1, axis=1, keepdims=True)
    t0, t1 = (np.cross(p, rng.normal(size=(50, 3))) for p in (p0, p1))
    t0 /= np.linalg.norm(t0, axis=1, keepdims=True)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    first, second, ok = biarcs(p0, t0, p1, t1)
    k = np.flatnonzero(ok)
    assert k.size > 25
    assert np.abs(second.end[k] - p1[k]).max() < 1e-11
    end_tangent = second.tangent(k, second.angle[k])
    assert np.abs(end_tangent - t1[k]).max() < 1e-9  # stereographic projection is conformal
    mid_out = first.tangent(k, first.angle[k])
    assert np.abs(mid_out - second.tangent(k, np.zeros(k.size))).max() < 1e-12


def test_rmm_along_biarcs_is_c0_and_converges_to_exact():
    twists = []
    for tol in (1e-3, 1e-4):
        spline = fit_spherical_biarcs(curve, tol, dz=dcurve)
        motion = spline.rmm()
        knots = spline.knots
        eps = 1e-12
        assert np.abs(motion.frames(knots[1:-1] - eps) - motion.frames(knots[1:-1] + eps)).max() < 1e-9
        assert np.abs(motion.quaternion(knots[1:-1] - eps) - motion.quaternion(knots[1:-1] + eps)).max() < 1e-9
        t = np.linspace(0, 1, 3001)
        f = motion.frames(t)
        assert np.abs(np.einsum("nji,njk->nik", f, f) - np.eye(3)).max() < 1e-12
        assert np.abs(f[:, :, 2] - spline.points(t)).max() < 1e-14
        e = spline.rmm(exact=True).frames(t)
        r = np.einsum("nji,njk->nik", e, f)
        twists.append(np.abs(np.arctan2(r[:, 1, 0] - r[:, 0, 1], r[:, 0, 0] + r[:, 1, 1])).max())
    assert twists[1] < twists[0] / 4


def test_bad_input_names_the_place():
    z = curve(np.linspace(0, 1, 50))
    bad = z.copy()
    bad[7] *= 1.01
    with pytest.raises(PlannerError, match=r"z\[7\].*unit"):
        fit_spherical_biarcs(bad)
    bad = z.copy()
    bad[9, 1] = np.nan
    with pytest.raises(PlannerError, match=r"z\[9\].*finite"):
        fit_spherical_biarcs(bad)
    t = np.linspace(0, 1, 50)
    t[12] = t[11]
    with pytest.raises(PlannerError, match=r"t\[12\]"):
        fit_spherical_biarcs(z, t=t)
    with pytest.raises(PlannerError, match="t: must have shape"):
        fit_spherical_biarcs(z, t=np.linspace(0, 1, 49))
    with pytest.raises(PlannerError, match="tol"):
        fit_spherical_biarcs(z, 0.0)
    with pytest.raises(PlannerError, match="at least 2"):
        fit_spherical_biarcs(z[:1])
    with pytest.raises(PlannerError, match=r"z\(t\) at t = .*unit"):
        fit_spherical_biarcs(lambda t: 2 * curve(t))
    with pytest.raises(PlannerError, match="interval"):
        fit_spherical_biarcs(curve, interval=(1.0, 0.0))


def test_corner_cannot_meet_tolerance():
    def corner(t):
        a = np.where(t < 0.5, t, 0.5) + 0.3
        b = np.where(t < 0.5, 0.0, t - 0.5)
        return np.stack((np.sin(a) * np.cos(b), np.sin(a) * np.sin(b), np.cos(a)), axis=1)

    with pytest.raises(ConvergenceError, match="near t = 0.5"):
        fit_spherical_biarcs(corner, 1e-9, interval=(0.0, 1.0))
    assert geodesic_distance(corner(np.array([0.0])), corner(np.array([1.0])))[0] > 0
