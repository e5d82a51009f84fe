"""planner.rotations, the one owner of rotation conversions: against scipy, round trips, sign rule, edge cases."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation, Slerp

from planner import quaternion as qt
from planner.errors import PlannerError
from planner.rotations import (
    RotationInputError,
    matrix_to_quaternion,
    matrix_to_rotvec,
    quaternion_to_matrix,
    quaternion_to_rotvec,
    rotate_vectors,
    rotation_angle,
    rotvec_to_matrix,
    rotvec_to_quaternion,
    slerp_matrices,
)

#: Half turns about the axes and about a diagonal, the identity, and small and near-pi angles.
SPECIAL_ROTVECS = np.array([
    [np.pi, 0, 0], [0, np.pi, 0], [0, 0, np.pi], [np.pi / np.sqrt(3)] * 3, [-np.pi, 0, 0],
    [0, 0, 0], [1e-9, -2e-9, 3e-9], [0, 0, np.pi - 1e-9], [0.3, -1.1, 0.4],
])


def random_matrices(n: int, seed: int = 1) -> np.ndarray:
    R = Rotation.random(n, random_state=seed).as_matrix()
    R[: len(SPECIAL_ROTVECS)] = Rotation.from_rotvec(SPECIAL_ROTVECS).as_matrix()
    return R


def sandwich_matrix(q: np.ndarray) -> np.ndarray:
    """Independent reference: columns q e_k q* / |q|^2 with the Hamilton product of planner.quaternion."""
    cols = [qt.sandwich(q, e, q) / qt.norm2(q)[..., None] for e in (qt.I, qt.J, qt.K)]
    return np.stack(cols, axis=-1)


def test_matrix_to_quaternion_matches_scipy_and_the_sign_rule():
    R = random_matrices(3000)
    q = matrix_to_quaternion(R)
    ref = Rotation.from_matrix(R).as_quat(canonical=True, scalar_first=True)
    np.testing.assert_allclose(q, ref, rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, rtol=0, atol=1e-15)
    assert (q[:, 0] >= 0).all()
    # exact half turns (w = 0): the first nonzero of x, y, z is positive
    half = matrix_to_quaternion(np.array([np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1]),
                                          [[0.0, 1, 0], [1, 0, 0], [0, 0, -1]], [[0.0, -1, 0], [-1, 0, 0], [0, 0, -1]]]))
    s2 = np.sqrt(0.5)
    np.testing.assert_allclose(half, [[0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1], [0, s2, s2, 0], [0, s2, -s2, 0]],
                               rtol=0, atol=2e-16)
    np.testing.assert_array_equal(matrix_to_quaternion(np.eye(3)), [1.0, 0.0, 0.0, 0.0])


def test_quaternion_matrix_round_trips():
    R = random_matrices(2000, seed=2)
    np.testing.assert_allclose(quaternion_to_matrix(matrix_to_quaternion(R)), R, rtol=0, atol=1e-15)
    q = Rotation.random(2000, random_state=3).as_quat(scalar_first=True)
    back = matrix_to_quaternion(quaternion_to_matrix(q))
    np.testing.assert_allclose(back, q * np.sign(q[:, :1]), rtol=0, atol=2e-15)  # q up to the sign rule


def test_quaternion_to_matrix_takes_any_nonzero_quaternion():
    rng = np.random.default_rng(4)
    q = rng.normal(size=(500, 4)) * rng.uniform(1e-3, 1e3, size=(500, 1))  # not unit
    m = quaternion_to_matrix(q)
    np.testing.assert_allclose(m, sandwich_matrix(q), rtol=0, atol=1e-14)
    np.testing.assert_allclose(quaternion_to_matrix(-q), m, rtol=0, atol=0)  # either sign, same matrix
    np.testing.assert_allclose(np.einsum("nji,njk->nik", m, m), np.broadcast_to(np.eye(3), m.shape), atol=1e-15)
    np.testing.assert_allclose(np.linalg.det(m), 1.0, atol=1e-14)
    out = np.full((500, 3, 3), np.nan)
    assert quaternion_to_matrix(q, out=out) is out
    np.testing.assert_array_equal(out, m)


def test_leading_axes_and_empty_arrays():
    R = random_matrices(24, seed=5).reshape(2, 3, 4, 3, 3)
    q = matrix_to_quaternion(R)
    assert q.shape == (2, 3, 4, 4)
    np.testing.assert_allclose(q.reshape(-1, 4), matrix_to_quaternion(R.reshape(-1, 3, 3)), atol=0)
    assert quaternion_to_matrix(q).shape == R.shape
    assert matrix_to_rotvec(R).shape == (2, 3, 4, 3)
    assert rotvec_to_matrix(matrix_to_rotvec(R)).shape == R.shape
    assert matrix_to_quaternion(np.eye(3)).shape == (4,)
    assert rotation_angle(R, R).shape == (2, 3, 4)
    for f, shape, out in ((matrix_to_quaternion, (0, 3, 3), (0, 4)), (quaternion_to_matrix, (0, 4), (0, 3, 3)),
                          (matrix_to_rotvec, (0, 3, 3), (0, 3)), (rotvec_to_matrix, (0, 3), (0, 3, 3)),
                          (rotvec_to_quaternion, (0, 3), (0, 4)), (quaternion_to_rotvec, (0, 4), (0, 3))):
        assert f(np.zeros(shape)).shape == out


def test_read_only_views_are_accepted():
    R = np.broadcast_to(np.eye(3), (5, 3, 3))
    np.testing.assert_array_equal(matrix_to_quaternion(R), np.tile([1.0, 0, 0, 0], (5, 1)))
    v = rotate_vectors(np.array([0.0, 0.0, np.pi / 2]), np.broadcast_to([1.0, 0.0, 0.0], (4, 3)))
    np.testing.assert_allclose(v, np.tile([0.0, 1.0, 0.0], (4, 1)), rtol=0, atol=4e-16)


def test_rotvec_matrix_round_trips_and_angle_pi():
    R = random_matrices(2000, seed=6)
    r = matrix_to_rotvec(R)
    np.testing.assert_allclose(r, Rotation.from_matrix(R).as_rotvec(), rtol=0, atol=1e-14)
    assert np.linalg.norm(r, axis=1).max() <= np.pi + 1e-15
    np.testing.assert_allclose(rotvec_to_matrix(r), R, rtol=0, atol=1e-15)
    # at exactly pi either of the two opposite vectors is right; both give R
    for k in range(5):
        assert np.linalg.norm(r[k]) == pytest.approx(np.pi, abs=1e-15)
        np.testing.assert_allclose(np.abs(r[k]), np.abs(SPECIAL_ROTVECS[k]), atol=1e-15)
    np.testing.assert_array_equal(matrix_to_rotvec(np.eye(3)), np.zeros(3))
    np.testing.assert_array_equal(rotvec_to_matrix(np.zeros(3)), np.eye(3))


def test_quaternion_to_rotvec_matches_scipy_and_keeps_the_sign():
    """The hand-written exception: to 1e-12 of scipy for w >= 0, the 2 pi complement for -q."""
    q = Rotation.random(5000, random_state=7).as_quat(canonical=True, scalar_first=True)
    r = quaternion_to_rotvec(q)
    np.testing.assert_allclose(r, Rotation.from_quat(q, scalar_first=True).as_rotvec(), rtol=0, atol=1e-12)
    r_neg = quaternion_to_rotvec(-q)
    theta = np.linalg.norm(r, axis=1)
    np.testing.assert_allclose(r_neg, r - (2 * np.pi / theta)[:, None] * r, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rotvec_to_matrix(r_neg), rotvec_to_matrix(r), atol=1e-14)
    np.testing.assert_array_equal(quaternion_to_rotvec(np.array([[1.0, 0, 0, 0], [-1.0, 0, 0, 0]])), np.zeros((2, 3)))


def test_rotvec_to_quaternion_keeps_angles_beyond_pi():
    rng = np.random.default_rng(8)
    axis = rng.normal(size=(1000, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    r = rng.uniform(0.0, 2 * np.pi - 1e-6, size=(1000, 1)) * axis  # angles up to (not including) 2 pi
    q = rotvec_to_quaternion(r)
    theta = np.linalg.norm(r, axis=1)
    np.testing.assert_allclose(q[:, 0], np.cos(theta / 2), rtol=0, atol=1e-15)  # negative beyond pi
    np.testing.assert_allclose(q[:, 1:], np.sin(theta / 2)[:, None] * axis, rtol=0, atol=1e-15)
    np.testing.assert_allclose(quaternion_to_rotvec(q), r, rtol=0, atol=1e-12)
    np.testing.assert_allclose(quaternion_to_matrix(q), Rotation.from_rotvec(r).as_matrix(), atol=1e-15)


def test_rotation_angle_matches_scipy_and_is_accurate_for_small_angles():
    """The other hand-written exception: to 1e-12 of scipy's magnitude of R1^T R2."""
    R1, R2 = random_matrices(3000, seed=9), Rotation.random(3000, random_state=10).as_matrix()
    ref = Rotation.from_matrix(np.einsum("nji,njk->nik", R1, R2)).magnitude()
    away = ref < np.pi - 1e-3  # the documented accuracy: eps / cos(theta / 2)
    assert away.sum() > 2900
    for got in (rotation_angle(R1, R2), rotation_angle(R2, R1)):
        np.testing.assert_allclose(got[away], ref[away], rtol=0, atol=4e-12)
        np.testing.assert_allclose(got, ref, rtol=0, atol=3e-8)
    at_pi = rotation_angle(np.eye(3), np.diag([1.0, -1.0, -1.0]))
    assert abs(at_pi - np.pi) < 3e-8
    tiny = np.geomspace(1e-12, 1e-3, 50)
    R3 = Rotation.from_rotvec(tiny[:, None] * np.array([0.6, 0.0, 0.8])).as_matrix() @ R1[:50]
    np.testing.assert_allclose(rotation_angle(R1[:50], R3), tiny, rtol=1e-3)  # trace formula: ~1e-8 absolute
    assert rotation_angle(np.eye(3), np.eye(3)) == 0.0


def test_rotate_vectors_is_the_matrix_product():
    rng = np.random.default_rng(11)
    r, v = rng.normal(size=(300, 3)) * 2.0, rng.normal(size=(300, 3))
    np.testing.assert_allclose(rotate_vectors(r, v), np.einsum("nij,nj->ni", rotvec_to_matrix(r), v), atol=1e-14)
    one = rotate_vectors(r[0], v)  # one rotation broadcast over many vectors
    np.testing.assert_allclose(one, v @ rotvec_to_matrix(r[0]).T, atol=1e-14)


def test_slerp_matrices_matches_scipy_slerp():
    R0, R1 = random_matrices(12, seed=12)[-1], Rotation.from_rotvec([0.4, 2.5, -0.3]).as_matrix()
    s = np.linspace(0.0, 1.0, 101)
    F = slerp_matrices(R0, R1, s)
    ref = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack((R0, R1))))(s).as_matrix()
    np.testing.assert_allclose(F, ref, rtol=0, atol=1e-14)
    np.testing.assert_allclose(F[0], R0, atol=1e-15)
    np.testing.assert_allclose(F[-1], R1, atol=1e-14)
    step = rotation_angle(F[:-1], F[1:])  # constant angular velocity
    np.testing.assert_allclose(step, rotation_angle(R0, R1) / 100, rtol=1e-9)
    # batched: k pairs, each with its own fractions
    A, B = random_matrices(16, seed=13)[-7:], Rotation.random(7, random_state=14).as_matrix()
    lam = np.random.default_rng(15).uniform(size=(7, 5))
    G = slerp_matrices(A, B, lam)
    assert G.shape == (7, 5, 3, 3)
    for k in range(7):
        np.testing.assert_allclose(G[k], Slerp([0.0, 1.0], Rotation.from_matrix(np.stack((A[k], B[k]))))(lam[k])
                                   .as_matrix(), atol=1e-14)


def test_bad_shapes_and_zero_quaternions_name_the_argument():
    with pytest.raises(RotationInputError, match=r"^R: expected an array of shape \(\.\.\., 3, 3\), got shape \(3, 4\)"):
        matrix_to_quaternion(np.zeros((3, 4)))
    with pytest.raises(RotationInputError, match=r"^q: expected .*\(\.\.\., 4\)"):
        quaternion_to_matrix(np.zeros((2, 3)))
    with pytest.raises(RotationInputError, match=r"^r: "):
        rotvec_to_matrix(np.zeros(4))
    with pytest.raises(RotationInputError, match=r"^q\[2\]: is a zero"):
        quaternion_to_matrix(np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 0, 0]]))
    with pytest.raises(RotationInputError, match=r"^s: "):
        slerp_matrices(np.eye(3), np.eye(3), 0.5)
    assert issubclass(RotationInputError, PlannerError)


unit_quaternions = arrays(np.float64, (8, 4), elements=st.floats(-1.0, 1.0)).filter(
    lambda a: (np.linalg.norm(a, axis=1) > 1e-3).all()).map(lambda a: a / np.linalg.norm(a, axis=1, keepdims=True))


@settings(max_examples=60, deadline=None)
@given(unit_quaternions)
def test_hypothesis_round_trips(q):
    R = quaternion_to_matrix(q)
    np.testing.assert_allclose(R, sandwich_matrix(q), atol=1e-14)
    p = matrix_to_quaternion(R)
    assert (p[:, 0] >= 0).all()
    np.testing.assert_allclose(np.abs(np.einsum("ni,ni->n", p, q)), 1.0, atol=1e-13)  # the same rotation
    r = quaternion_to_rotvec(q)
    np.testing.assert_allclose(rotvec_to_matrix(r), R, atol=1e-13)
    turning = np.linalg.norm(q[:, 1:], axis=1) > 1e-3  # angle 2 pi (q = -1) is r = 0, i.e. q = +1
    np.testing.assert_allclose(rotvec_to_quaternion(r[turning]), q[turning], atol=1e-12)  # the sign of q is kept
    np.testing.assert_allclose(rotation_angle(R, rotvec_to_matrix(matrix_to_rotvec(R))), 0.0, atol=1e-7)
