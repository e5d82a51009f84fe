"""Jüttler's RMM of circular arcs (seed juttler-rotation-minimizing-spherical-motions.md, eqs. 9-18)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planner.errors import PlannerError
from planner.frames.juttler import arc_motion, exact_arc_motion, rational_coefficients, rmm_arc
from planner.frames.piecewise_motion import chain_arc_motion
from planner.frames.spherical_arc import SphericalArcs, rotate

T = np.linspace(0.0, 1.0, 2001)

phis = st.floats(0.05, 3.0) | st.floats(-3.0, -0.05)
psis = st.floats(0.0, np.pi)
weights = st.floats(0.3, 3.0)
rhos = st.floats(-7.0, 7.0)


def rotation_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (rad) of the rotation taking frames a (n, 3, 3) to frames b, accurate near 0."""
    r = np.einsum("nji,njk->nik", a, b)
    axis = np.stack((r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]), axis=1)
    return np.arctan2(0.5 * np.linalg.norm(axis, axis=1), 0.5 * (np.trace(r, axis1=1, axis2=2) - 1.0))


def fd_angular_velocity(motion, t: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Angular velocity from central differences of the frames: skew(F' F^T)."""
    w = np.einsum("nij,nkj->nik", (motion.frames(t + h) - motion.frames(t - h)) / (2 * h), motion.frames(t))
    return np.stack((w[:, 2, 1], w[:, 0, 2], w[:, 1, 0]), axis=1)


def assert_frames(f: np.ndarray, tol: float = 1e-12) -> None:
    assert np.abs(np.einsum("nji,njk->nik", f, f) - np.eye(3)).max() < tol
    assert np.abs(np.linalg.det(f) - 1.0).max() < tol


def angle_to_axis_deg(motion, t):
    w, z = motion.angular_velocity(t), motion.axis(t)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(w, z), axis=1), np.einsum("ij,ij->i", w, z)))


# ---------------------------------------------------------------------------------------------------
# The paper's figure 2
# ---------------------------------------------------------------------------------------------------
def test_figure2_angle_between_angular_velocity_and_axis():
    motion = rmm_arc(np.radians(94.7), np.radians(81.3), w0=1.0, w1=1.0)
    ang = angle_to_axis_deg(motion, T)
    assert np.abs(ang - 90.0).max() <= 0.05  # seed: 89.966 .. 90.026 for its weights
    assert abs(ang[0] - 90.0) < 1e-12 and abs(ang[-1] - 90.0) < 1e-12  # property 3 of section 6
    assert np.abs(ang - 90.0).max() > 1e-3  # the rational motion is not the exact RMM inside


def test_exact_motion_is_rotation_minimizing_and_matches_eq_11():
    for w in (None, 1.0):
        motion = exact_arc_motion(np.radians(94.7), np.radians(81.3), rho=0.4, w0=w, w1=w)
        omega = motion.angular_velocity(T)
        z = motion.axis(T)
        assert (np.abs(np.einsum("ij,ij->i", omega, z)) <= 1e-9 * np.linalg.norm(omega, axis=1)).all()
        tt = np.linspace(0.01, 0.99, 9)
        assert np.abs(fd_angular_velocity(motion, tt) - motion.angular_velocity(tt)).max() < 1e-7
        assert_frames(motion.frames(T))


def test_exact_uniform_motion_traces_eq_9():
    phi, psi = 2.1, 0.7
    c = np.stack((np.sin(psi) * np.cos(T * phi), np.sin(psi) * np.sin(T * phi), np.full_like(T, np.cos(psi))), 1)
    motion = exact_arc_motion(phi, psi)
    assert np.abs(motion.axis(T) - c).max() < 1e-14
    omega_is_c_cross_dc = np.cross(c, phi * np.stack((-c[:, 1], c[:, 0], 0 * T), 1))  # Prop. 1, eq. (5)
    assert np.abs(motion.angular_velocity(T) - omega_is_c_cross_dc).max() < 1e-14


# ---------------------------------------------------------------------------------------------------
# Properties of the rational approximation (section 6)
# ---------------------------------------------------------------------------------------------------
@settings(max_examples=40, deadline=None)
@given(phis, psis, weights, weights, rhos)
def test_rational_end_positions_eq_18(phi, psi, w0, w1, rho):
    motion = rmm_arc(phi, psi, w0, w1, rho)
    exact = exact_arc_motion(phi, psi, rho)
    r, q = motion.quaternion([0.0, 1.0]), exact.quaternion([0.0, 1.0])
    assert np.abs(r[0] - w0**2 * q[0]).max() < 1e-12 * w0**2
    assert np.abs(r[1] - w1**2 * q[1]).max() < 1e-12 * w1**2


@settings(max_examples=40, deadline=None)
@given(phis, psis, weights, weights, rhos)
def test_rational_ends_are_rotation_minimizing_property_3(phi, psi, w0, w1, rho):
    motion = rmm_arc(phi, psi, w0, w1, rho)
    ends = np.array([0.0, 1.0])
    omega, z = motion.angular_velocity(ends), motion.axis(ends)
    scale = np.linalg.norm(omega, axis=1) + abs(phi)  # |omega| vanishes on a point arc (psi = 0)
    assert (np.abs(np.einsum("ij,ij->i", omega, z)) <= 1e-12 * scale).all()
    # and there omega equals the exact angular velocity c x c' (same parameterization)
    assert np.abs(omega - motion.exact().angular_velocity(ends)).max() < 1e-12 * (1 + np.abs(omega).max())


@settings(max_examples=40, deadline=None)
@given(phis, psis, weights, weights, rhos)
def test_rational_axis_is_the_rational_circle_eq_16_17(phi, psi, w0, w1, rho):
    motion = rmm_arc(phi, psi, w0, w1, rho)
    sp, cp = np.sin(psi), np.cos(psi)
    b = np.array([[sp, 0, cp], [sp, np.tan(phi / 2) * sp, cp], [sp * np.cos(phi), sp * np.sin(phi), cp]])  # (17)
    r = np.array([w0**2, w0 * w1 * np.cos(phi / 2), w1**2])  # eq. (17)
    basis = np.stack(((1 - T) ** 2, 2 * T * (1 - T), T**2), axis=1)
    c_star = (basis * r) @ b / (basis @ r)[:, None]  # eq. (16)
    assert np.abs(motion.axis(T) - c_star).max() < 1e-12
    assert np.abs(motion.exact().axis(T) - c_star).max() < 1e-12
    assert_frames(motion.frames(T))


@settings(max_examples=25, deadline=None)
@given(phis, psis, rhos)
def test_footnote_2_rho_is_a_constant_spin(phi, psi, rho):
    base, spun = rmm_arc(phi, psi, 1.3, 0.8, 0.0), rmm_arc(phi, psi, 1.3, 0.8, rho)
    rz = np.array([[np.cos(rho), np.sin(rho), 0], [-np.sin(rho), np.cos(rho), 0], [0, 0, 1]])  # Rz(-rho)
    assert np.abs(base.frames(T) @ rz - spun.frames(T)).max() < 1e-12


@settings(max_examples=25, deadline=None)
@given(st.floats(0.1, 2.5), psis, weights, weights)
def test_reparameterized_r2_is_the_unit_weight_motion_reparameterized(phi, psi, w0, w1):
    unit = rmm_arc(phi, psi)
    motion = rmm_arc(phi, psi, w0, w1, r2_weights="reparameterized")
    s = T * w1 / ((1 - T) * w0 + T * w1)  # Moebius reparameterization taking R1(w0, w1) to R1(1, 1)
    assert np.abs(motion.frames(T) - unit.frames(s)).max() < 1e-12
    paper = rmm_arc(phi, psi, w0, w1)
    ends = np.array([0.0, 1.0])
    for m in (motion, paper):  # both satisfy eq. (18) and property 3
        omega = m.angular_velocity(ends)
        assert np.abs(np.einsum("ij,ij->i", omega, m.axis(ends))).max() <= 1e-12 * (1 + np.abs(omega).max())
        assert rotation_angle(m.frames(ends), m.exact().frames(ends)).max() < 1e-12
    # the twist against the exact RMM does not depend on the weights, and is never worse than the paper's
    tw_unit = rotation_angle(unit.frames(T), unit.exact().frames(T)).max()
    tw = rotation_angle(motion.frames(T), motion.exact().frames(T)).max()
    assert abs(tw - tw_unit) <= 1e-3 * tw_unit + 1e-13
    assert tw <= rotation_angle(paper.frames(T), paper.exact().frames(T)).max() * (1 + 1e-3) + 1e-13


def test_r1_r2_degrees_and_product():
    r1, r2 = rational_coefficients(1.2, 0.9, 1.0, 1.0, 0.0)
    assert r1.shape == (2, 4) and r2.shape == (3, 4)
    assert rmm_arc(1.2, 0.9).coeffs.shape == (4, 4)  # R = R1 R2 is cubic: a rational motion of degree 6


def test_great_circle_is_exact():
    # psi = pi/2: no spin is needed (theta = 0), eq. (15) has a 0/0 that the sinc form resolves
    motion = rmm_arc(2.0, np.pi / 2, 1.2, 0.7, 0.3)
    assert np.isfinite(motion.coeffs).all()
    assert rotation_angle(motion.frames(T), motion.exact().frames(T)).max() < 1e-13


def test_point_arc_is_constant():
    motion = rmm_arc(1.0, 0.0, 1.0, 1.0, 0.2)
    f = motion.frames(T)
    assert np.abs(f - f[0]).max() < 1e-14


def test_twist_against_exact_converges_with_order_5_in_the_arc_angle():
    psi = np.radians(81.3)
    errs = [rotation_angle(m.frames(T), m.exact().frames(T)).max()
            for m in (rmm_arc(phi, psi) for phi in (1.6, 0.8, 0.4))]
    orders = np.log2(np.array(errs[:-1]) / errs[1:])
    assert (orders > 4.5).all() and (orders < 5.5).all()
    assert errs[0] < np.radians(0.02)


# ---------------------------------------------------------------------------------------------------
# Helix: the RMF turns against the Frenet frame by -2 pi c / sqrt(a^2 + c^2) per turn
# ---------------------------------------------------------------------------------------------------
def helix_frenet(s, a, c):
    w = np.hypot(a, c)
    tan = np.stack((-a * np.sin(s), a * np.cos(s), np.full_like(s, c)), 1) / w
    nor = np.stack((-np.cos(s), -np.sin(s), 0 * s), 1)
    return tan, nor, np.cross(tan, nor)


@pytest.mark.parametrize("a, c", [(2.0, 0.7), (1.0, -0.4), (0.5, 3.0)])
def test_helix_turn_angle(a, c):
    # The helix tangent turns about e3 on the circle psi = arccos(c / w). Sign convention: the angle
    # of the RMF normal against the Frenet normal N, positive from N towards B (about T).
    w = np.hypot(a, c)
    tan0 = helix_frenet(np.zeros(1), a, c)[0][0]
    quarter = 4
    starts = rotate(np.tile([0.0, 0, 1], (quarter, 1)), np.arange(quarter) * 2 * np.pi / quarter,
                    np.tile(tan0, (quarter, 1)))
    arcs = SphericalArcs(starts, np.tile([0.0, 0, 1], (quarter, 1)), np.full(quarter, 2 * np.pi / quarter),
                         np.full(quarter, np.arccos(c / w)))
    _, n0, b0 = helix_frenet(np.zeros(1), a, c)
    start = np.column_stack((tan0, n0[0], b0[0]))  # RMF = Frenet at s = 0
    for rational in (True, False):
        chain = chain_arc_motion(arcs, np.linspace(0, 2 * np.pi, quarter + 1), start_frame=start, axis_column=0,
                                 rational=rational)
        f = chain.frames(np.linspace(0, 2 * np.pi, 401))
        assert np.abs(f[:, 2, 0] - c / w).max() < 1e-12  # the tangent stays on the helix's indicatrix
        s = np.unwrap(np.arctan2(-f[:, 0, 0], f[:, 1, 0]))  # helix parameter where that tangent occurs
        tan, nor, bi = helix_frenet(s, a, c)
        assert np.abs(f[:, :, 0] - tan).max() < 1e-12
        ang = np.unwrap(np.arctan2(np.einsum("ij,ij->i", f[:, :, 1], bi), np.einsum("ij,ij->i", f[:, :, 1], nor)))
        if not rational:  # the exact RMM turns uniformly: -c/w per radian of s
            assert np.abs(ang - (-c / w) * s).max() < 1e-12
        # joints are exact for both (eq. 18), so the turn angle per full turn is exact
        assert abs(ang[-1] - ang[0] - (-2 * np.pi * c / w)) < 1e-12


# ---------------------------------------------------------------------------------------------------
# General position, chains
# ---------------------------------------------------------------------------------------------------
def random_chain(rng, m):
    start = rng.normal(size=3)
    start /= np.linalg.norm(start)
    starts, axes, angles = [], [], []
    for _ in range(m):
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        phi = rng.uniform(0.2, 1.5)
        starts.append(start)
        axes.append(u)
        angles.append(phi)
        start = rotate(u[None], np.array([phi]), start[None])[0]
    starts, axes, angles = np.array(starts), np.array(axes), np.array(angles)
    psi = np.arccos(np.clip(np.einsum("ij,ij->i", axes, starts), -1, 1))
    return SphericalArcs(starts, axes, angles, psi)


def test_arc_motion_general_position_and_start_frame():
    rng = np.random.default_rng(3)
    arcs = random_chain(rng, 1)
    a, u, phi = arcs.start[0], arcs.axis[0], arcs.angle[0]
    f0 = np.linalg.qr(np.column_stack((a, rng.normal(size=(3, 2)))))[0]
    f0 = f0 * np.sign(f0[:, 0] @ a)
    f0[:, 2] *= np.linalg.det(f0)
    for col in (0, 2):
        start = np.roll(f0, col, axis=1)
        m = arc_motion(a, u, phi, start_frame=start, axis_column=col, w0=1.4, w1=0.6)
        assert np.abs(m.frames([0.0])[0] - start).max() < 1e-12
        z = m.axis(T)
        assert np.abs(z - rotate(np.tile(u, (T.size, 1)), m.arc_angle(T), np.tile(a, (T.size, 1)))).max() < 1e-12
        assert_frames(m.frames(T))
        ex = m.exact()
        omega = ex.angular_velocity(T)
        assert (np.abs(np.einsum("ij,ij->i", omega, ex.axis(T))) <= 1e-9 * np.linalg.norm(omega, axis=1)).all()
        assert np.abs(fd_angular_velocity(ex, T[10:-10:100]) - ex.angular_velocity(T[10:-10:100])).max() < 1e-7
        assert np.abs(fd_angular_velocity(m, T[10:-10:100]) - m.angular_velocity(T[10:-10:100])).max() < 1e-7


def test_chain_is_c0_with_continuous_quaternions():
    rng = np.random.default_rng(5)
    arcs = random_chain(rng, 7)
    knots = np.cumsum(np.concatenate(([0.0], rng.uniform(0.5, 2.0, 7))))
    chain = chain_arc_motion(arcs, knots, axis_column=2)
    eps = 1e-11
    for motion in (chain, chain.exact()):
        left, right = motion.frames(knots[1:-1] - eps), motion.frames(knots[1:-1] + eps)
        assert np.abs(left - right).max() < 1e-9
        ql, qr = motion.quaternion(knots[1:-1] - eps), motion.quaternion(knots[1:-1] + eps)
        assert np.abs(ql - qr).max() < 1e-9  # same sign on both sides
        assert_frames(motion.frames(np.linspace(knots[0], knots[-1], 3001)))
    assert np.abs(chain.joint_quaternions - chain.exact().joint_quaternions).max() < 1e-13
    # every segment starts from the end frame of the previous one
    for k in range(1, 7):
        seg = arc_motion(arcs.start[k], arcs.axis[k], arcs.angle[k], start_frame=chain.frames([knots[k]])[0])
        assert np.abs(seg.frames(T) - chain.segment(k).frames(T)).max() < 1e-11


def test_bad_arc_parameters_name_the_parameter():
    with pytest.raises(PlannerError, match="r2_weights"):
        rmm_arc(1.0, 1.0, r2_weights="best")
    cases = [((np.nan, 1.0), "phi"), ((7.0, 1.0), "phi"), ((1.0, -0.1), "psi"), ((1.0, 4.0), "psi"),
             ((1.0, 1.0, 0.0), "w0"), ((1.0, 1.0, 1.0, -2.0), "w1"), ((1.0, 1.0, 1.0, 1.0, np.inf), "rho")]
    for args, name in cases:
        with pytest.raises(PlannerError, match=name):
            rmm_arc(*args)


def test_bad_start_frame_and_chain_gap():
    rng = np.random.default_rng(8)
    arcs = random_chain(rng, 3)
    a, u, phi = arcs.start[0], arcs.axis[0], arcs.angle[0]
    good = arc_motion(a, u, phi).frames([0.0])[0]
    with pytest.raises(PlannerError, match="start_frame.*orthonormal"):
        arc_motion(a, u, phi, start_frame=1.01 * good)
    with pytest.raises(PlannerError, match="start_frame.*column 2"):
        arc_motion(a, u, phi, start_frame=good[:, [1, 2, 0]])
    with pytest.raises(PlannerError, match="start_frame.*left-handed"):
        arc_motion(a, u, phi, start_frame=good * [1, -1, 1])
    broken = SphericalArcs(arcs.start.copy(), arcs.axis, arcs.angle, arcs.psi)
    broken.start[2] = rotate(arcs.axis[1:2], np.array([1e-6]), arcs.start[2:3])[0]
    with pytest.raises(PlannerError, match=r"arcs\[2\]"):
        chain_arc_motion(broken)
    with pytest.raises(PlannerError, match=r"knots\[2\]"):
        chain_arc_motion(arcs, [0.0, 1.0, 1.0, 2.0])
    with pytest.raises(PlannerError, match=r"t\[1\]"):
        chain_arc_motion(arcs).frames([0.5, 3.5])
