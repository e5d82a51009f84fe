"""Double reflection method (Wang, Jüttler, Zheng, Liu 2008) for sampled curves."""

from __future__ import annotations

import numpy as np
import pytest

from planner import quaternion as quat
from planner.errors import PlannerError
from planner.frames.double_reflection import double_reflection_frames
from planner.frames.ph_cubic_rmm import ph_cubic_rmm


def helix(s, a, c):
    """Points, unit tangents T, Frenet normals N and binormals B of r = (a cos s, a sin s, c s)."""
    w = np.hypot(a, c)
    pts = np.stack((a * np.cos(s), a * np.sin(s), c * s), axis=1)
    tan = np.stack((-a * np.sin(s), a * np.cos(s), np.full_like(s, c)), axis=1) / w
    nor = np.stack((-np.cos(s), -np.sin(s), 0 * s), axis=1)
    return pts, tan, nor, np.cross(tan, nor)


def wang_reference(x, t, r0):
    """Algorithm 1 of Wang et al. (2008), literally: sequential reflections of r."""
    r = [r0]
    for i in range(len(x) - 1):
        v1 = x[i + 1] - x[i]
        c1 = v1 @ v1
        r_l = r[-1] - (2 / c1) * (v1 @ r[-1]) * v1
        t_l = t[i] - (2 / c1) * (v1 @ t[i]) * v1
        v2 = t[i + 1] - t_l
        c2 = v2 @ v2
        r.append(r_l - (2 / c2) * (v2 @ r_l) * v2)
    return np.array(r)


def turn_against_frenet(f, nor, bi):
    """Angle of column 1 against N, positive from N towards B (about T), unwrapped."""
    return np.unwrap(np.arctan2(np.einsum("ij,ij->i", f[:, :, 1], bi), np.einsum("ij,ij->i", f[:, :, 1], nor)))


def test_converges_with_order_4_on_a_helix():
    a, c, turns = 2.0, 0.7, 2
    w = np.hypot(a, c)
    errors = []
    for n in (25, 50, 100, 200):
        s = np.linspace(0, 2 * np.pi * turns, n * turns + 1)
        pts, tan, nor, bi = helix(s, a, c)
        f = double_reflection_frames(pts, tan, np.column_stack((tan[0], nor[0], bi[0])))
        errors.append(np.abs(turn_against_frenet(f, nor, bi) - (-c / w) * s).max())
    orders = np.log2(np.array(errors[:-1]) / errors[1:])
    assert (np.abs(orders - 4.0) < 0.3).all()
    assert errors[-1] < 1e-8
    # per turn the RMF turns against the Frenet frame by -2 pi c / sqrt(a^2 + c^2)
    ang = turn_against_frenet(f, nor, bi)
    assert abs((ang[-1] - ang[0]) / turns - (-2 * np.pi * c / w)) < 1e-9


def test_agrees_with_the_sequential_algorithm_and_frames_are_orthonormal():
    rng = np.random.default_rng(1)
    s = np.sort(rng.uniform(0, 12, 3000))
    pts, tan, nor, bi = helix(s, 1.5, -0.4)
    pts += 0.01 * np.sin(np.outer(s, [3.0, 5.0, 7.0]))  # a general space curve, uneven steps
    tan = 3.0 * (tan + 0.01 * np.cos(np.outer(s, [3.0, 5.0, 7.0])) * [3.0, 5.0, 7.0] / np.hypot(1.5, 0.4))
    f = double_reflection_frames(pts, tan)
    unit = tan / np.linalg.norm(tan, axis=1, keepdims=True)
    ref = wang_reference(pts, unit, f[0][:, 1])
    assert np.abs(f[:, :, 1] - ref).max() < 1e-12
    assert np.abs(f[:, :, 0] - unit).max() < 1e-15
    assert np.abs(np.einsum("nji,njk->nik", f, f) - np.eye(3)).max() < 1e-12
    assert np.abs(np.linalg.det(f) - 1).max() < 1e-12


def test_start_frame_is_used_and_default_is_valid():
    pts, tan, nor, bi = helix(np.linspace(0, 3, 50), 1.0, 0.5)
    start = np.column_stack((tan[0], bi[0], -nor[0]))
    f = double_reflection_frames(pts, tan, start)
    assert np.abs(f[0] - start).max() < 1e-15
    g = double_reflection_frames(pts, tan)
    assert np.abs(g[:, :, 0] - tan).max() < 1e-15
    # the RMF is unique up to a constant spin: g = f rotated about the tangent by a constant angle
    rel = np.arctan2(np.einsum("ij,ij->i", g[:, :, 1], f[:, :, 2]), np.einsum("ij,ij->i", g[:, :, 1], f[:, :, 1]))
    assert np.abs(rel - rel[0]).max() < 1e-12


def test_matches_exact_rmf_of_a_ph_cubic():
    a0, a1 = np.array([1.0, 0.3, -0.2, 0.4]), np.array([0.2, 1.1, 0.5, -0.3])
    h = quat.sandwich(a0, quat.I, a0), quat.sym(a0, quat.I, a1), quat.sandwich(a1, quat.I, a1)
    exact = ph_cubic_rmm(*h).exact()
    t = np.linspace(0, 1, 2001)
    p = np.cumsum([np.zeros(3), h[0] / 3, h[1] / 3, h[2] / 3], axis=0)  # Bezier points of the PH cubic
    pts = np.stack([(1 - t) ** 3, 3 * t * (1 - t) ** 2, 3 * t**2 * (1 - t), t**3], axis=1) @ p
    e = exact.frames(t)
    f = double_reflection_frames(pts, e[:, :, 0], e[0])
    assert np.abs(f - e).max() < 1e-9


def test_repeated_points_are_handled():
    pts, tan, nor, bi = helix(np.linspace(0, 3, 200), 1.0, 0.5)
    pts2 = np.insert(pts, 50, pts[50], axis=0)
    tan2 = np.insert(tan, 50, tan[50], axis=0)
    start = np.column_stack((tan[0], nor[0], bi[0]))
    f, g = double_reflection_frames(pts, tan, start), double_reflection_frames(pts2, tan2, start)
    assert np.abs(np.delete(g, 50, axis=0) - f).max() < 1e-14


def test_bad_input_names_the_place():
    pts, tan, nor, bi = helix(np.linspace(0, 3, 20), 1.0, 0.5)
    with pytest.raises(PlannerError, match="tangents: has 19 rows but 20"):
        double_reflection_frames(pts, tan[:-1])
    bad = pts.copy()
    bad[4, 2] = np.nan
    with pytest.raises(PlannerError, match=r"points\[4\].*finite"):
        double_reflection_frames(bad, tan)
    bad = tan.copy()
    bad[7] = 0.0
    with pytest.raises(PlannerError, match=r"tangents\[7\].*zero"):
        double_reflection_frames(pts, bad)
    bad = tan.copy()
    v1 = (pts[11] - pts[10]) / np.linalg.norm(pts[11] - pts[10])
    bad[11] = tan[10] - 2 * (v1 @ tan[10]) * v1  # points back along the chord: H2 is undefined
    with pytest.raises(PlannerError, match=r"tangents\[11\].*reverses"):
        double_reflection_frames(pts, bad)
    with pytest.raises(PlannerError, match="at least 2"):
        double_reflection_frames(pts[:1], tan[:1])
    with pytest.raises(PlannerError, match="start.*orthonormal"):
        double_reflection_frames(pts, tan, 2 * np.column_stack((tan[0], nor[0], bi[0])))
    with pytest.raises(PlannerError, match="start.*column 0"):
        double_reflection_frames(pts, tan, np.column_stack((nor[0], bi[0], tan[0])))
    with pytest.raises(PlannerError, match=r"points: expected an array of shape \(n, 3\)"):
        double_reflection_frames(pts[:, :2], tan)
