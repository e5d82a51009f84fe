"""Modal tool axes of CAM passes: interpolation without overshoot, rotation-minimizing spin, turns."""

from __future__ import annotations

import io

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation

from planner import PlanSettings, plan
from planner.cam import axis_field, fit_pass
from planner.cam.axes import arc_departure, axis_departure, spin_about_axis, transport, travel_frames, turn_axis
from planner.frames import exact_spherical_rmm
from planner.io import read_toolpath

# A 5-axis APT excerpt in NX style: the axis is written only when it changes (modal).
MODAL = """MULTAX
GOTO/0,0,0,0,0,1
GOTO/10,0,0
GOTO/20,0,0
GOTO/21,0,0,0.5,0,0.8660254
GOTO/22,0,0,0.7071068,0,0.7071068
GOTO/40,0,0
GOTO/60,0,0
GOTO/80,0,0
"""


def cam_job(toolpath, **kw):
    """The CAM polyline model, at the former CAM default feed of 10 mm/s."""
    return plan(toolpath, PlanSettings(path="cam", feed=0.01, **kw))


def modal_job():
    return cam_job(read_toolpath(io.StringIO(MODAL), format="apt"))


def rotation_vectors(F: np.ndarray) -> np.ndarray:
    """Body-frame rotation vectors (n - 1, 3) between consecutive frames (n, 3, 3)."""
    return Rotation.from_matrix(np.matmul(np.swapaxes(F[:-1], 1, 2), F[1:])).as_rotvec()


def test_modal_axis_is_carried_and_hit_at_every_point():
    job = modal_job()
    cut = job.moves[0]
    item = cut.item
    s2 = np.sqrt(0.5)
    expected = np.array([[0, 0, 1]] * 3 + [[0.5, 0, 0.8660254]] + [[s2, 0, s2]] * 4)
    assert np.abs(item.axes - expected).max() <= 1e-7  # the 3-value GOTOs inherit the last vector
    assert list(item.axis_given) == [True, False, False, True, True, False, False, False]
    F = cut.frames.frames(cut.path.waypoint_knots)
    tool_z = -item.axes / np.linalg.norm(item.axes, axis=1, keepdims=True)  # approach axis = -CAM vector
    assert np.abs(F[:, :, 2] - tool_z).max() <= 1e-13
    assert job.max_axis_error_deg <= 1e-10
    # constant stretches stay constant between the points (no ringing): spans 0-1 and 4-6
    k = cut.path.waypoint_knots
    for a, b in ((0, 2), (4, 7)):
        z = cut.frames.axis(np.linspace(k[a], k[b], 501))
        assert np.abs(z - tool_z[a]).max() <= 1e-15


def test_no_overshoot_between_points_unlike_a_c2_spline():
    cut = modal_job().moves[0]
    f = cut.frames
    assert axis_departure(f, samples=64) <= 1e-12  # stays on the CAM great-circle arcs
    u = cut.path.waypoint_knots
    uu = u[:-1, None] + np.diff(u)[:, None] * np.linspace(0.0, 1.0, 65)
    z = CubicSpline(u, f.axes)(uu.ravel())  # what planner.frames.tool_frames interpolates
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    assert np.degrees(arc_departure(z.reshape(uu.shape + (3,)), f.axes[:-1], f.axes[1:]).max()) > 30.0


def varying_pass():
    """A curved pass whose tool axis tilts back and forth (unequal spacing, up to 40 degrees)."""
    t = np.linspace(0.0, 1.0, 15) ** 1.3
    P = np.column_stack((0.1 * t, 0.03 * np.sin(3 * t), 0.01 * t**2))
    tilt = np.radians(40.0) * np.sin(5 * t)
    axes = np.column_stack((np.sin(tilt), 0.3 * np.sin(tilt) ** 2, -np.cos(tilt)))
    fit = fit_pass(P, 1e-5)
    return fit.path, axes / np.linalg.norm(axes, axis=1, keepdims=True), P


def test_spin_is_rotation_minimizing():
    path, axes, P = varying_pass()
    f = axis_field(path, axes)
    u = np.linspace(0.0, path.knots[-1], 20001)
    F = f.frames(u)
    r = rotation_vectors(F)
    along_z = np.abs(np.einsum("ni,ni->n", r, np.array([0.0, 0.0, 1.0])[None].repeat(len(r), 0)))
    assert along_z.max() <= 1e-6 * np.linalg.norm(r, axis=1).max()  # omega . z = 0 (to O(h^2))
    assert np.degrees(spin_about_axis(F)) <= 1e-6
    assert np.degrees(spin_about_axis(travel_frames(P, axes))) > 1.0  # the naive baseline spins


def test_spin_integral_matches_adaptive_quadrature():
    path, axes, _ = varying_pass()
    f = axis_field(path, axes)
    m = f.motion
    end = m.pieces[1]
    b = m.bases[0]

    def rate(x):
        z, dz = m.z(np.array([x])), m.dz(np.array([x]))
        return float(b @ np.cross(z[0], dz[0]) / (1.0 + b @ z[0]))

    k = path.waypoint_knots
    pts = k[(k > 0) & (k < end)]
    ref, err = quad(rate, 0.0, end, points=pts, epsabs=1e-15, epsrel=1e-14, limit=500)
    assert m.spin(np.array([end * (1 - 1e-15)]))[0] == pytest.approx(ref, abs=1e-12)
    # and the frames agree with the frames package's exact RMM (its adaptive rule is ~1e-10 across the
    # kinks of a C1 axis interpolant; the frames here are integrated knot to knot)
    exact = exact_spherical_rmm(m.z, m.dz, f.start, interval=(0.0, path.knots[-1]))
    u = np.linspace(0.0, path.knots[-1], 3001)
    assert np.abs(f.frames(u) - exact.frames(u)).max() <= 1e-9


def test_transport_and_flip_turn_without_spin():
    F = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
    z_new = np.array([0.0, 0.6, 0.8])
    G = transport(F, z_new)
    assert np.array_equal(G[:, 2], z_new) and np.allclose(G.T @ G, np.eye(3), atol=1e-15)
    r = Rotation.from_matrix(G @ F.T).as_rotvec()  # the turn, in the base frame
    assert abs(r @ F[:, 2]) <= 1e-15 and abs(r @ z_new) <= 1e-12  # about an axis normal to both
    n, ang = turn_axis(F, -F[:, 2])  # a flip: about the frame's x column
    assert ang == pytest.approx(np.pi) and np.array_equal(n, F[:, 0])
    assert transport(F, F[:, 2]) is F


def test_reorientation_at_an_axis_jump_turns_in_place():
    text = """MULTAX
GOTO/0,0,0,0,0,1
GOTO/10,0,0
GOTO/10,0,0,0.8660254,0,-0.5
GOTO/20,0,0
"""
    job = cam_job(read_toolpath(io.StringIO(text), format="apt"), rate=500.0)
    assert [m.kind for m in job.moves] == ["cut", "reorientation", "cut"]
    turn = job.moves[1]
    assert turn.item.line == 4 and turn.frames.angle == pytest.approx(np.radians(120.0), abs=1e-7)
    (on_turn,) = [c for c in job.trajectory().chunks() if c.move == 1]
    assert on_turn.kind == "reorientation" and len(on_turn) > 100
    assert np.abs(on_turn.poses[:, :3] - [0.01, 0.0, 0.0]).max() <= 1e-15  # in place
    R = Rotation.from_rotvec(on_turn.poses[:, 3:]).as_matrix()
    r = rotation_vectors(R)
    assert np.abs(np.einsum("ni,ni->n", r, np.tile([0.0, 0.0, 1.0], (len(r), 1)))).max() <= 1e-12
    # it ends exactly on the new axis, where the next pass starts
    assert np.allclose(job.moves[2].start_frame[:, 2], [-0.8660254, 0.0, 0.5], atol=1e-7)
    assert np.array_equal(turn.end_frame, job.moves[2].start_frame)
