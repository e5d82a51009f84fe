"""The one-pose fast paths of planner.kinematics: inverse, inverse_nearest, forward for one joint vector,
and the float path of the rotation-vector conversions (planner.rotations' *_1 and *_n).

The one-pose inverse kinematics (``inverse_one``, Python floats) is the documented exception to the
block solver: these property tests prove that it gives the block solver's branches (all 8, same order,
same validity) to 1e-12 on random poses and next to the wrist, shoulder and elbow singularities and the
workspace boundary, and that every solution reproduces its pose to 1e-9.
"""

from __future__ import annotations

import dataclasses
import importlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from planner.errors import PlannerError
from planner.kinematics import (
    UnreachableError,
    forward,
    forward_matrix,
    get_model,
    inverse,
    inverse_batch,
    inverse_nearest,
    inverse_path,
    link_frames,
    matrix_to_pose,
    model_names,
    pose_to_matrix,
    wrap_angle,
)
from planner.kinematics.poses import frame_matrix, pose_frame_1, pose_matrices_n
from planner.rotations import matrix_to_rotvec_1, matrix_to_rotvec_n, rotvec_to_matrix_1, rotvec_to_matrix_n

inv = importlib.import_module("planner.kinematics.inverse")
inverse_one = importlib.import_module("planner.kinematics.inverse_one")

NAMES = model_names()
SAME = 1e-12  # scalar against block solver (rad)
ROUND_TRIP = 1e-9  # m, rad

angle = st.floats(-np.pi, np.pi)
joints = st.lists(angle, min_size=6, max_size=6).map(np.array)
sign = st.sampled_from([-1.0, 1.0])
# 0 or +-10^e for e in [-17, -3]: from exact singularity through round-off to clearly regular
tiny = st.one_of(st.just(0.0), st.tuples(sign, st.floats(-17.0, -3.0)).map(lambda t: t[0] * 10.0 ** t[1]))
tcps = st.one_of(
    st.none(),
    st.tuples(
        st.lists(st.floats(-0.2, 0.2), min_size=3, max_size=3), st.lists(angle, min_size=3, max_size=3)
    ).map(lambda t: np.array(t[0] + t[1])),
)


def branches_one(name, pose, tcp=None, q6_ref=0.0):
    """The one-pose solver's 8 branches (None where missing) for a pose."""
    sols, _ = inv._branches_one(get_model(name), [float(v) for v in pose], tcp, q6_ref)
    return sols


def assert_same_as_block_solver(name, pose, tcp=None, q6_ref=0.0):
    """All 8 branches of the one-pose solver equal the block solver's (validity, order, joints to 1e-12);
    every solution reproduces the pose to 1e-9. Returns the number of valid branches."""
    sols = branches_one(name, pose, tcp, q6_ref)
    block = inverse_batch(name, np.asarray(pose)[None], tcp=tcp, q6_ref=q6_ref)
    valid = np.array([q is not None for q in sols])
    assert np.array_equal(valid, block.valid[0])
    if valid.any():
        Q = np.array([q for q in sols if q is not None])
        assert np.abs(wrap_angle(Q - block.q[0][valid])).max() <= SAME
        back = forward_matrix(name, Q, tcp=tcp)
        T = pose_to_matrix(pose)
        assert np.linalg.norm(back[:, :3, 3] - T[:3, 3], axis=1).max() < ROUND_TRIP
        angle = (Rotation.from_matrix(back[:, :3, :3]).inv() * Rotation.from_matrix(T[:3, :3])).magnitude()
        assert angle.max() < ROUND_TRIP
    return int(valid.sum())


def unique_by_definition(q: np.ndarray) -> np.ndarray:
    keep = []
    for row in q:
        if all(np.abs(wrap_angle(row - k)).max() > 1e-9 for k in keep):
            keep.append(row)
    return np.array(keep).reshape(-1, 6)


# --- inverse: the one-pose solver equals the block solver ------------------------------------------


@settings(max_examples=300, deadline=None)
@given(name=st.sampled_from(NAMES), q=joints, tcp=tcps, q6_ref=angle)
def test_random_poses_equal_block_solver(name, q, tcp, q6_ref):
    pose = forward(name, q, tcp=tcp)
    assert assert_same_as_block_solver(name, pose, tcp, q6_ref) >= 1
    sols = inverse(name, pose, tcp=tcp, q6_ref=q6_ref)  # the public result: the block's rows, filtered
    block = inverse_batch(name, pose, tcp=tcp, q6_ref=q6_ref)
    expected = unique_by_definition(block.q[0][block.within_limits[0]])
    assert sols.shape == expected.shape and np.abs(wrap_angle(sols - expected)).max(initial=0.0) <= SAME
    assert np.all(sols > -np.pi) and np.all(sols <= np.pi)


@settings(max_examples=300, deadline=None)
@given(name=st.sampled_from(NAMES), q=joints, base=st.sampled_from([0.0, np.pi, -np.pi]), eps=tiny, q6_ref=angle)
def test_near_wrist_singularity_equals_block_solver(name, q, base, eps, q6_ref):
    q[4] = base + eps  # sin q5 from 0 (q6 set to q6_ref) through 1e-6 (q234, q6 may turn) to 1e-3
    assert assert_same_as_block_solver(name, forward(name, q), q6_ref=q6_ref) >= 1


@settings(max_examples=300, deadline=None)
@given(name=st.sampled_from(NAMES), q=joints, base=st.sampled_from([0.0, np.pi]), eps=tiny)
def test_near_elbow_boundary_equals_block_solver(name, q, base, eps):
    q[2] = base + eps  # arm stretched (q3 = 0) or folded (q3 = pi): cos q3 = +-1, clipped round-off
    assert assert_same_as_block_solver(name, forward(name, q)) >= 1


@settings(max_examples=300, deadline=None)
@given(name=st.sampled_from(NAMES), q=joints, eps3=tiny, eps5=tiny, turn=st.floats(0.1, 3.0), side=sign)
def test_wrist_singular_at_the_elbow_boundary_equals_block_solver(name, q, eps3, eps5, turn, side):
    """Stretched elbow and wrist singularity at once, with q6_ref away from the generating q6: q234 and
    q6 must turn together (the one-pose solver hands these poses to the block solver)."""
    q[2], q[4] = eps3, eps5
    assert assert_same_as_block_solver(name, forward(name, q), q6_ref=q[5] + side * turn) >= 1


@settings(max_examples=300, deadline=None)
@given(name=st.sampled_from(NAMES), q=joints, eps=tiny, rel=st.floats(-1e-3, 1e-3))
def test_workspace_boundary_equals_block_solver(name, q, eps, rel):
    """Arm stretched, then the pose moved along the arm by a tiny or small distance, inwards or out of
    reach: clipped candidates are kept only if forward kinematics reproduces the pose."""
    q[2] = 0.0
    m = get_model(name)
    frames = link_frames(name, q)
    along = frames[3, :3, 3] - frames[1, :3, 3]  # shoulder to wrist 1, perpendicular to z1: q1 unchanged
    T = forward_matrix(name, q)
    T[:3, 3] += (eps + rel * abs(m.a2 + m.a3)) * along / np.linalg.norm(along)
    assert_same_as_block_solver(name, matrix_to_pose(T))


@settings(max_examples=300, deadline=None)
@given(name=st.sampled_from(NAMES), q=joints, eps=tiny, q6_ref=angle)
def test_shoulder_singularity_equals_block_solver(name, q, eps, q6_ref):
    """The wrist centre moved radially onto the d4 cylinder, just inside or just outside it."""
    m = get_model(name)
    T = forward_matrix(name, q)
    p5 = T[:3, 3] - m.d6 * T[:3, 2]
    r = np.hypot(*p5[:2])
    T[:2, 3] += p5[:2] * (m.d4 * (1.0 + eps) / r - 1.0)
    assert_same_as_block_solver(name, matrix_to_pose(T), q6_ref=q6_ref)


def test_the_block_solver_decides_turned_candidates():
    """Where q234 and q6 turn together, solve_one defers to the block solver (and the results agree)."""
    m = get_model("ur5e")
    bent = np.array([0.4, -1.1, 1.2, -0.6, 0.0, 0.3])  # wrist singular, elbow bent: q6 may take any value
    R, p = inv._flange_target_1(forward("ur5e", bent).tolist(), None)
    assert inverse_one.solve_one(m, R, p, bent[5] + 1.0) is not None
    q = np.array([0.4, -1.1, 0.0, -0.6, 0.0, 0.3])  # wrist singular, elbow stretched: q6 = -0.7 is out of reach
    R, p = inv._flange_target_1(forward("ur5e", q).tolist(), None)
    assert inverse_one.solve_one(m, R, p, q[5] - 1.0) is None
    assert assert_same_as_block_solver("ur5e", forward("ur5e", q), q6_ref=q[5] - 1.0) >= 1


def test_unreachable_and_inside_the_shoulder_cylinder():
    m = get_model("ur5e")
    far = np.array([2.0, 0.5, 0.3, 0.0, np.pi, 0.0])
    inside = np.array([0.0, 0.0, 0.5 - m.d6, 0.0, 0.0, 0.0])
    for pose in (far, inside):
        assert assert_same_as_block_solver("ur5e", pose) == 0
        assert inverse("ur5e", pose).shape == (0, 6)


# --- inverse_nearest ---------------------------------------------------------------------------------


def nearest_by_definition(name, pose, q_near, tcp=None):
    """Every valid branch at every whole-turn placement within the limits: the joint-space distance of
    each branch's best placement to q_near, sorted; the valid branches (wrapped); and whether a
    placement lies within round-off (1e-9) of a limit, where inside or outside is a matter of rounding."""
    m = get_model(name)
    sol = inverse_batch(name, pose, tcp=tcp, q6_ref=wrap_angle(q_near[5]))
    dist, edge = [], False
    for q in sol.q[0][sol.valid[0]]:
        cand = np.where(m.multiturn, q + np.arange(-3, 4)[:, None] * 2 * np.pi, q)  # (7, 6) placements
        gap = np.where((cand >= m.lower) & (cand <= m.upper), np.abs(cand - q_near), np.inf)
        dist.append(np.sqrt(np.sum(gap.min(axis=0) ** 2)))
        edge |= bool((np.minimum(np.abs(cand - m.lower), np.abs(cand - m.upper)) < 1e-9).any())
    return np.sort(dist), sol.q[0][sol.valid[0]], edge


@settings(max_examples=300, deadline=None)
@given(name=st.sampled_from(NAMES), q=joints, q_near=st.lists(st.floats(-2 * np.pi, 2 * np.pi), min_size=6,
       max_size=6).map(np.array), tcp=tcps)
def test_nearest_is_the_nearest_branch_by_definition(name, q, q_near, tcp):
    pose = forward(name, q, tcp=tcp)
    out = inverse_nearest(name, pose, q_near, tcp=tcp)
    dist, branches, edge = nearest_by_definition(name, pose, q_near, tcp)
    assert np.abs(wrap_angle(out - branches)).max(axis=1).min() <= SAME  # a branch, placed by whole turns
    m = get_model(name)
    assert np.all(out >= m.lower) and np.all(out <= m.upper)
    if edge:
        return  # (a joint exactly at a limit, e.g. q = 0 placed at 2 pi: in or out by rounding)
    assert abs(np.linalg.norm(out - q_near) - dist[0]) <= SAME
    unique = len(dist) == 1 or dist[1] > dist[0] + 1e-9  # (else a tie, e.g. a joint pi away: either way)
    if unique and abs(np.sin(q[4])) > 1e-3:  # (inverse_path first tracks with q6_ref = 0 at wrist singularities)
        path = inverse_path(name, pose[None], q_start=q_near, tcp=tcp)[0]  # the tracker's first sample
        if np.all(path >= m.lower) and np.all(path <= m.upper):
            np.testing.assert_allclose(out, path, atol=SAME, rtol=0)


@settings(max_examples=200, deadline=None)
@given(name=st.sampled_from(NAMES), q=st.lists(st.floats(-1.9 * np.pi, 1.9 * np.pi), min_size=6, max_size=6)
       .map(np.array), noise=st.lists(st.floats(-0.01, 0.01), min_size=6, max_size=6).map(np.array))
def test_nearest_recovers_unwrapped_joints(name, q, noise):
    """From joints near the generating ones (anywhere in +-2 pi), the generating joints come back."""
    m = get_model(name)
    T = forward_matrix(name, q)
    p5 = T[:3, 3] - m.d6 * T[:3, 2]
    if abs(np.sin(q[4])) < 0.05 or abs(np.sin(q[2])) < 0.05 or np.hypot(*p5[:2]) < m.d4 + 0.01:
        return  # next to a singularity another branch may be as near
    np.testing.assert_allclose(inverse_nearest(name, forward(name, q), q + noise), q, atol=1e-9, rtol=0)


def test_nearest_at_wrist_singularity_holds_wrist_3():
    q = np.array([0.4, -1.3, 1.2, -0.9, 0.0, 5.0])  # wrist 3 beyond pi: held at q_near's value
    out = inverse_nearest("ur5e", forward("ur5e", q), q + [0, 0, 0, 0, 0, 0.2])
    assert out[5] == pytest.approx(5.2, abs=1e-12)
    np.testing.assert_allclose(forward("ur5e", out), forward("ur5e", q), atol=1e-12)


def test_nearest_turns_back_inside_the_limits():
    m = get_model("ur10e")
    q = np.array([0.5, -1.4, 1.6, -1.7, 1.3, 0.5])
    q_near = q + [0, 0, 0, 0, 0, 2 * np.pi - 0.2]  # wrist 3 near its upper limit 2 pi
    pose = forward("ur10e", q)
    unlimited = inverse_path("ur10e", pose[None], q_start=q_near)[0]
    assert unlimited[5] == pytest.approx(q[5] + 2 * np.pi) and unlimited[5] > m.upper[5]  # the limit matters
    out = inverse_nearest("ur10e", pose, q_near)
    assert np.all(out >= m.lower) and np.all(out <= m.upper)
    assert np.linalg.norm(out - q_near) == pytest.approx(nearest_by_definition("ur10e", pose, q_near)[0][0], abs=1e-12)
    assert np.linalg.norm(out - q_near) > np.linalg.norm(unlimited - q_near)


def test_nearest_unreachable_says_why():
    m = get_model("ur5e")
    with pytest.raises(UnreachableError, match=r"^no inverse kinematics solution: out of reach of ur5e") as e:
        inverse_nearest("ur5e", [2.0, 0.5, 0.3, 0.0, np.pi, 0.0], np.zeros(6))
    assert e.value.index is None and isinstance(e.value, PlannerError)
    with pytest.raises(UnreachableError, match=r"closer than d4"):
        inverse_nearest("ur5e", [0.0, 0.0, 0.5 - m.d6, 0.0, 0.0, 0.0], np.zeros(6))
    narrow = dataclasses.replace(m, name="narrow", q_min=(-0.1,) * 6, q_max=(0.1,) * 6)
    with pytest.raises(UnreachableError, match=r"outside the joint limits of narrow"):
        inverse_nearest(narrow, forward("ur5e", [1.0, -1.2, 1.3, -1.1, 1.4, 0.5]), np.zeros(6))


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: inverse_nearest("ur5e", np.zeros((2, 6)), np.zeros(6)), r"inverse_nearest\(\) takes one pose"),
        (lambda: inverse_nearest("ur5e", [0.3, 0.1, 0.4, 0, np.nan, 0], np.zeros(6)), r"pose\[4\] is nan"),
        (lambda: inverse_nearest("ur5e", [0.3, 0.1, 0.4, 0, 0, 0], np.zeros(5)), r"q_near: expected shape"),
        (lambda: inverse_nearest("ur5e", [0.3, 0.1, 0.4, 0, 0, 0], np.zeros((2, 6))), r"q_near: expected shape"),
        (lambda: inverse_nearest("ur5e", [0.3, 0.1, 0.4, 0, 0, 0], [0, 0, np.inf, 0, 0, 0]), r"q_near\[2\] is inf"),
        (lambda: inverse("ur5e", [0.3, 0.1, 0.4, 0, 0, 0], tcp=[0, 0, "x", 0, 0, 0]), r"tcp: expected numbers"),
        (lambda: inverse("ur5e", [0.3, 0.1, 0.4, 0, 0, 0], q6_ref=np.nan), r"q6_ref\[0\] is not finite"),
        (lambda: forward("ur5e", [0, 0, 0, 0, 0, "a"]), r"q: expected numbers"),
    ],
)
def test_bad_input_names_the_place(call, message):
    with pytest.raises(PlannerError, match=message):
        call()


# --- forward for one joint vector ------------------------------------------------------------------


@settings(max_examples=300, deadline=None)
@given(name=st.sampled_from(NAMES), q=st.lists(st.floats(-2 * np.pi, 2 * np.pi), min_size=6, max_size=6), tcp=tcps)
def test_forward_and_conversions_of_one_equal_batch_exactly(name, q, tcp):
    batch = forward(name, np.array([q, q]), tcp=tcp)
    assert np.array_equal(forward(name, q, tcp=tcp), batch[0])
    assert np.array_equal(forward(name, tuple(q), tcp=tcp), batch[1])
    assert np.array_equal(forward_matrix(name, q, tcp=tcp), forward_matrix(name, np.array([q]), tcp=tcp)[0])
    T = forward_matrix(name, np.array([q, q]), tcp=tcp)
    assert np.array_equal(matrix_to_pose(T[0]), matrix_to_pose(T)[0])
    assert np.array_equal(pose_to_matrix(batch[0]), pose_to_matrix(batch)[0])
    # the float path of the pose conversion (inverse kinematics) and its numpy twin: identical entries, and
    # within round-off of the one public conversion
    one = frame_matrix(*pose_frame_1(batch[0].tolist()))
    assert np.array_equal(one, pose_matrices_n(batch)[0])
    assert np.abs(one - pose_to_matrix(batch[0])).max() < 1e-15


# --- rotation-vector conversions against scipy -------------------------------------------------------


def rotvecs(n: int, seed: int) -> np.ndarray:
    """Rotation vectors: random angles in [0, pi], tiny ones (down to 0), and ones just below pi."""
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    k = n // 4
    theta = np.concatenate([
        rng.uniform(0.0, np.pi, n - 3 * k),
        10.0 ** rng.uniform(-16, -1, k),
        np.pi - 10.0 ** rng.uniform(-12, -2, k),
        np.r_[0.0, np.pi, 1e-3, np.nextafter(1e-3, 1), rng.uniform(0, np.pi, k - 4)],
    ])
    return axis * theta[:, None]


def equivalent_rotvec_gap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|a - b|, or |a + b| where both angles are pi (the same rotation either way round)."""
    gap = np.linalg.norm(a - b, axis=1)
    at_pi = (np.linalg.norm(a, axis=1) > np.pi - 1e-9) & (np.linalg.norm(b, axis=1) > np.pi - 1e-9)
    return np.where(at_pi, np.minimum(gap, np.linalg.norm(a + b, axis=1)), gap)


def test_rotvec_to_matrix_matches_scipy():
    r = rotvecs(4000, 1)
    R = rotvec_to_matrix_n(r)
    assert np.abs(R - Rotation.from_rotvec(r).as_matrix()).max() < 1e-12
    assert np.abs(R @ R.transpose(0, 2, 1) - np.eye(3)).max() < 1e-14
    assert all(rotvec_to_matrix_1(*v) == tuple(M.ravel()) for v, M in zip(r.tolist(), R, strict=True))


def test_matrix_to_rotvec_matches_scipy():
    r = rotvecs(4000, 2)
    R = Rotation.from_rotvec(r).as_matrix()
    ours = matrix_to_rotvec_n(R)
    assert equivalent_rotvec_gap(ours, Rotation.from_matrix(R).as_rotvec()).max() < 1e-12
    assert equivalent_rotvec_gap(ours, r).max() < 1e-12  # and the rotation vectors we started from
    assert np.linalg.norm(ours, axis=1).max() <= np.pi
    assert all(matrix_to_rotvec_1(*M.ravel()) == tuple(v) for v, M in zip(ours.tolist(), R, strict=True))
    # exact half turns: w = 0, the sign is scipy's (first non-zero component positive)
    for M in (np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])):
        np.testing.assert_allclose(matrix_to_rotvec_n(M[None])[0], Rotation.from_matrix(M).as_rotvec(), atol=1e-15)
