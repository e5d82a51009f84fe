"""GRM frames (Peng, Pang, Pan 2023): the exact constraint (24), the weights, the real twist figure."""

from __future__ import annotations

import numpy as np
import pytest

from planner import bernstein
from planner import quaternion as qt
from planner.curves import PHQuintic
from planner.errors import PlannerError
from planner.frames.er import er_frames
from planner.frames.grm import g_poly_values, grm, grm_from_coefficients
from planner.frames.metrics import angular_velocity, max_twist_deg
from planner.frames.rmf import rmf_frames

SEED = PHQuintic.from_quaternions((0, 1, 0, 2), (0, 2, 1, -1), (0, 3, -2, -1))
# the paper's printed solutions (section 5)
PAPER_RHO1 = ([6.5789, 3.1495, -2.1811, 15.3863, 17.1115], [-0.8943, 1.0685, -0.6119, 1.1118, 3.9292])
PAPER_TAUKAPPA = ([9.8125, 1.1353, -1.1893, 15.1672, 9.1231], [-1.4645, 0.8832, -0.4792, -0.0104, 2.7759])


@pytest.fixture(scope="module")
def solutions():
    return {w: grm(SEED, w) for w in ("twist", "1", "sigma", "tau_kappa")}


def test_g_is_the_seed_right_hand_side_of_degree_6():
    t = np.linspace(0, 1, 13)
    A = SEED.quaternion(t)
    dA = bernstein.evaluate(bernstein.derivative(SEED.A), t)
    direct = np.einsum("ni,ni->n", 2 * qt.sym(dA, qt.J, A), qt.sandwich(A, qt.K, A))  # (d/dt AjA*).(AkA*)
    assert np.allclose(g_poly_values(SEED.A, t), direct, rtol=1e-13, atol=1e-12)
    coeffs = np.polynomial.polynomial.polyfit(t, direct, 8)
    assert np.abs(coeffs[7:]).max() < 1e-9 * np.abs(coeffs).max()  # degree 6: 7 equations, not 8


@pytest.mark.parametrize("weight", ["twist", "1", "sigma", "tau_kappa"])
def test_constraint_24_holds_to_round_off(solutions, weight):
    g = solutions[weight]
    assert g.constraint_residual < 1e-9
    t = np.linspace(0, 1, 301)
    a, b = bernstein.evaluate(g.a, t), bernstein.evaluate(g.b, t)
    da, db = bernstein.evaluate(bernstein.derivative(g.a), t), bernstein.evaluate(bernstein.derivative(g.b), t)
    gt = g_poly_values(SEED.A, t)
    assert np.abs(a * db - da * b - gt).max() <= 1e-9 * np.abs(gt).max()


def test_paper_printed_solutions_violate_24_by_about_1_percent():
    rho1 = grm_from_coefficients(SEED, *PAPER_RHO1)
    assert 0.01 < rho1.constraint_residual < 0.02  # DESIGN.md: about 1.4 %
    assert grm_from_coefficients(SEED, *PAPER_TAUKAPPA).constraint_residual > 0.005


def test_twist_default_is_no_worse_than_the_paper(solutions):
    paper = grm_from_coefficients(SEED, *PAPER_RHO1)
    ours = solutions["twist"]
    # the paper's frame twists 1.73 deg against the exact RMF (1.1 deg if (24) held with its a^2 + b^2)
    assert ours.max_twist_deg <= min(paper.max_twist_deg, 1.1)
    for w, g in solutions.items():
        assert ours.max_twist_deg <= g.max_twist_deg + 1e-9, w


def test_low_objective_13_can_twist_far_more(solutions):
    """DESIGN.md: rho = 1 is a poor proxy: its optimum twists tens of degrees."""
    assert solutions["1"].max_twist_deg > 10 * solutions["twist"].max_twist_deg


def test_max_twist_figure_matches_frames(solutions):
    g = solutions["twist"]
    t = np.linspace(0, 1, 1001)
    assert max_twist_deg(g.frames(t), rmf_frames(SEED, t)) == pytest.approx(g.max_twist_deg, abs=1e-9)


def test_grm_frames_are_orthonormal_adapted_and_rational(solutions):
    g = solutions["twist"]
    t = np.linspace(0, 1, 101)
    F = g.frames(t)
    assert np.abs(np.einsum("nji,njk->nik", F, F) - np.eye(3)).max() < 1e-14
    assert np.abs(F[:, :, 0] - SEED.tangent(t)).max() < 1e-13
    # eq. (11): u = ((b^2 - a^2) AjA* + 2ab AkA*) / ((a^2 + b^2) sigma), a rational vector
    a, b = bernstein.evaluate(g.a, t), bernstein.evaluate(g.b, t)
    A = SEED.quaternion(t)
    sig = qt.norm2(A)
    u = ((b * b - a * a)[:, None] * qt.sandwich(A, qt.J, A) + (2 * a * b)[:, None] * qt.sandwich(A, qt.K, A))
    assert np.allclose(F[:, :, 1], u / ((a * a + b * b) * sig)[:, None], atol=1e-14)


def test_grm_angular_velocity_is_nearly_normal(solutions):
    g = solutions["twist"]
    t = np.linspace(0.05, 0.95, 19)
    tan = SEED.tangent(t)
    ratio = lambda w: (np.abs(np.einsum("ni,ni->n", w, tan)) / np.linalg.norm(w, axis=1)).max()  # noqa: E731
    grm_ratio = ratio(angular_velocity(g.frames, t))
    er_ratio = ratio(angular_velocity(lambda x: er_frames(SEED, x), t))
    assert grm_ratio < 0.06 and grm_ratio < er_ratio / 5  # approximately RM (the ER frame: 0.36)


def test_with_start_rotates_the_whole_frame(solutions):
    g = solutions["twist"]
    F0 = g.frames([0.0])[0]
    c, s = np.cos(1.1), np.sin(1.1)
    start = F0 @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    h = g.with_start(start)
    assert np.abs(h.frames([0.0])[0] - start).max() < 1e-14
    t = np.linspace(0, 1, 11)
    ang = np.arctan2(np.einsum("ni,ni->n", np.cross(g.frames(t)[:, :, 1], h.frames(t)[:, :, 1]), SEED.tangent(t)),
                     np.einsum("ni,ni->n", g.frames(t)[:, :, 1], h.frames(t)[:, :, 1]))
    assert np.allclose(ang, 1.1, atol=1e-13)


def test_callable_weight_and_determinism():
    g1 = grm(SEED, lambda t: 1.0 + t)
    g2 = grm(SEED, lambda t: 1.0 + t)
    assert np.array_equal(g1.a, g2.a) and np.array_equal(g1.b, g2.b)
    assert g1.constraint_residual < 1e-9


def test_bad_input():
    with pytest.raises(PlannerError, match="weight must be one of"):
        grm(SEED, "banana")
    with pytest.raises(PlannerError, match="PH quintic"):
        grm(object())
    with pytest.raises(PlannerError, match="non-negative"):
        grm(SEED, lambda t: -np.ones_like(t))
    with pytest.raises(PlannerError, match="5 Bernstein coefficients"):
        grm_from_coefficients(SEED, [1, 2], [3, 4])


def test_grm_many_solves_every_segment_of_a_path():
    from planner.curves import fit_ph_spline
    from planner.frames.grm import grm_many

    th = np.linspace(0, 2.5, 9)
    path = fit_ph_spline(np.c_[np.cos(th), np.sin(th), 0.3 * th + 0.1 * np.sin(3 * th)])
    sols = grm_many(path.segments)
    assert len(sols) == path.n_segments
    for seg, g in zip(path.segments, sols, strict=True):
        assert g.constraint_residual < 1e-9
        single = grm(seg)
        assert g.max_twist_deg <= max(3 * single.max_twist_deg, 0.05)
        t = np.linspace(0, 1, 201)
        assert max_twist_deg(g.frames(t), rmf_frames(seg, t)) == pytest.approx(g.max_twist_deg, abs=0.05)
    with pytest.raises(PlannerError, match="weight must be one of"):
        grm_many(path.segments, "nope")
    assert grm_many([]) == []


def _helix_path(n):
    """The benchmark's wavy helix (bench/bench_paths.py) through n waypoints, jittered by 1 micron."""
    from planner.curves import fit_ph_spline

    s = np.linspace(0.0, 6 * np.pi, n)
    p = np.c_[0.25 * np.cos(s), 0.25 * np.sin(s) + 0.05 * np.sin(3 * s), 0.02 * s]
    return fit_ph_spline(p + np.random.default_rng(42).normal(scale=1e-6, size=p.shape))


def test_every_point_of_each_plane_orbit_satisfies_24():
    """The closed form of the constraint set: W(lam a_V, (b_V + mu a_V) / lam) = g for any lam > 0, mu, on
    every real plane (Newton-confirmed candidates of the Pluecker quadrics)."""
    from planner.frames.grm import _orbit_planes, _Problem
    from planner.frames.grm_orbits import g_power, orbit_point

    segs = _helix_path(12).segments[:4] + [SEED]
    A = np.stack([c.A for c in segs])
    gp = g_power(A)
    t = np.linspace(0, 1, 301)
    gt = np.array([g_poly_values(c.A, t) for c in segs])
    assert np.abs(gp @ np.vander(t, 7, increasing=True).T - gt).max() <= 1e-13 * np.abs(gt).max()
    seg, aV, bV = _orbit_planes(_Problem(segs, "twist", np.zeros((len(segs), 101)), gp), A)
    assert set(seg) == set(range(len(segs)))  # at least one real plane each (an odd number exist)
    lam, mu = np.array([0.3, 1.0, 4.0]), np.array([-2.0, 0.0, 5.0])
    for i, av0, bv0 in zip(seg, aV, bV, strict=True):
        a, b = orbit_point(av0, bv0, lam, mu)
        for j in range(3):
            av, bv = bernstein.evaluate(a[j], t), bernstein.evaluate(b[j], t)
            da, db = bernstein.evaluate(bernstein.derivative(a[j]), t), bernstein.evaluate(bernstein.derivative(b[j]), t)
            assert a[j][0] == 0 and b[j][0] == pytest.approx(1 / lam[j], rel=1e-15)
            assert np.abs(av * db - da * bv - gt[i]).max() <= 1e-11 * np.abs(gt[i]).max()


def test_spin_between_samples_is_penalized():
    """z = b + i a passing near 0 between two samples spins the frame by 2 pi unseen by the samples."""
    from planner.frames.grm_orbits import bernstein_bend, spin_suspect

    t = np.linspace(0, 1, 101)
    # z(t) = (t - 0.505) + 1e-4 i: |z| >= 0.005 at every sample, 1e-4 at t = 0.505
    a = np.full(5, 1e-4)
    b = np.array([-0.505, -0.255, -0.005, 0.245, 0.495])  # Bernstein coefficients of t - 0.505
    zr, zi = bernstein.evaluate(b, t), bernstein.evaluate(a, t)
    m2 = zr**2 + zi**2
    floor2 = np.full(t.size, 0.004**2)
    assert (m2 >= floor2).all()
    assert spin_suspect(zr, zi, m2, floor2, bernstein_bend(a, b), 0.01)
    b_far = b + 2.0  # the same line moved away from 0: |z| >= 1.4 everywhere
    zr = bernstein.evaluate(b_far, t)
    m2 = zr**2 + zi**2
    assert not spin_suspect(zr, zi, m2, floor2, bernstein_bend(a, b_far), 0.01)


def test_batched_and_single_curve_results_agree():
    from planner.frames.grm import grm_many

    segs = _helix_path(30).segments[5:9] + [SEED]
    many = grm_many(segs)
    for c, g in zip(segs, many, strict=True):
        one = grm(c)
        assert np.allclose(one.a, g.a, rtol=1e-9, atol=1e-12 * np.abs(g.b).max())
        assert np.allclose(one.b, g.b, rtol=1e-9, atol=1e-12 * np.abs(g.b).max())
        assert one.max_twist_deg == pytest.approx(g.max_twist_deg, rel=1e-6, abs=1e-12)
    again = grm_many(segs)
    assert all(np.array_equal(x.a, y.a) and np.array_equal(x.b, y.b) for x, y in zip(many, again, strict=True))


def test_closed_form_search_is_no_worse_than_the_grid_search():
    """On the benchmark path (200 waypoints): the per-segment twist against the exact RMF, worst and median,
    no worse than the exhaustive grid search with Newton continuation; (24) to round-off wherever the
    grid search met it, and no worse where it only reached a best-effort point."""
    from planner.frames.grm import grm_many

    segs = _helix_path(200).segments
    new, ref = grm_many(segs), grm_many(segs, search="grid")
    tw, tw_ref = (np.array([g.max_twist_deg for g in s]) for s in (new, ref))
    rs, rs_ref = (np.array([g.constraint_residual for g in s]) for s in (new, ref))
    assert tw.max() <= tw_ref.max() and np.median(tw) <= np.median(tw_ref)
    assert rs.max() < 1e-12 and (rs <= np.maximum(rs_ref, 1e-12)).all()
    t = np.linspace(0, 1, 201)
    for i in np.argsort(tw)[-3:]:  # the reported figure is the frames' real twist
        assert max_twist_deg(new[i].frames(t), rmf_frames(segs[i], t)) <= tw[i] + 1e-9
    with pytest.raises(PlannerError, match="search must be"):
        grm_many(segs[:1], search="fast")
