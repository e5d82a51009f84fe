"""Jüttler's rational RMF of spatial PH cubics (seed juttler-..., section 7.1)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from planner import quaternion as quat
from planner.errors import PlannerError
from planner.frames.ph_cubic_rmm import ph_cubic_rmm, ph_cubic_spline_rmm, tangent_arcs
from planner.rotations import quaternion_to_matrix

T = np.linspace(0.0, 1.0, 1001)


def hodograph(a0, a1):
    """Control vectors of the hodograph A i A* of A(t) = (1 - t) A0 + t A1."""
    return quat.sandwich(a0, quat.I, a0), quat.sym(a0, quat.I, a1), quat.sandwich(a1, quat.I, a1)


def unit_tangent(h, t):
    hh = np.outer((1 - t) ** 2, h[0]) + np.outer(2 * t * (1 - t), h[1]) + np.outer(t * t, h[2])
    return hh / np.linalg.norm(hh, axis=1, keepdims=True)


def rotation_angle(a, b):
    r = np.einsum("nji,njk->nik", a, b)
    axis = np.stack((r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]), axis=1)
    return np.arctan2(0.5 * np.linalg.norm(axis, axis=1), 0.5 * (np.trace(r, axis1=1, axis2=2) - 1.0))


def ode_rmf(h, f0, t):
    """Reference RMF: parallel transport of the normal vectors, e' = (z x z') x e, DOP853."""
    def rhs(s, y):
        hh = (1 - s) ** 2 * h[0] + 2 * s * (1 - s) * h[1] + s * s * h[2]
        dh = 2 * ((1 - s) * (h[1] - h[0]) + s * (h[2] - h[1]))
        nh = np.linalg.norm(hh)
        z = hh / nh
        dz = (dh - z * (z @ dh)) / nh
        w = np.cross(z, dz)
        e = y.reshape(2, 3)
        return np.cross(w, e).ravel()

    sol = solve_ivp(rhs, (0.0, 1.0), f0[:, 1:].T.ravel(), method="DOP853", rtol=1e-13, atol=1e-14, t_eval=t)
    return sol.y.T.reshape(-1, 2, 3)


quaternions = st.lists(st.floats(-2, 2), min_size=4, max_size=4).map(np.array).filter(
    lambda q: np.linalg.norm(q) > 0.3)


@settings(max_examples=30, deadline=None)
@given(quaternions, quaternions)
def test_first_column_is_the_unit_tangent_and_exact_motion_is_rmf(a0, a1):
    h = hodograph(a0, a1)
    if np.dot(a0, a1) < -0.95 * np.linalg.norm(a0) * np.linalg.norm(a1):
        return  # near-cusp segments are rejected (tested below)
    motion = ph_cubic_rmm(*h)
    f, e = motion.frames(T), motion.exact().frames(T)
    z = unit_tangent(h, T)
    # the biarc of the tangent indicatrix is built from its end directions: for a nearly straight segment
    # (indicatrix arc phi -> 0) round-off is amplified like eps / phi
    phi = np.arccos(np.clip(z[0] @ z[-1], -1.0, 1.0))
    tol = 1e-12 + 16 * np.finfo(float).eps / max(phi, 1e-6)
    assert np.abs(f[:, :, 0] - z).max() < tol
    assert np.abs(e[:, :, 0] - z).max() < tol
    for frames in (f, e):
        assert np.abs(np.einsum("nji,njk->nik", frames, frames) - np.eye(3)).max() < 1e-12
        assert np.abs(np.linalg.det(frames) - 1).max() < 1e-12
    omega = motion.exact().angular_velocity(T)
    assert (np.abs(np.einsum("ij,ij->i", omega, z)) <= 1e-9 * np.linalg.norm(omega, axis=1) + 1e-13).all()
    assert rotation_angle(f[[0, -1]], e[[0, -1]]).max() < 1e-12  # seed eq. (18)
    # the quaternion polynomial is cubic and gives the frames
    assert motion.coeffs.shape == (4, 4)
    assert np.abs(quaternion_to_matrix(motion.quaternion(T)) - f).max() < 1e-15


def test_exact_rmf_matches_ode_reference():
    rng = np.random.default_rng(11)
    for _ in range(3):
        a0, a1 = rng.normal(size=(2, 4))
        h = hodograph(a0, a1)
        motion = ph_cubic_rmm(*h)
        t = np.linspace(0, 1, 11)
        ref = ode_rmf(np.array(h), motion.frames([0.0])[0], t)
        exact = motion.exact().frames(t)
        assert np.abs(exact[:, :, 1:].transpose(0, 2, 1) - ref).max() < 1e-10


def test_rational_twist_is_small_for_moderate_turning():
    # a segment whose tangent turns by about 97 degrees with |A1| / |A0| = 1.06
    a0 = np.array([1.0, 0.0, 0.0, 0.0])
    a1 = np.array([np.cos(np.pi / 4), 0.3, 0.2, np.sin(np.pi / 4)])
    h = hodograph(a0, a1)
    twist = {}
    for choice in ("paper", "reparameterized"):
        motion = ph_cubic_rmm(*h, r2_weights=choice)
        assert 1.2 < motion.phi < 2.0
        twist[choice] = np.degrees(rotation_angle(motion.frames(T), motion.exact().frames(T)).max())
    assert 1e-6 < twist["reparameterized"] < 0.02
    assert twist["paper"] > 2 * twist["reparameterized"]  # the seed's heuristic for R2 twists more


def test_start_frame_is_honoured_and_checked():
    rng = np.random.default_rng(2)
    h = hodograph(*rng.normal(size=(2, 4)))
    z0 = h[0] / np.linalg.norm(h[0])
    n = np.cross(z0, [0.3, -0.2, 0.9])
    n /= np.linalg.norm(n)
    start = np.column_stack((z0, n, np.cross(z0, n)))
    assert np.abs(ph_cubic_rmm(*h, start=start).frames([0.0])[0] - start).max() < 1e-14
    with pytest.raises(PlannerError, match="start.*column 0"):
        ph_cubic_rmm(*h, start=start[:, [1, 2, 0]])
    with pytest.raises(PlannerError, match="start.*orthonormal"):
        ph_cubic_rmm(*h, start=start * 1.001)


def test_bad_hodographs_are_rejected():
    h0, h1, h2 = hodograph(np.array([1.0, 0.2, -0.3, 0.5]), np.array([0.4, 1.0, 0.1, -0.2]))
    with pytest.raises(PlannerError, match="not the hodograph of a PH cubic"):
        ph_cubic_rmm(h0, h1 + [0.0, 0.05, 0.0], h2)
    with pytest.raises(PlannerError, match="h0.*zero"):
        ph_cubic_rmm(np.zeros(3), h1, h2)
    with pytest.raises(PlannerError, match="h1: is not finite"):
        ph_cubic_rmm(h0, [np.nan, 0, 0], h2)
    with pytest.raises(PlannerError, match="h2: expected a vector of shape"):
        ph_cubic_rmm(h0, h1, [1.0, 2.0])
    a0 = np.array([1.0, 0.2, -0.3, 0.5])
    with pytest.raises(PlannerError, match="cusp"):
        ph_cubic_rmm(*hodograph(a0, -2 * a0))


# ---------------------------------------------------------------------------------------------------
# G1 PH cubic splines
# ---------------------------------------------------------------------------------------------------
def g1_spline(rng, m):
    """Hodographs of m PH cubics with common tangent directions at the joints (A0' = lam A1 exp(i chi))."""
    hods, a0 = [], rng.normal(size=4)
    for _ in range(m):
        a1 = a0 + 0.6 * rng.normal(size=4)
        hods.append(hodograph(a0, a1))
        a0 = rng.uniform(0.5, 2.0) * quat.mul(a1, quat.exp_i(rng.uniform(-np.pi, np.pi)))
    return np.array(hods)


def test_spline_is_c0_and_agrees_with_segmentwise_construction():
    rng = np.random.default_rng(4)
    hods = g1_spline(rng, 6)
    knots = np.arange(7.0)
    chain = ph_cubic_spline_rmm(hods, knots)
    eps = 1e-11
    assert np.abs(chain.frames(knots[1:-1] - eps) - chain.frames(knots[1:-1] + eps)).max() < 1e-9
    assert np.abs(chain.quaternion(knots[1:-1] - eps) - chain.quaternion(knots[1:-1] + eps)).max() < 1e-9
    prev = None
    for k in range(6):
        start = None if prev is None else prev.frames([1.0])[0]
        seg = ph_cubic_rmm(*hods[k], start=start)
        assert np.abs(seg.frames(T) - chain.frames(k + T)).max() < 1e-11
        assert np.abs(chain.frames(k + T)[:, :, 0] - unit_tangent(hods[k], T)).max() < 1e-12
        prev = seg


def test_spline_rejects_corner_and_names_segment():
    rng = np.random.default_rng(6)
    hods = g1_spline(rng, 4)
    hods[2] = hodograph(*rng.normal(size=(2, 4)))  # tangent jumps at the joint 1|2
    with pytest.raises(PlannerError, match=r"arcs\[2\]"):
        ph_cubic_spline_rmm(hods)
    hods = g1_spline(rng, 4)
    hods[3, 1] += 0.1
    with pytest.raises(PlannerError, match=r"hodographs\[3\]"):
        tangent_arcs(hods)
