"""Exact rotation-minimizing frames and ER frames of PH curves."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from scipy.integrate import solve_ivp

from planner.curves import PHCubic, PHQuintic, fit_ph_spline
from planner.errors import PlannerError
from planner.frames.er import er_frames
from planner.frames.metrics import angular_velocity, frenet_frames
from planner.frames.rmf import RMFAngle, rmf_frames
from tests.conftest import quaternions

SEED = PHQuintic.from_quaternions((0, 1, 0, 2), (0, 2, 1, -1), (0, 3, -2, -1))


def orthonormal_error(F):
    return np.abs(np.einsum("nji,njk->nik", F, F) - np.eye(3)).max()


@given(quaternions(), quaternions(), quaternions())
@settings(max_examples=30, deadline=None)
def test_er_and_rmf_frames_are_orthonormal_right_handed_adapted(A0, A1, A2):
    c = PHQuintic.from_quaternions(A0, A1, A2)
    t = np.linspace(0, 1, 41)
    speed = c.speed(np.linspace(0, 1, 201))
    assume(speed.min() > 1e-3 * speed.max())  # a cusp (A(t) = 0) has no tangent to compare with
    for F in (er_frames(c, t), rmf_frames(c, t)):
        assert orthonormal_error(F) < 1e-14
        assert np.allclose(np.linalg.det(F), 1.0, atol=1e-14)
        assert np.abs(F[:, :, 0] - c.tangent(t)).max() < 1e-13


def test_er_frame_is_the_seed_definition():
    from planner import quaternion as qt

    t = np.linspace(0, 1, 9)
    A = c_A = SEED.quaternion(t)
    sigma = qt.norm2(c_A)[:, None]
    F = er_frames(SEED, t)
    for col, u in enumerate((qt.I, qt.J, qt.K)):
        assert np.allclose(F[:, :, col], qt.sandwich(A, u, A) / sigma, atol=1e-15)


def transport_reference(curve, t, u0):
    """Parallel transport u' = -(u . r'') r' / |r'|^2 by DOP853 at tight tolerances."""

    def rhs(x, u):
        d1, d2 = curve.derivative(x)[0], curve.derivative(x, 2)[0]
        return -(u @ d2) * d1 / (d1 @ d1)

    sol = solve_ivp(rhs, (0, 1), u0, method="DOP853", rtol=1e-13, atol=1e-15, dense_output=True)
    return sol.sol(t).T


@pytest.mark.parametrize(
    "curve",
    [
        SEED,
        PHQuintic.from_quaternions((1, 0.2, -0.5, 0.3), (0.1, 1.5, 0.4, -0.7), (-0.6, 0.3, 1.1, 0.9)),
        PHCubic.from_quaternions((0.3, 1.0, -0.2, 0.5), (0.8, -0.4, 0.9, 0.1)),
    ],
)
def test_rmf_agrees_with_high_accuracy_ode_to_1e9_rad(curve):
    t = np.linspace(0, 1, 21)
    F = rmf_frames(curve, t)
    U = transport_reference(curve, t, F[0, :, 1])
    ang = np.arctan2(np.einsum("ni,ni->n", np.cross(F[:, :, 1], U), F[:, :, 0]), np.einsum("ni,ni->n", F[:, :, 1], U))
    assert np.abs(ang).max() < 1e-9


@given(quaternions(), quaternions(), quaternions())
@settings(max_examples=20, deadline=None)
def test_rmf_angular_velocity_has_no_tangent_component(A0, A1, A2):
    c = PHQuintic.from_quaternions(A0, A1, A2)
    t = np.linspace(0.05, 0.95, 19)
    w = angular_velocity(lambda x: rmf_frames(c, x), t, h=1e-3)
    along = np.abs(np.einsum("ni,ni->n", w, c.tangent(t)))
    norm = np.linalg.norm(w, axis=1)
    assert (along <= 1e-9 * np.maximum(norm, 1e-12) + 1e-12).all()


def test_er_frame_spins_about_the_tangent_where_the_rmf_does_not():
    t = np.linspace(0.05, 0.95, 19)
    tan = SEED.tangent(t)
    w_er = angular_velocity(lambda x: er_frames(SEED, x), t)
    w_rmf = angular_velocity(lambda x: rmf_frames(SEED, x), t)
    assert np.abs(np.einsum("ni,ni->n", w_er, tan)).max() > 0.1
    assert np.abs(np.einsum("ni,ni->n", w_rmf, tan)).max() < 1e-9 * np.linalg.norm(w_rmf, axis=1).max()


@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")
def test_rmf_angle_integral_matches_quadrature_of_the_seed_rate():
    """psi(1) - psi(0) = -int (d/dt A j A*).(A k A*) / sigma^2 dt (seed eq. 6 up to its factor 2 theta)."""
    from scipy.integrate import quad

    from planner import bernstein
    from planner import quaternion as qt

    def rate(x):
        A = SEED.quaternion(x)
        dA = bernstein.evaluate(bernstein.derivative(SEED.A), np.atleast_1d(x))
        dj = 2 * qt.sym(dA, qt.J, A)
        return -float(np.einsum("ni,ni->n", dj, qt.sandwich(A, qt.K, A))[0]) / qt.norm2(A)[0] ** 2

    ref = quad(rate, 0, 1, epsabs=1e-15, epsrel=1e-14)[0]
    assert RMFAngle.of(SEED.A).total == pytest.approx(ref, abs=1e-13)
    t = np.linspace(0, 1, 501)
    assert np.abs(RMFAngle.of(SEED.A).on_grid(t) - RMFAngle.of(SEED.A)(t)).max() < 1e-14


def test_rmf_start_frame_is_honoured():
    F0 = er_frames(SEED, [0.0])[0]
    c, s = np.cos(0.7), np.sin(0.7)
    start = F0 @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    F = rmf_frames(SEED, [0.0, 0.5], start=start)
    assert np.abs(F[0] - start).max() < 1e-15
    G = rmf_frames(SEED, [0.5])
    ang = np.arctan2(np.cross(G[0, :, 1], F[1, :, 1]) @ G[0, :, 0], G[0, :, 1] @ F[1, :, 1])
    assert ang == pytest.approx(0.7, abs=1e-14)  # the RMF is rigid in the normal plane


def test_helix_rmf_turns_against_frenet_by_minus_2pi_c_over_sqrt():
    """On r = (a cos s, a sin s, c s) the RMF turns against Frenet by -2 pi c / sqrt(a^2 + c^2) per turn."""
    a, c = 1.0, 0.4
    s = np.linspace(0, 2 * np.pi, 241)
    p = np.c_[a * np.cos(s), a * np.sin(s), c * s]
    tang = np.c_[-a * np.sin(s), a * np.cos(s), np.full_like(s, c)]
    path = fit_ph_spline(p, tang, continuity="C1")
    from planner.frames.path import frame_field

    u = path.waypoint_knots[[0, -1]]
    F = frame_field(path, "rmf").frames(u)
    N = frenet_frames(path.derivative(u), path.derivative(u, 2))
    # angle of the RMF normal against the Frenet normal, positive from N to B
    ang = np.arctan2(np.einsum("ni,ni->n", F[:, :, 1], N[:, :, 2]), np.einsum("ni,ni->n", F[:, :, 1], N[:, :, 1]))
    turned = np.angle(np.exp(1j * (ang[1] - ang[0])))
    assert turned == pytest.approx(np.angle(np.exp(-2j * np.pi * c / np.hypot(a, c))), abs=1e-6)


def test_bad_start_frame():
    with pytest.raises(PlannerError, match="must be the unit tangent"):
        rmf_frames(SEED, [0.0], start=np.eye(3))
    with pytest.raises(PlannerError, match="orthonormal"):
        rmf_frames(SEED, [0.0], start=2 * np.eye(3))
    with pytest.raises(PlannerError, match="3x3"):
        rmf_frames(SEED, [0.0], start=np.eye(2))


@pytest.mark.parametrize("per_segment", [1.5, 4, 12, 60])
def test_path_angles_chained_along_samples_equal_the_direct_quadrature(per_segment):
    """PathRMFAngles chains sorted samples (6 to 12 Gauss points from the previous sample, by distance);
    each sample must equal its own 16-point quadrature from the panel edge, at any sample density,
    with repeated samples and runs that cross segment joints."""
    from planner.frames.rmf_batch import PathRMFAngles

    rng = np.random.default_rng(5)
    s = np.linspace(0.0, 6 * np.pi, 40)
    wp = np.c_[np.cos(s), np.sin(s) + 0.3 * np.sin(3 * s), 0.1 * s] + rng.normal(scale=0.01, size=(40, 3))
    path = fit_ph_spline(wp)
    u = np.sort(rng.uniform(path.knots[0], path.knots[-1], int(per_segment * path.n_segments)))
    u = np.concatenate((u, u[::7]))  # repeated samples
    u.sort()
    k, t = path.locate(u)
    angles = PathRMFAngles(path.A)
    assert np.abs(angles(k, t) - angles.direct(k, t)).max() < 1e-13
