"""The spin choice's shared and streamlined computations give the same bits as the straightforward ones.

The grid search of ``spin="reach"`` takes its joints joint-major from one unchecked inverse-kinematics call
(:func:`planner.kinematics.inverse_frames`) and computes its step costs for all shifts at once; the time law gives s,
v, a from one phase search (:meth:`FeedProfile.state`). Here each is compared with the public, checked function or the
cost formula written out shift by shift, and a whole spun job's exports with those of the job planned on them. The
compiled grid search (planner/cam/_spin_search.c, step costs and dynamic programming in one pass) is compared with
the numpy one.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from planner import PlanSettings, plan
from planner.cam import spin_choice as sc
from planner.cam.spin import spun
from planner.export import export
from planner.kinematics import inverse_batch, inverse_frames

EXAMPLE = "examples/nx_first_pass.cls"
ANGLED = (0.0, 0.05, 0.12, 0.6, 0.0, 0.0)
TIGHT = (0.3, 0.2, -0.3, 0.0, 0.0, 0.0)


def _frames(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    R = q * np.sign(np.linalg.det(q))[:, None, None]
    p = rng.uniform(-0.9, 0.9, (n, 3))  # some out of reach of a UR5e
    return p, R


@pytest.mark.parametrize("tcp", [None, ANGLED])
def test_inverse_frames_are_inverse_batch_bit_for_bit(tcp):
    p, R = _frames(3000, 7)
    T = np.zeros((p.shape[0], 4, 4))
    T[:, :3, :3], T[:, :3, 3], T[:, 3, 3] = R, p, 1.0
    ref = inverse_batch("ur5e", T, tcp=tcp)
    q, valid = inverse_frames("ur5e", p, R, tcp=tcp)
    assert 0.1 < ref.valid.mean() < 0.9  # reachable and unreachable poses both tested
    assert np.array_equal(valid, ref.valid.T)
    assert q.transpose(2, 1, 0).tobytes() == ref.q.tobytes()  # NaN where not valid, in the same places


def _reference_joints(arm, p, R, psi):
    """Joints (6, n, 8, G) of frames turned by each spin, from the checked public solver (as before sharing)."""
    psi = np.broadcast_to(psi, (p.shape[0],) + np.shape(psi)[-1:])
    n, G = psi.shape
    F = spun(np.repeat(R[:, None], G, axis=1), psi).reshape(-1, 3, 3)
    T = np.zeros((n * G, 4, 4))
    T[:, :3, :3], T[:, :3, 3], T[:, 3, 3] = F, np.repeat(p, G, axis=0), 1.0
    sol = inverse_batch(arm.robot, T, tcp=arm.tcp)
    valid = sol.valid.reshape(n, G, 8).transpose(0, 2, 1)
    q = sol.q.reshape(n, G, 8, 6).transpose(3, 0, 2, 1)
    return np.where(valid, q, 0.0), np.ascontiguousarray(valid)


def _reference_step_costs(arm, q, valid, X, t, free, rate, gstep, shifts):
    """The step costs of the grid search written out shift by shift and joint by joint (see ``_step_costs``)."""
    _, n, nb, G = q.shape
    out = np.empty((n - 1, nb, shifts.size, G))
    dX, h = np.diff(X)[:, None, None], np.diff(t)[:, None, None]
    timed = (np.arange(n - 1) >= free)[:, None, None]
    for k, sh in enumerate(shifts):
        src = np.clip(np.arange(G) - sh, 0, G - 1)  # the predecessor of g, clipped to the grid
        travel = np.zeros((n - 1, nb, G))
        top = np.zeros((n - 1, nb, G))
        for j in range(6):
            d = np.abs(q[j, 1:] - q[j, :-1][..., src])
            d = np.minimum(d, 2.0 * math.pi - d)
            if j in (3, 5):
                travel += d
            top = np.maximum(top, d * (1.0 / arm.vmax)[j])
        both = valid[1:] & valid[:-1][..., src]
        travel *= both
        top *= both
        cost = sc.W_TRAVEL * travel
        ratio = np.where(h > 0.0, top / np.where(h > 0.0, h, 1.0), np.where(top > 1e-9, np.inf, 0.0))
        speed = sc.W_SPEED * np.maximum(0.0, ratio - sc.SPEED_SAFE) ** 2 + sc.W_FAST * (ratio > 1.0)
        spin = sc.W_RATE * np.maximum(0.0, abs(sh) * gstep / np.maximum(h, 1e-9) / max(rate, 1e-9) - 1.0) ** 2
        cost += np.where(timed, speed + spin, 0.0)
        if sh != 0:
            cost += np.where(dX <= 0.0, sc.OUT_OF_REACH, 0.0)
        out[:, :, k] = np.minimum(cost, sc.OUT_OF_REACH)
    return out


@pytest.fixture(scope="module")
def run_samples():
    """The samples of the example's run with the angled nozzle at the tight frame, the spin still the RMM's."""
    captured = {}
    real = sc.choose_spin

    def grab(moves, settings):
        captured["moves"], captured["settings"] = moves, settings
        return real(moves, settings)

    sc.choose_spin = grab
    try:
        plan(EXAMPLE, PlanSettings(robot="ur5e", part_frame=TIGHT, tcp=ANGLED, spin="reach"))
    finally:
        sc.choose_spin = real
    moves, s = captured["moves"], captured["settings"]
    ks = [k for k, m in enumerate(moves) if m.kind == "cut"]
    S, _ = sc._samples(moves, ks, sc.as_transform(s.part_frame, "part_frame"), float(s.reach_step))
    return S


@pytest.mark.parametrize("tcp", [ANGLED, (0.0, 0.0, 0.1, 0.0, 0.0, 0.3)])  # a spin moves every joint; wrist 3 only
def test_grid_joints_and_step_costs_are_the_straightforward_ones_bit_for_bit(run_samples, tcp):
    S = run_samples
    arm = sc._Arm("ur5e", tcp)
    grid = np.linspace(-math.pi, math.pi, sc.GRID + 1)
    p = S.p if not arm.wrist3 else S.p + np.array([0.0, 0.25, 0.25])  # the short tool: nearer the arm's middle
    q, valid = arm.joints(p, S.R, grid)
    if not arm.wrist3:
        q0, valid0 = _reference_joints(arm, p, S.R, grid)
        assert np.array_equal(valid, valid0) and q.tobytes() == q0.tobytes()
    assert 0.0 < valid.mean() < 1.0  # some branches or spins out of reach
    shifts = np.arange(-sc.MAX_STEP, sc.MAX_STEP + 1)
    gstep = float(grid[1] - grid[0])
    X = S.X.copy()
    X[5] = X[4]  # a step where the run's coordinate stands (a turn in place)
    for rate, free in ((math.radians(90.0), 0), (1e-3, 10)):  # also spin-rate costs, and steps in rapids
        got = sc._step_costs(arm, q, valid, X, S.t, free, rate, gstep, shifts)
        want = _reference_step_costs(arm, q, valid, X, S.t, free, rate, gstep, shifts)
        assert got.tobytes() == want.tobytes()
    assert (want >= sc.OUT_OF_REACH).any() and (want[want < 1.0] > 0.0).any()


def test_time_law_state_is_s_v_a_bit_for_bit(run_samples):
    job = plan(EXAMPLE, PlanSettings(robot="ur5e", part_frame=TIGHT))
    prof = next(m.profile for m in job.moves if m.kind == "cut")
    t = np.concatenate(([-1.0, 0.0], np.linspace(0.0, prof.duration, 5001), [prof.duration, prof.duration + 1.0]))
    s, v, a = prof.state(t)
    assert s.tobytes() == prof.s(t).tobytes() and v.tobytes() == prof.v(t).tobytes()
    assert a.tobytes() == prof.a(t).tobytes()


def test_a_spun_job_exports_the_bytes_of_the_straightforward_spin_choice(monkeypatch):
    """The example with the angled nozzle at the tight frame (its run spun): the trajectory and the saved job's
    spin, planned with the shared computations and with the straightforward ones, byte for byte."""
    settings = PlanSettings(robot="ur5e", part_frame=TIGHT, tcp=ANGLED, spin="reach")
    fast = plan(EXAMPLE, settings)
    assert fast.summary()["spin"]["spun_runs"] == 1
    monkeypatch.setattr(sc._Arm, "joints", _reference_joints)
    monkeypatch.setattr(sc, "_step_costs", _reference_step_costs)
    monkeypatch.setattr(sc, "_spin_search", None)  # the numpy search, on the step costs written out
    slow = plan(EXAMPLE, settings)
    for fmt in ("csv", "json"):
        assert export(fast, fmt) == export(slow, fmt)
    spins = [(m.frames.spin.knots.tobytes(), m.frames.spin.coeffs.tobytes()) for m in fast.moves
             if hasattr(m.frames, "spin")]
    assert spins == [(m.frames.spin.knots.tobytes(), m.frames.spin.coeffs.tobytes()) for m in slow.moves
                     if hasattr(m.frames, "spin")]


COMPILED_MISSING = (
    "planner/cam/_spin_search.c is not built: the install found no C compiler (or Python's headers); "
    "install gcc (Debian: apt-get install gcc python3-dev) and run `pip install -e .` again"
)


def test_the_compiled_grid_search_is_built():
    """The install built the compiled grid search (pyproject.toml makes it optional for users; the test command's
    machine has a C compiler, and without it every spin choice would silently take the numpy search)."""
    assert sc._spin_search is not None, COMPILED_MISSING


@pytest.mark.parametrize("tcp", [ANGLED, (0.0, 0.0, 0.1, 0.0, 0.0, 0.3)])  # a spin moves every joint; wrist 3 only
def test_the_compiled_grid_search_is_the_numpy_one_bit_for_bit(run_samples, tcp, monkeypatch):
    """The cheapest path (spins and branch) of the compiled search and of the numpy one, on the example's run: from
    no spin and pinned where the arm is, with rapids before the run (no rate or speed costs there), a spin rate
    bound that costs everywhere, and a step where the run's coordinate stands."""
    assert sc._spin_search is not None, COMPILED_MISSING
    arm = sc._Arm("ur5e", tcp)
    S = run_samples
    if arm.wrist3:
        S = replace(S, p=S.p + np.array([0.0, 0.25, 0.25]))  # the short tool: nearer the arm's middle
    X = S.X.copy()
    X[5] = X[4]
    S = replace(S, X=X)
    paths = []
    for rate, free, pin in ((math.radians(90.0), 0, math.nan), (math.radians(90.0), 10, 0.7), (1e-3, 3, -2.0)):
        got = sc._grid_path(arm, S, rate, free, pin)
        with monkeypatch.context() as m:
            m.setattr(sc, "_spin_search", None)
            want = sc._grid_path(arm, S, rate, free, pin)
        assert got[1] == want[1] and got[0].tobytes() == want[0].tobytes()
        paths.append(got[0])
    assert any(np.ptp(p) > 0.0 for p in paths)  # some path turns the tool


def test_the_compiled_grid_search_refuses_what_it_cannot_read():
    """The kernel is private (_grid_path builds its arrays), but a wrong array is an exception naming it, never a
    read past an array's end."""
    assert sc._spin_search is not None, COMPILED_MISSING
    kernel = sc._spin_search.grid_search
    n, G, K = 4, 5, 2
    args = [np.zeros((6, n, 8, G)), np.ones((n, 8, G), bool), np.zeros((n, 8, G)), np.ones(n - 1), np.ones(n - 1),
            np.zeros((n - 1, 2 * K + 1)), np.ones(6), 0, K, (1.0, 1.0, 1.0, 0.8, 1e6), np.zeros((8, G)),
            np.zeros((n - 1, 8, G), np.int8)]
    kernel(*args)  # as _grid_path calls it
    for i, bad, error, match in ((2, np.zeros((n, 8, G + 1)), ValueError, "shapes do not agree"),
                                 (5, np.zeros((n - 1, 2 * K)), ValueError, "shapes do not agree"),
                                 (0, np.zeros((6, n, 8 * G)), ValueError, r"q must be \(6, n, 8, G\)"),
                                 (2, np.zeros((n, 8, G), np.float32), TypeError, "1-byte items, the rest float64"),
                                 (0, np.zeros((6, n, G, 8)).transpose(0, 1, 3, 2), ValueError, "not C-contiguous")):
        with pytest.raises(error, match=match):
            kernel(*args[:i], bad, *args[i + 1:])
