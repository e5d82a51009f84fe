"""Exact and rational RMM of a smooth spherical curve (tool axis given; seed juttler-..., sec. 2, 7.2)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from planner.errors import PlannerError
from planner.frames.spherical_rmm import exact_spherical_rmm, rational_spherical_rmm

T = np.linspace(0.0, 1.0, 401)


def curve(t):
    a = 0.3 + 2.7 * t  # from 17 to 172 degrees off e3: the base direction must be renewed
    b = 4 * t + np.sin(3 * t)
    return np.stack((np.sin(a) * np.cos(b), np.sin(a) * np.sin(b), np.cos(a)), axis=1)


def dcurve(t):
    a, da = 0.3 + 2.7 * t, 2.7
    b, db = 4 * t + np.sin(3 * t), 4 + 3 * np.cos(3 * t)
    return np.stack((np.cos(a) * np.cos(b) * da - np.sin(a) * np.sin(b) * db,
                     np.cos(a) * np.sin(b) * da + np.sin(a) * np.cos(b) * db, -np.sin(a) * da), axis=1)


def ode_frames(z, dz, f0, t):
    """Reference: parallel transport of columns 0, 1 with omega = z x z' (Prop. 1), DOP853."""
    def rhs(s, y):
        s1 = np.array([s])
        w = np.cross(z(s1)[0], dz(s1)[0])
        return np.cross(w, y.reshape(2, 3)).ravel()

    sol = solve_ivp(rhs, (t[0], t[-1]), f0[:, :2].T.ravel(), method="DOP853", rtol=1e-13, atol=1e-14, t_eval=t)
    return sol.y.T.reshape(-1, 2, 3).transpose(0, 2, 1)


def rotation_angle(a, b):
    r = np.einsum("nji,njk->nik", a, b)
    axis = np.stack((r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]), axis=1)
    return np.arctan2(0.5 * np.linalg.norm(axis, axis=1), 0.5 * (np.trace(r, axis1=1, axis2=2) - 1.0))


def test_exact_rmm_matches_parallel_transport_ode():
    motion = exact_spherical_rmm(curve, dcurve)
    assert len(motion.pieces) > 2  # several base directions were used
    t = np.linspace(0, 1, 41)
    f = motion.frames(t)
    assert np.abs(f[:, :, 2] - curve(t)).max() < 1e-14
    ref = ode_frames(curve, dcurve, f[0], t)
    assert np.abs(f[:, :, :2] - ref).max() < 1e-10


def test_exact_rmm_properties():
    motion = exact_spherical_rmm(curve, dcurve)
    f = motion.frames(T)
    assert np.abs(np.einsum("nji,njk->nik", f, f) - np.eye(3)).max() < 1e-12
    assert np.abs(np.linalg.det(f) - 1).max() < 1e-12
    omega = motion.angular_velocity(T)
    z = curve(T)
    assert (np.abs(np.einsum("ij,ij->i", omega, z)) <= 1e-9 * np.linalg.norm(omega, axis=1)).all()
    assert np.abs(omega - np.cross(z, dcurve(T))).max() < 1e-12  # Prop. 1, eq. (5)
    h = 1e-6
    tt = T[5:-5:20]
    w = np.einsum("nij,nkj->nik", (motion.frames(tt + h) - motion.frames(tt - h)) / (2 * h), motion.frames(tt))
    w = np.stack((w[:, 2, 1], w[:, 0, 2], w[:, 1, 0]), axis=1)
    assert np.abs(w - motion.angular_velocity(tt)).max() < 1e-7
    q = motion.quaternion(np.linspace(0, 1, 20001))
    assert np.abs(np.diff(q, axis=0)).max() < 1e-3  # no sign flips, also across base renewals


@pytest.mark.parametrize("a, c, turns", [(2.0, 0.7, 2), (1.0, -0.4, 1), (0.3, 2.0, 3)])
def test_helix_tangent_indicatrix_turns_against_frenet(a, c, turns):
    # Tool axis = helix tangent T(s); sign convention: angle of the RMF normal against the Frenet
    # normal N measured from N towards B = T x N. Expected: -2 pi c / sqrt(a^2 + c^2) per turn.
    w = np.hypot(a, c)

    def tan(s):
        return np.stack((-a * np.sin(s), a * np.cos(s), np.full_like(s, c)), axis=1) / w

    def dtan(s):
        return np.stack((-a * np.cos(s), -a * np.sin(s), 0 * s), axis=1) / w

    span = 2 * np.pi * turns
    s = np.linspace(0, span, 301)
    nor = np.stack((-np.cos(s), -np.sin(s), 0 * s), axis=1)
    bi = np.cross(tan(s), nor)
    start = np.column_stack((nor[0], bi[0], tan(s[:1])[0]))  # columns N, B, T: right-handed, axis last
    f = exact_spherical_rmm(tan, dtan, start, interval=(0.0, span)).frames(s)
    ang = np.unwrap(np.arctan2(np.einsum("ij,ij->i", f[:, :, 0], bi), np.einsum("ij,ij->i", f[:, :, 0], nor)))
    assert np.abs(ang - (-c / w) * s).max() < 1e-10
    assert abs((ang[-1] - ang[0]) / turns - (-2 * np.pi * c / w)) < 1e-10


def test_reparameterization_invariance_corollary_2():
    def g(t):
        return t**2 * (3 - 2 * t)

    def z2(t):
        return curve(g(t))

    def dz2(t):
        return dcurve(g(t)) * (6 * t * (1 - t))[:, None]

    a = exact_spherical_rmm(curve, dcurve).frames(g(T))
    b = exact_spherical_rmm(z2, dz2).frames(T)  # z'(0) = 0 at both ends: stationary axis handled
    assert rotation_angle(a, b).max() < 1e-10


def test_constant_axis_gives_constant_frame():
    axis = np.array([0.0, 0.6, -0.8])
    motion = exact_spherical_rmm(lambda t: np.tile(axis, (t.size, 1)), lambda t: np.zeros((t.size, 3)))
    f = motion.frames(T)
    assert np.abs(f - f[0]).max() < 1e-15
    assert np.abs(f[0][:, 2] - axis).max() < 1e-15


def test_start_frame_and_bad_input():
    z0 = curve(np.zeros(1))[0]
    x = np.cross(z0, [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    start = np.column_stack((x, np.cross(z0, x), z0))
    assert np.abs(exact_spherical_rmm(curve, dcurve, start).frames([0.0])[0] - start).max() < 1e-15
    with pytest.raises(PlannerError, match="start.*column 2"):
        exact_spherical_rmm(curve, dcurve, start[:, [2, 0, 1]])
    with pytest.raises(PlannerError, match="start.*orthonormal"):
        exact_spherical_rmm(curve, dcurve, start + 1e-6)
    with pytest.raises(PlannerError, match="dz.*derivative"):
        exact_spherical_rmm(curve, lambda t: 1.1 * dcurve(t))
    with pytest.raises(PlannerError, match=r"z\(t\) at t = .*unit"):
        exact_spherical_rmm(lambda t: 1.5 * curve(t), dcurve)
    with pytest.raises(PlannerError, match=r"dz\(t\) at t = .*finite"):
        exact_spherical_rmm(curve, lambda t: dcurve(t) * np.where(t > 0.6, np.nan, 1.0)[:, None])
    with pytest.raises(PlannerError, match="interval"):
        exact_spherical_rmm(curve, dcurve, interval=(0.0, 0.0))
    with pytest.raises(PlannerError, match=r"t\[1\].*outside"):
        exact_spherical_rmm(curve, dcurve).frames([0.5, 1.5])


def test_rational_approximation_converges_to_the_exact_rmm():
    exact = exact_spherical_rmm(curve, dcurve)
    e = exact.frames(T)
    for tol in (1e-3, 1e-5, 1e-7):
        motion = rational_spherical_rmm(curve, dcurve, tol, start=e[0])
        f = motion.frames(T)
        assert np.abs(np.einsum("nji,njk->nik", f, f) - np.eye(3)).max() < 1e-12
        z = curve(T)
        axis_error = np.arctan2(np.linalg.norm(np.cross(f[:, :, 2], z), axis=1), np.einsum("ij,ij->i", f[:, :, 2], z))
        # the axis runs on the biarc spline, parameterized to follow z(t): the tool axis at t is within
        # about tol of z(t), and the whole frame within about tol of the exact RMM frame
        assert axis_error.max() < 2 * tol
        assert rotation_angle(f, e).max() < 2 * tol
        hk = motion.knots[::2]  # at the Hermite knots the axes coincide: only the spin differs
        assert rotation_angle(motion.frames(hk), exact.frames(hk)).max() < 0.1 * tol
        eps = 1e-12
        assert np.abs(motion.quaternion(motion.knots[1:-1] - eps) - motion.quaternion(motion.knots[1:-1] + eps)
                      ).max() < 1e-9
