"""The free spin about an axisymmetric tool (spin="reach", planner.cam.spin and planner.cam.spin_choice)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner import PlannerError, PlanSettings, load_job, plan
from planner.cam.spin import SpinCurve, SpunFrames, spun
from planner.cam.spin_choice import spin_is_wrist3, spin_rates
from planner.kinematics import forward_matrix, inverse_batch
from planner.kinematics.poses import pose_to_matrix

EXAMPLE = "examples/nx_first_pass.cls"
#: A nozzle angled 34 deg off the flange axis, 120 mm out: a spin moves every joint.
ANGLED = (0.0, 0.05, 0.12, 0.6, 0.0, 0.0)
#: A part frame where the RMM spin of the example, with the angled nozzle, leaves poses out of reach.
TIGHT = (0.3, 0.2, -0.3, 0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def angled():
    s = dict(robot="ur5e", part_frame=TIGHT, tcp=ANGLED)
    return plan(EXAMPLE, PlanSettings(**s)), plan(EXAMPLE, PlanSettings(spin="reach", **s))


def _poses(job, rate=125.0):
    chunks = list(job.trajectory(rate).chunks())
    return np.concatenate([c.poses for c in chunks])


def test_spun_frames_keep_the_tool_axis_bit_for_bit_and_turn_about_it():
    rng = np.random.default_rng(3)
    q, _ = np.linalg.qr(rng.normal(size=(50, 3, 3)))
    F = q * np.sign(np.linalg.det(q))[:, None, None]
    psi = rng.uniform(-7.0, 7.0, 50)
    G = spun(F, psi)
    assert np.array_equal(G[:, :, 2], F[:, :, 2])
    assert np.abs(np.einsum("nji,njk->nik", G, G) - np.eye(3)).max() < 1e-14
    cos = np.einsum("nj,nj->n", F[:, :, 0], G[:, :, 0])
    assert np.abs(cos - np.cos(psi)).max() < 1e-14


def test_spin_curve_is_c2_and_a_transition_rests_at_its_ends():
    c = SpinCurve.transition(0.3, -1.2, 0.05)
    x = np.linspace(0.0, 0.05, 2001)
    assert c(0.0)[0] == pytest.approx(0.3, abs=1e-15) and c(0.05)[0] == pytest.approx(-1.2, abs=1e-15)
    assert abs(c(0.0, 1)[0]) < 1e-12 and abs(c(0.05, 1)[0]) < 1e-9
    d2 = c(x, 2)
    assert np.abs(np.diff(d2)).max() < 1e-2 * np.abs(d2).max()  # continuous second derivative
    assert c(-1.0)[0] == c(0.0)[0] and c(1.0)[0] == c(0.05)[0]  # constant beyond the ends


def test_a_spin_about_the_flange_axis_is_wrist_3_alone():
    tcp = (0.0, 0.0, 0.15, 0.0, 0.0, 0.4)
    assert spin_is_wrist3(None) and spin_is_wrist3(tcp) and not spin_is_wrist3(ANGLED)
    q = np.array([[0.3, -1.2, 1.4, -1.7, -1.5, 0.2]])
    T = forward_matrix("ur5e", q, tcp=tcp)[0]
    psi = 0.7
    Ts = T.copy()
    Ts[:3, :3] = spun(T[None, :3, :3], np.array([psi]))[0]
    q2 = q.copy()
    q2[0, 5] += psi
    assert np.abs(forward_matrix("ur5e", q2, tcp=tcp)[0] - Ts).max() < 1e-12


def test_settings_refuse_a_spin_for_no_robot_and_bad_bounds():
    with pytest.raises(PlannerError) as e:
        PlanSettings(spin="reach").checked()
    assert e.value.field == "spin" and "robot" in str(e.value)
    with pytest.raises(PlannerError) as e:
        PlanSettings(spin="free", robot="ur5e").checked()
    assert e.value.field == "spin"
    for bad in (math.nan, -1.0, math.inf):
        with pytest.raises(PlannerError) as e:
            PlanSettings(spin="reach", robot="ur5e", spin_rate=bad).checked()
        assert e.value.field == "spin_rate"
    with pytest.raises(PlannerError) as e:
        plan(np.c_[np.linspace(0, 0.2, 5), np.zeros(5), np.zeros(5)] + [0.4, 0.1, 0.2],
             PlanSettings(spin="reach", robot="ur5e"))
    assert e.value.field == "spin" and "axes" in str(e.value)


def test_rmm_default_plans_no_spun_frames():
    job = plan(EXAMPLE, PlanSettings(robot="ur5e", part_frame=(0.4, 0.9965, -0.1, 0, 0, 0)))
    assert not any(isinstance(m.frames, SpunFrames) for m in job.moves)
    assert "spin" not in job.summary()


def test_reach_keeps_the_tool_axis_and_tcp_path(angled):
    rmm, reach = angled
    assert reach.summary()["spin"]["spun_runs"] == 1
    for a, b in zip(rmm.moves, reach.moves, strict=True):
        if a.kind not in ("cut", "rapid"):
            continue
        L = float(a.path.length)
        s = np.linspace(0.0, L, 301)
        Fa, Fb = a.frames.at_length(s), b.frames.at_length(s)
        assert np.abs(Fa[:, :, 2] - Fb[:, :, 2]).max() < 1e-12  # the tool axis, to round-off
        u = a.path.parameter_at_length(s)
        assert np.abs(a.frames.frames(u)[:, :, 2] - b.frames.frames(u)[:, :, 2]).max() < 1e-12
        # the rotation between them is about the tool axis only
        rel = np.einsum("nji,njk->nik", Fa, Fb)
        assert np.abs(rel[:, 2, :2]).max() < 1e-12 and np.abs(rel[:, :2, 2]).max() < 1e-12
        qa, qb = a.frames.quaternions(u), b.frames.quaternions(u)
        from planner.rotations import quaternion_to_matrix

        assert np.abs(quaternion_to_matrix(qb) - b.frames.frames(u)).max() < 1e-12
        assert np.abs(quaternion_to_matrix(qa)[:, :, 2] - quaternion_to_matrix(qb)[:, :, 2]).max() < 1e-12
    # the streamed TCP positions are the same samples (the cut's time law is unchanged)
    pa, pb = _poses(rmm), _poses(reach)
    assert pa.shape == pb.shape
    assert np.abs(pa[:, :3] - pb[:, :3]).max() < 1e-12
    za = np.array([pose_to_matrix(p)[:3, 2] for p in pa[::50]])
    zb = np.array([pose_to_matrix(p)[:3, 2] for p in pb[::50]])
    assert np.abs(za - zb).max() < 1e-9


def test_reach_meets_the_spin_bounds_and_buys_reach(angled):
    rmm, reach = angled
    s = reach.settings
    for m in reach.moves:
        w, a = spin_rates(m)
        assert w <= s.spin_rate * (1 + 1e-9), (m.kind, w)
        assert a <= s.spin_acceleration * (1 + 1e-9), (m.kind, a)
    sp = reach.summary()["spin"]
    assert sp["reach"]["out_of_reach_samples"] < sp["rmm"]["out_of_reach_samples"]
    assert sp["reach"]["singularity_margin"] > sp["rmm"]["singularity_margin"]
    # the figures are real: the spun poses' inverse kinematics is what they say on the chosen branch
    m = next(m for m in reach.moves if m.kind == "cut")
    assert m.frames.figures is not None and m.frames.figures.samples > 10
    assert any("spin      reach" in line for line in reach.describe())


def test_the_spin_is_continuous_across_moves(angled):
    _, reach = angled
    moving = [m for m in reach.moves if m.frames is not None]
    for a, b in zip(moving, moving[1:], strict=False):
        assert np.abs(a.end_frame - b.start_frame).max() < 1e-9
        assert np.abs(a.frames.end - a.end_frame).max() < 1e-12


def test_a_job_with_large_margins_keeps_the_rmm_spin():
    s = dict(robot="ur5e", part_frame=(0.4, 0.9965, -0.1, 0, 0, 0))
    rmm, reach = plan(EXAMPLE, PlanSettings(**s)), plan(EXAMPLE, PlanSettings(spin="reach", **s))
    assert reach.summary()["spin"]["spun_runs"] == 0
    pa, pb = _poses(rmm), _poses(reach)
    assert np.abs(pa - pb).max() < 1e-12


def test_a_spun_job_saves_and_loads_to_the_same_trajectory(angled, tmp_path):
    _, reach = angled
    path = tmp_path / "spun.job"
    reach.save(path)
    back = load_job(path)
    assert np.array_equal(_poses(back), _poses(reach))
    assert back.summary()["spin"] == reach.summary()["spin"]


def test_the_joints_of_a_spun_job_are_its_poses(angled):
    _, reach = angled
    tr = reach.trajectory(125.0)
    for chunk in tr.chunks():
        ok = np.isfinite(chunk.joints).all(axis=1)
        if not ok.any():
            continue
        T = forward_matrix("ur5e", chunk.joints[ok][::20], tcp=ANGLED)
        P = np.array([pose_to_matrix(p) for p in chunk.poses[ok][::20]])
        assert np.abs(T - P).max() < 1e-9
        sol = inverse_batch("ur5e", chunk.poses[ok][:5], tcp=ANGLED)
        assert sol.valid.any(axis=1).all()


@pytest.fixture(scope="module")
def excerpt():
    """The NX excerpt (33 passes, 18 runs) with the angled nozzle where the RMM spin leaves passes out of reach."""
    s = dict(robot="ur5e", part_frame=(0.25, 0.3, -0.25, 0.0, 0.0, 0.0), tcp=ANGLED)
    src = "tests/data/nx_clsf_ust_a2_excerpt.cls"
    return plan(src, PlanSettings(**s)), plan(src, PlanSettings(spin="reach", **s))


def test_reach_makes_the_passes_reachable_where_the_rmm_spin_cannot(excerpt):
    rmm, reach = excerpt
    assert rmm.summary()["unreachable_passes"]
    assert not reach.summary()["unreachable_passes"]
    sp = reach.summary()["spin"]
    assert sp["rmm"]["out_of_reach_samples"] > 0 and sp["reach"]["out_of_reach_samples"] == 0
    assert sp["reachable_only_by_spin"] and sp["spun_runs"] >= 2
    assert any("reachable only with this spin" in line for line in reach.describe())
    assert len(reach.problems) < len(rmm.problems)


def test_spin_bounds_hold_on_every_move_and_rapids_carry_the_transitions(excerpt):
    _, reach = excerpt
    s = reach.settings
    transitions = 0
    for m in reach.moves:
        w, a = spin_rates(m)
        assert w <= s.spin_rate * (1 + 1e-9), (m.kind, m.line, w)
        assert a <= s.spin_acceleration * (1 + 1e-9), (m.kind, m.line, a)
        transitions += m.kind == "rapid" and isinstance(m.frames, SpunFrames) and not m.frames.spin.is_constant
    assert transitions >= 1
    moving = [m for m in reach.moves if m.frames is not None]
    for a, b in zip(moving, moving[1:], strict=False):
        assert np.abs(a.end_frame - b.start_frame).max() < 1e-9


def test_the_plot_draws_the_spin_and_what_it_bought(excerpt, tmp_path):
    from planner.plot import plot_job

    _, reach = excerpt
    out = tmp_path / "spin.png"
    plot_job(reach, out)
    assert out.stat().st_size > 50_000


def test_absurdly_small_spin_bounds_hold_and_do_not_stretch_the_job(excerpt):
    rmm, _ = excerpt
    s = dict(robot="ur5e", part_frame=(0.25, 0.3, -0.25, 0.0, 0.0, 0.0), tcp=ANGLED)
    slow = plan("tests/data/nx_clsf_ust_a2_excerpt.cls",
                PlanSettings(spin="reach", spin_rate=1e-6, spin_acceleration=1e-6, **s))
    assert slow.duration < 1.01 * rmm.duration  # the spin is held through the rapids, not carried at 1e-6 rad/s
    for m in slow.moves:
        w, a = spin_rates(m)
        assert w <= 1e-6 * (1 + 1e-9) and a <= 1e-6 * (1 + 1e-9), (m.kind, m.line, w, a)


def test_auto_placement_then_the_spin():
    """part_frame='auto' places the part for the RMM frames first, then the spin is chosen at that frame."""
    job = plan(EXAMPLE, PlanSettings(robot="ur5e", part_frame="auto", tcp=ANGLED, spin="reach"))
    assert job.placement is not None and job.settings.part_frame == job.placement.part_frame
    sp = job.summary()["spin"]
    assert sp["runs"] == 1 and sp["reach"]["out_of_reach_samples"] == 0
    assert sp["reach"]["singularity_margin"] >= sp["rmm"]["singularity_margin"]
    assert not job.problems
