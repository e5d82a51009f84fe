"""UR models, forward kinematics and closed-form inverse kinematics (planner.kinematics)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from planner.errors import PlannerError
from planner.kinematics import (
    MODELS,
    UnknownModelError,
    forward,
    forward_matrix,
    get_model,
    inverse,
    inverse_batch,
    link_frames,
    matrix_to_pose,
    model_names,
    pose_to_matrix,
    wrap_angle,
)

NAMES = model_names()
ROUND_TRIP = 1e-9  # m for positions, rad for rotations

joints = st.lists(st.floats(-np.pi, np.pi), min_size=6, max_size=6).map(np.array)


def rotation_gap(pose_a, pose_b) -> np.ndarray:
    """Angle (rad) of the rotation taking pose_a's orientation to pose_b's."""
    ra = Rotation.from_rotvec(np.atleast_2d(pose_a)[:, 3:])
    rb = Rotation.from_rotvec(np.atleast_2d(pose_b)[:, 3:])
    return (ra.inv() * rb).magnitude()


def position_gap(pose_a, pose_b) -> np.ndarray:
    return np.linalg.norm(np.atleast_2d(pose_a)[:, :3] - np.atleast_2d(pose_b)[:, :3], axis=1)


def poe_forward(name: str, q: np.ndarray) -> np.ndarray:
    """Independent forward kinematics: product of exponentials about the joint axes at q = 0.

    Axes at the zero configuration, worked out by hand from the DH table (frame i-1 z axis through
    the origin of frame i-1; frame 1 is Rx(pi/2), so z1 = -y; frame 4 is Rx(pi), so z4 = -z):
      joint 1: (0, 0, 1) through (0, 0, 0)          joint 4: (0, -1, 0) through (a2 + a3, 0, d1)
      joint 2: (0, -1, 0) through (0, 0, d1)        joint 5: (0, 0, -1) through (a2 + a3, -d4, 0)
      joint 3: (0, -1, 0) through (a2, 0, d1)       joint 6: (0, -1, 0) through (a2 + a3, 0, d1 - d5)
    and the flange at q = 0: rotation Rx(pi/2), origin (a2 + a3, -(d4 + d6), d1 - d5).
    """
    m = get_model(name)
    a23 = m.a2 + m.a3
    axes = [(0, 0, 1), (0, -1, 0), (0, -1, 0), (0, -1, 0), (0, 0, -1), (0, -1, 0)]
    points = [
        (0, 0, 0), (0, 0, m.d1), (m.a2, 0, m.d1), (a23, 0, m.d1), (a23, -m.d4, 0), (a23, 0, m.d1 - m.d5)
    ]
    R = Rotation.identity(len(q))
    p = np.zeros((len(q), 3))
    for j in range(6):  # T <- T exp([S_j] q_j), each exp a rotation about a line through points[j]
        Rj = Rotation.from_rotvec(np.outer(q[:, j], axes[j]))
        pj = np.asarray(points[j]) - Rj.apply(points[j])
        p = p + R.apply(pj)
        R = R * Rj
    p_tool = p + R.apply([a23, -(m.d4 + m.d6), m.d1 - m.d5])
    R_tool = R * Rotation.from_rotvec([np.pi / 2, 0, 0])
    return np.hstack([p_tool, R_tool.as_rotvec()])


# --- models ----------------------------------------------------------------------------------------


def test_models_lookup_by_name():
    assert set(NAMES) == {"ur3e", "ur5e", "ur10e", "ur16e", "ur20"}
    assert get_model("UR5e") is MODELS["ur5e"]
    assert get_model(MODELS["ur20"]) is MODELS["ur20"]
    for m in MODELS.values():
        assert m.a2 < 0 and m.a3 < 0 and min(m.d1, m.d4, m.d5, m.d6) > 0
        assert np.all(m.speed_limits > 0) and np.all(m.upper - m.lower > 2 * np.pi)


def test_unknown_model_lists_valid_names():
    with pytest.raises(UnknownModelError, match="'ur7'.*ur3e, ur5e, ur10e, ur16e, ur20"):
        get_model("ur7")
    with pytest.raises(UnknownModelError, match="valid names"):
        forward(5, np.zeros(6))


def test_models_are_frozen():
    with pytest.raises(AttributeError):
        MODELS["ur5e"].d1 = 1.0


# --- forward kinematics ----------------------------------------------------------------------------


def test_ur5e_zero_pose_by_hand():
    # DH chain at q = 0: frame 1 = Rx(pi/2) at (0, 0, d1); links 2, 3 extend along x by a2 + a3;
    # d4 along z3 = z1 = -y; frame 4 = Rx(pi), so d5 along -z; frame 5 = Rx(pi/2), d6 along -y.
    # Tool at (a2 + a3, -(d4 + d6), d1 - d5) = (-0.425 - 0.3922, -(0.1333 + 0.0996), 0.1625 - 0.0997),
    # i.e. x = -(|a2| + |a3|), orientation Rx(pi/2) (rotation vector (pi/2, 0, 0)).
    pose = forward("ur5e", np.zeros(6))
    np.testing.assert_allclose(pose[:3], [-0.8172, -0.2329, 0.0628], atol=1e-15)
    np.testing.assert_allclose(pose[3:], [np.pi / 2, 0, 0], atol=1e-15)


def test_ur5e_upright_pose_by_hand():
    # q = (0, -pi/2, 0, -pi/2, 0, 0): the arm points straight up, links 2 and 3 along +z, wrist 1
    # turns z4 to +z so d5 adds height; tool at (0, -(d4 + d6), d1 + |a2| + |a3| + d5), with tool
    # axes x = -x0, y = -z0, z = -y0.
    T = forward_matrix("ur5e", [0, -np.pi / 2, 0, -np.pi / 2, 0, 0])
    np.testing.assert_allclose(T[:3, 3], [0, -0.2329, 0.1625 + 0.425 + 0.3922 + 0.0997], atol=1e-15)
    np.testing.assert_allclose(T[:3, :3], [[-1, 0, 0], [0, 0, -1], [0, -1, 0]], atol=1e-15)


@pytest.mark.parametrize("name", NAMES)
def test_forward_matches_product_of_exponentials(name):
    q = np.random.default_rng(1).uniform(-2 * np.pi, 2 * np.pi, (500, 6))
    ours, ref = forward(name, q), poe_forward(name, q)
    assert position_gap(ours, ref).max() < 1e-14
    assert rotation_gap(ours, ref).max() < 1e-14


@pytest.mark.parametrize("name", NAMES)
def test_forward_closed_form_matches_dh_chain(name):
    q = np.random.default_rng(2).uniform(-2 * np.pi, 2 * np.pi, (200, 6))
    frames = link_frames(name, q)
    np.testing.assert_allclose(frames[:, 0], np.broadcast_to(np.eye(4), (200, 4, 4)))
    np.testing.assert_allclose(frames[:, 6], forward_matrix(name, q), atol=1e-14)


def test_forward_shapes_and_vectorization():
    q = np.random.default_rng(3).uniform(-np.pi, np.pi, (7, 6))
    batch = forward("ur10e", q)
    assert batch.shape == (7, 6) and forward("ur10e", q[3]).shape == (6,)
    np.testing.assert_array_equal(batch[3], forward("ur10e", q[3]))
    assert forward_matrix("ur10e", q).shape == (7, 4, 4) and link_frames("ur10e", q[0]).shape == (7, 4, 4)
    np.testing.assert_allclose(pose_to_matrix(batch), forward_matrix("ur10e", q), atol=1e-15)
    assert position_gap(matrix_to_pose(forward_matrix("ur10e", q)), batch).max() == 0.0


def test_tcp_offset():
    q = np.array([0.3, -1.1, 1.4, -1.6, 1.2, 0.4])
    tcp = np.array([0.01, -0.02, 0.15, 0.0, 0.3, 0.0])
    T = forward_matrix("ur5e", q, tcp=tcp)
    np.testing.assert_allclose(T, forward_matrix("ur5e", q) @ pose_to_matrix(tcp), atol=1e-15)
    sols = inverse("ur5e", matrix_to_pose(T), tcp=tcp)
    assert np.abs(wrap_angle(sols - q)).max(axis=1).min() < 1e-9


# --- inverse kinematics ----------------------------------------------------------------------------


def well_conditioned(name: str, q: np.ndarray) -> bool:
    """Away from the wrist, elbow and shoulder singularities (where IK solutions coalesce)."""
    m = get_model(name)
    T = forward_matrix(name, q)
    p5 = T[:3, 3] - m.d6 * T[:3, 2]
    return abs(np.sin(q[4])) > 1e-3 and abs(np.sin(q[2])) > 1e-3 and np.hypot(*p5[:2]) > m.d4 + 1e-3


@settings(max_examples=60, deadline=None)
@given(name=st.sampled_from(NAMES), q=joints)
def test_inverse_round_trip_and_contains_generator(name, q):
    pose = forward(name, q)
    sols = inverse(name, pose)
    assert 1 <= len(sols) <= 8 and np.isfinite(sols).all()
    assert np.all(sols > -np.pi) and np.all(sols <= np.pi)
    back = forward(name, sols)
    assert position_gap(back, pose).max() < ROUND_TRIP
    assert rotation_gap(back, pose).max() < ROUND_TRIP
    if well_conditioned(name, q):
        assert np.abs(wrap_angle(sols - q)).max(axis=1).min() < 1e-9


@pytest.mark.parametrize("name", NAMES)
def test_inverse_batch_round_trip(name):
    # Generating joints over +-2 pi: the solution set contains them modulo 2 pi.
    q = np.random.default_rng(4).uniform(-2 * np.pi, 2 * np.pi, (3000, 6))
    poses = forward(name, q)
    sol = inverse_batch(name, poses)
    assert sol.q.shape == (3000, 8, 6) and sol.valid.shape == (3000, 8)
    assert np.isnan(sol.q[~sol.valid]).all() and np.isfinite(sol.q[sol.valid]).all()
    assert np.array_equal(sol.within_limits, sol.valid)  # all UR joints cover (-pi, pi]
    target = np.repeat(poses, sol.valid.sum(axis=1), axis=0)
    back = forward(name, sol.q[sol.valid])
    assert position_gap(back, target).max() < ROUND_TRIP
    assert rotation_gap(back, target).max() < ROUND_TRIP
    err = np.nanmin(np.abs(wrap_angle(sol.q - q[:, None])).max(axis=2), axis=1)
    assert np.quantile(err, 0.999) < 1e-9 and err.max() < 1e-6  # the worst are near singularities


def test_inverse_at_wrist_singularity():
    # q5 = 0: only q4 + q6 is fixed, q6 takes the reference value and the two wrist branches coincide.
    q = np.array([0.4, -1.3, 1.2, -0.9, 0.0, 0.7])
    pose = forward("ur5e", q)
    sols = inverse("ur5e", pose)
    assert len(sols) < 8 and np.isfinite(sols).all()
    assert position_gap(forward("ur5e", sols), pose).max() < ROUND_TRIP
    assert rotation_gap(forward("ur5e", sols), pose).max() < ROUND_TRIP
    singular = np.abs(np.sin(sols[:, 4])) < 1e-9
    assert singular.any() and np.all(sols[singular, 5] == 0.0)
    sols = inverse("ur5e", pose, q6_ref=0.7)
    assert np.abs(wrap_angle(sols - q)).max(axis=1).min() < 1e-9


def test_inverse_at_elbow_and_shoulder_boundaries():
    # Stretched elbow (q3 = 0): the elbow branches coincide; solutions exist and are exact.
    q = np.array([0.2, -0.8, 0.0, -1.0, 1.1, 0.3])
    pose = forward("ur10e", q)
    sols = inverse("ur10e", pose)
    assert 1 <= len(sols) < 8
    assert position_gap(forward("ur10e", sols), pose).max() < ROUND_TRIP
    assert np.abs(wrap_angle(sols - q)).max(axis=1).min() < 1e-6  # acos is sqrt-ill-conditioned here
    # Wrist centre exactly on the shoulder cylinder |p5_xy| = d4: the two shoulder branches coincide.
    m = get_model("ur5e")
    T = forward_matrix("ur5e", [0.0, -1.3, 1.9, -0.5, 1.0, 0.2])
    p5 = T[:3, 3] - m.d6 * T[:3, 2]
    r = np.hypot(*p5[:2])
    T[:2, 3] += p5[:2] * (m.d4 / r - 1.0)  # move radially onto the cylinder, orientation unchanged
    sols = inverse("ur5e", matrix_to_pose(T))
    assert len(sols) >= 1
    assert position_gap(forward("ur5e", sols), matrix_to_pose(T)).max() < ROUND_TRIP


def test_unreachable_pose_has_no_solution():
    far = np.array([2.0, 0.5, 0.3, 0.0, np.pi, 0.0])
    assert inverse("ur5e", far).shape == (0, 6)
    # Wrist centre on the base axis: inside the d4 cylinder, no shoulder angle exists.
    m = get_model("ur5e")
    inside = np.array([0.0, 0.0, 0.5 - m.d6, 0.0, 0.0, 0.0])  # tool z up, wrist centre at (0, 0, 0.5)
    assert inverse("ur5e", inside).shape == (0, 6)
    sol = inverse_batch("ur5e", np.vstack([far, inside]))
    assert not sol.valid.any() and np.isnan(sol.q).all()


def test_wrap_angle_interval():
    x = np.array([np.pi, -np.pi, 3 * np.pi, 0.0, -1e-17, 2 * np.pi + 0.1, -np.nextafter(np.pi, 4)])
    w = wrap_angle(x)
    assert np.all(w > -np.pi) and np.all(w <= np.pi)
    np.testing.assert_allclose(w, [np.pi, np.pi, np.pi, 0.0, -1e-17, 0.1, np.pi], atol=1e-15)


# --- bad input ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: forward("ur5e", np.zeros(5)), r"q: expected shape \(6,\) or \(n, 6\), got \(5,\)"),
        (lambda: forward("ur5e", np.zeros((2, 3, 6))), r"q: expected shape"),
        (lambda: forward("ur5e", [np.zeros(6), [0, 0, 0, np.nan, 0, 0]]), r"q\[1, 3\] \(row 1\) is nan"),
        (lambda: forward("ur5e", ["a"] * 6), r"q: expected numbers"),
        (lambda: forward("ur5e", np.zeros(6), tcp=np.zeros((2, 6))), r"tcp: expected one pose"),
        (lambda: inverse("ur5e", np.zeros(7)), r"pose: expected shape"),
        (lambda: inverse("ur5e", np.zeros((2, 6))), r"inverse\(\) takes one pose"),
        (lambda: inverse("ur5e", [0.3, 0.1, np.inf, 0, 0, 0]), r"pose\[2\] is inf"),
        (lambda: inverse_batch("ur5e", np.zeros((3, 6)), q6_ref=np.zeros(2)), r"q6_ref: expected"),
        (lambda: inverse("ur99", np.zeros(6)), r"unknown robot model 'ur99'; valid names: ur3e"),
        (lambda: matrix_to_pose(np.eye(3)), r"transform: expected shape \(4, 4\)"),
    ],
)
def test_bad_input_names_the_place(call, message):
    with pytest.raises(PlannerError, match=message):
        call()


def test_inverse_batch_takes_transforms_and_refuses_bad_ones():
    """Tool transforms (n, 4, 4) give the branches of their poses (the rotation vectors' round trip only differs by
    round-off); a transform that is not finite, not orthonormal or a reflection is refused naming its row."""
    rng = np.random.default_rng(11)
    tcp = (0.0, 0.05, 0.12, 0.6, 0.0, 0.0)
    q = rng.uniform(-3.0, 3.0, (300, 6))
    T = forward_matrix("ur5e", q, tcp=tcp)
    poses = np.array([matrix_to_pose(t) for t in T])
    a, b = inverse_batch("ur5e", poses, tcp=tcp), inverse_batch("ur5e", T, tcp=tcp)
    assert np.array_equal(a.valid, b.valid) and a.valid.any(axis=1).all()
    assert np.nanmax(np.abs(a.q - b.q)) < 1e-9
    back = forward_matrix("ur5e", b.q[b.valid], tcp=tcp)
    assert np.abs(back - np.repeat(T, b.valid.sum(axis=1), axis=0)).max() < 1e-9
    for bad, what in ((T * 1.01, "orthonormal"), (T.copy(), "finite"), (T.copy(), "proper")):
        if what == "finite":
            bad[7, 1, 2] = np.nan
        if what == "proper":
            bad[7, :3, 0] *= -1.0
        with pytest.raises(PlannerError) as e:
            inverse_batch("ur5e", bad, tcp=tcp)
        assert what in str(e.value) and ("pose[7]" in str(e.value) or what == "orthonormal")
    with pytest.raises(PlannerError, match=r"\(n, 4, 4\)"):
        inverse_batch("ur5e", np.zeros((3, 3, 3)))
