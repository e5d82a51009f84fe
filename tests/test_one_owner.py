"""One owner per concept: pose <-> transform conversion (planner.kinematics.poses), rotation conversion
(planner.rotations), the arc-length bookkeeping of the PH splines (planner.curves.piecewise_length); and the names
they replaced, importable for one more release, each warning (DeprecationWarning) with its replacement."""

from __future__ import annotations

import importlib
import re
import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from planner.curves import fit_ph_spline, fit_planar_ph_spline
from planner.curves.piecewise_length import PiecewiseLength
from planner.errors import PlannerError
from planner.kinematics import as_transform, matrix_to_pose, pose_to_matrix
from planner.rotations import matrix_to_rotvec_1, matrix_to_rotvec_n, rotvec_to_matrix_1, rotvec_to_matrix_n

RNG = np.random.default_rng(25)
POSES = np.hstack((RNG.uniform(-1.0, 1.0, (400, 3)), RNG.normal(size=(400, 3))))
POSES[:4, 3:] = [[0.0, 0.0, 0.0], [np.pi, 0.0, 0.0], [0.0, 1e-9, 0.0], [1e-4, -2e-4, 3e-4]]


def test_pose_and_transform_convert_back_and_forth_as_scipy_does():
    T = pose_to_matrix(POSES)
    np.testing.assert_allclose(T[:, :3, :3], Rotation.from_rotvec(POSES[:, 3:]).as_matrix(), rtol=0, atol=1e-15)
    assert np.array_equal(T[:, :3, 3], POSES[:, :3]) and (T[:, 3] == [0, 0, 0, 1]).all()
    back = matrix_to_pose(T)
    assert np.linalg.norm(back[:, 3:], axis=1).max() <= np.pi + 1e-15  # angle in [0, pi]
    gap = Rotation.from_rotvec(back[:, 3:]).inv() * Rotation.from_rotvec(POSES[:, 3:])
    assert gap.magnitude().max() < 1e-14
    for i in (0, 1, 7, 399):  # one pose or transform gives the batch's numbers exactly
        assert np.array_equal(pose_to_matrix(POSES[i]), T[i])
        assert np.array_equal(matrix_to_pose(T[i]), back[i])
        assert np.array_equal(as_transform(POSES[i], "frame"), T[i])  # a user's frame: the same conversion


@pytest.mark.parametrize("value, message", [
    ([0.1, 0.2, 0.3], r"^part_frame: must be a pose \(6,\) \[x, y, z, rx, ry, rz\] or a matrix \(4, 4\), got \(3,\)"),
    ([0.1, 0.2, np.nan, 0, 0, 0], r"^part_frame\[2\]: must be finite, got nan$"),
    (np.diag([1.0, 1.0, 2.0, 1.0]), r"^part_frame: must be a rigid transform"),
    (np.diag([1.0, 1.0, -1.0, 1.0]), r"^part_frame: must be a rigid transform"),
    ("0,0,0,0,0,0", r"^part_frame: must be numbers, got the string"),
])
def test_a_frame_that_is_no_rigid_transform_is_refused_naming_it(value, message):
    with pytest.raises(PlannerError, match=message):
        as_transform(value, "part_frame")


def test_the_float_path_of_the_rotations_matches_scipy_one_and_many_alike():
    r = POSES[:, 3:]
    R = rotvec_to_matrix_n(r)
    assert np.abs(R - Rotation.from_rotvec(r).as_matrix()).max() < 1e-15
    assert all(rotvec_to_matrix_1(*v) == tuple(M.ravel()) for v, M in zip(r.tolist(), R, strict=True))
    back = matrix_to_rotvec_n(R)
    assert np.abs(back - Rotation.from_matrix(R).as_rotvec()).max() < 1e-12
    assert all(matrix_to_rotvec_1(*M.ravel()) == tuple(v) for v, M in zip(back.tolist(), R, strict=True))


def test_both_splines_take_their_arc_length_from_one_implementation():
    t = np.linspace(0.0, 1.5, 9)
    wp = np.column_stack((np.cos(t), np.sin(2 * t), np.zeros_like(t)))
    for spline in (fit_ph_spline(wp), fit_ph_spline(wp, continuity="C1"), fit_planar_ph_spline(wp),
                   fit_planar_ph_spline(wp).to_ph_spline()):
        assert isinstance(spline, PiecewiseLength)
        # the length of a piece is the integral of its speed (16-point Gauss-Legendre: exact for these degrees)
        x, w = np.polynomial.legendre.leggauss(16)
        b = spline.piece_bounds
        for k in range(b.size - 1):
            u = b[k] + 0.5 * (x + 1.0) * (b[k + 1] - b[k])
            integral = 0.5 * (b[k + 1] - b[k]) * (w @ spline.speed(u))
            assert abs(spline.segment_lengths[k] - integral) <= 1e-13 * spline.length
        s = np.linspace(0.0, spline.length, 37)
        u = spline.parameter_at_length(s)
        assert np.abs(spline.arc_length(u) - s).max() <= 1e-12 * spline.length
        np.testing.assert_allclose(spline.cumulative_lengths[[0, -1]], [0.0, spline.length], rtol=0, atol=0)


def _warns(replacement: str):
    return pytest.warns(DeprecationWarning, match=re.escape(replacement))


def test_the_replaced_names_still_work_and_name_their_replacement():
    T = pose_to_matrix(POSES[5])
    with _warns("use planner.kinematics.matrix_to_pose"):
        assert np.array_equal(importlib.import_module("planner.motion").transform_to_pose(T), matrix_to_pose(T))
    old = importlib.import_module("planner.kinematics.rotvec")
    r = POSES[:5, 3:]
    with _warns("use planner.rotations.rotvec_to_matrix_n"):
        assert np.array_equal(old.rotvec_to_matrix(r), rotvec_to_matrix_n(r))
    with _warns("use planner.rotations.matrix_to_rotvec_n"):
        assert np.array_equal(old.matrix_to_rotvec(rotvec_to_matrix_n(r)), matrix_to_rotvec_n(rotvec_to_matrix_n(r)))
    with _warns("use planner.rotations.rotvec_to_matrix_1"):
        assert old.rotvec_to_matrix_1(0.1, 0.2, 0.3) == rotvec_to_matrix_1(0.1, 0.2, 0.3)
    with _warns("use planner.rotations.matrix_to_rotvec_1"):
        assert old.matrix_to_rotvec_1(*np.eye(3).ravel()) == (0.0, 0.0, 0.0)
    with _warns("planner.kinematics.ur_outputs.UR_OUTPUTS"):
        assert importlib.import_module("drivers.modbus_io").OUTPUT_KINDS == {
            "standard": (0, 8), "configurable": (8, 8), "tool": (16, 2)}
    script_text = importlib.import_module("planner.export.script_text")
    with _warns("UR_OUTPUTS[kind].script_setter"):
        assert script_text.SETTERS["tool"] == "set_tool_digital_out"
    with _warns("output_switch(kind, pin, False)"):
        assert script_text.initial_io([]) == []
    validation = importlib.import_module("planner.validation")
    with _warns("has_attributes is deprecated"):
        assert validation.has_attributes(T, "T", "an array", "shape") is T
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the names that stay are no deprecated ones
        from planner.kinematics.ur_outputs import IO_BIT_OFFSET, OUTPUT_PINS
        from planner.motion import OUTPUT_PINS as motion_pins
        from planner.settings import OUTPUT_KINDS
        from planner.trajectory import IO_BIT_OFFSET as trajectory_offsets
    assert OUTPUT_KINDS is OUTPUT_PINS is motion_pins and trajectory_offsets is IO_BIT_OFFSET
