"""Sinumerik CYCLE800 swivel planes (axis by axis, new and additive, reset) and drilling cycles CYCLE81/82 called
alone or modally with MCALL: every point checked against the frame or the cycle's values, and the programs planned
to the same path as their ISO equivalents."""

from __future__ import annotations

import io
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from planner import PlanSettings, plan
from planner.io import read_gcode

MM = 1e-3


def read(text: str, name: str = "t.mpf"):
    return read_gcode(io.StringIO(text), source=name)


def frame(x0, angles, x1, seq="XYZ"):
    """p_part = X0 + R (X1 + p) with R the intrinsic rotations (scipy's upper-case sequence), mm and degrees."""
    R = Rotation.from_euler(seq, angles, degrees=True).as_matrix()
    return R, np.asarray(x0, float) + R @ np.asarray(x1, float)


SWIVEL = """G17 G710 G90
G0 X0 Y0 Z100
CYCLE800(1,"TC1",200000,57,10,20,5,30,-20,15,1,2,3,-1,100,1)
G0 X10 Y5
Z20
G1 Z0 F500
X30
Y25
CYCLE800()
G0 Z100
X0 Y0
"""


def test_cycle800_axis_by_axis_frame_and_tool_axis_until_the_reset():
    tp = read(SWIVEL)
    R, o = frame([10, 20, 5], [30, -20, 15], [1, 2, 3], "XYZ")  # _MODE 57: about X, then Y, then Z
    prog = np.array([[10, 5, 20], [10, 5, 0], [30, 5, 0], [30, 25, 0]], float)
    expect = prog @ R.T + o
    # line 2: (0, 0, 100) before; the swivel retracts (_FR=1): no point until X, Y and Z are known (line 5)
    assert tp.lines.tolist() == [2, 5, 6, 7, 8, 10, 11]
    assert np.allclose(tp.points[1:5] / MM, expect, rtol=0, atol=1e-9)
    assert tp.rapid.tolist() == [True, True, False, False, False, True, True]
    # the tool along the swivelled z while the plane is active, +Z again after CYCLE800()
    assert np.allclose(tp.axes[1:5], R[:, 2], atol=1e-12)
    assert np.allclose(tp.axes[5:], [0, 0, 1], atol=1e-12)
    # after the reset the coordinates are the part's again: X and Y of line 10 are the modal ones carried over
    # (the physical point reached on line 8), Z the programmed one
    assert np.allclose(tp.points[5] / MM, [expect[3, 0], expect[3, 1], 100], atol=1e-9)
    assert np.allclose(tp.points[6] / MM, [0, 0, 100], atol=1e-9)
    assert [e.name for e in tp.events_of("frame")] == ["CYCLE800", "CYCLE800"]


def test_cycle800_zyx_additive_and_the_position_kept_without_retract():
    text = ("G17 G710 G90\nG0 X5 Y0 Z50\n"
            "CYCLE800(0,\"TC1\",0,27,0,0,0,90,0,0,0,0,0,-1,100,1)\n"  # no retract: the tool stays where it is
            "G91 G0 X10\n"  # 10 mm along the swivelled x from there
            "CYCLE800(0,\"TC1\",1,57,0,0,10,0,30,0,0,0,0,-1,100,1)\n"  # additive: in the plane already swivelled
            "G90 G1 X0 Y0 Z0 F300\n")
    tp = read(text)
    R1, o1 = frame([0, 0, 0], [90, 0, 0], [0, 0, 0], "ZYX")  # _MODE 27: A about Z first
    R2, o2 = frame([0, 0, 10], [0, 30, 0], [0, 0, 0], "XYZ")
    p0 = np.array([5, 0, 50.0])
    p1 = p0 + R1 @ np.array([10, 0, 0])
    assert np.allclose(tp.points / MM, [p0, p1, o1 + R1 @ o2], rtol=0, atol=1e-9)
    assert np.allclose(tp.axes[-1], (R1 @ R2)[:, 2], atol=1e-12)
    assert np.allclose(tp.axes[1], R1[:, 2], atol=1e-12)


def test_swivelled_program_plans_to_the_same_path_as_its_iso_equivalent(tmp_path):
    """The swivelled program and an APT file with the same points and tool axes written out plan to the same poses."""
    tp = read(SWIVEL)
    sin = tmp_path / "swivel.mpf"
    sin.write_text(SWIVEL)
    apt = ["FEDRAT/MMPM,500"]
    feeds = tp.feeds
    for k, (p, a) in enumerate(zip(tp.points / MM, tp.axes, strict=True)):
        if tp.rapid[k]:
            apt.append("RAPID")
        elif k and not np.isnan(feeds[k]):
            apt.append(f"FEDRAT/MMPM,{feeds[k] / MM * 60:.6f}")
        apt.append("GOTO/" + ",".join(f"{v:.12f}" for v in (*p, *a)))
    iso = tmp_path / "swivel.apt"
    iso.write_text("\n".join(apt) + "\n")
    s = PlanSettings(path="cam", rate=250.0)
    a, b = plan(sin, s), plan(iso, s)
    pa = np.concatenate([c.poses for c in a.trajectory().chunks()])
    pb = np.concatenate([c.poses for c in b.trajectory().chunks()])
    assert pa.shape == pb.shape and np.abs(pa - pb).max() < 1e-9
    # the cuts' tool z (the approach axis) is minus the swivelled z
    R, _ = frame([10, 20, 5], [30, -20, 15], [1, 2, 3], "XYZ")
    cut = next(c for c in a.trajectory().chunks() if c.kind == "cut")
    z = Rotation.from_rotvec(cut.poses[:, 3:]).as_matrix()[:, :, 2]
    assert np.allclose(z, -R[:, 2], atol=1e-9)


MCALL = """G17 G710 G90 F200
G0 X0 Y0 Z10
MCALL CYCLE81(10,0,2,-5)
G0 X10 Y0
X20
Y10
MCALL
G0 X0 Y0
"""
ISO = """G17 G21 G90 F200
G0 X0 Y0 Z10
G98 G81 X10 Y0 Z-5 R2
X20
Y10
G80
G0 X0 Y0
"""


def test_mcall_cycle81_drills_at_every_position_like_g81(tmp_path):
    tp = read(MCALL)
    z = [round(p[2] / MM, 9) for p in tp.points]
    per_hole = [10, 2, -5, 2, 10]  # positioning at RTP, rapid to RFP + SDIS, feed to DP, out, up to RTP
    assert z == [10] + per_hole * 3 + [10]
    assert [tuple(np.round(p[:2] / MM, 9)) for p in tp.points[1:16:5]] == [(10, 0), (20, 0), (20, 10)]
    feeds = tp.feeds / (MM / 60)
    assert np.allclose(feeds[3::5], 200) and tp.rapid[1:16:5].all() and not tp.rapid[3::5].any()
    iso = read_gcode(io.StringIO(ISO), source="t.nc")
    assert np.allclose(tp.points, iso.points, rtol=0, atol=1e-12)
    assert tp.rapid.tolist() == iso.rapid.tolist()
    assert np.allclose(np.nan_to_num(tp.feeds), np.nan_to_num(iso.feeds), rtol=0, atol=1e-15)
    a = tmp_path / "holes.mpf"
    a.write_text(MCALL)
    b = tmp_path / "holes.nc"
    b.write_text(ISO)
    ja, jb = plan(a, PlanSettings(path="cam")), plan(b, PlanSettings(path="cam"))
    assert [m.kind for m in ja.moves] == [m.kind for m in jb.moves]
    assert ja.count("cut") == 3  # one plunge a hole, never a cut between holes
    pa = np.concatenate([c.poses for c in ja.trajectory(250.0).chunks()])
    pb = np.concatenate([c.poses for c in jb.trajectory(250.0).chunks()])
    assert np.abs(pa - pb).max() < 1e-12


def test_cycle82_alone_and_modal_with_dwell_depth_from_dpr_and_in_a_swivel_plane():
    text = ("G17 G710 G90 F120\nG0 X0 Y0 Z20\n"
            "CYCLE82(20,5,1,,3,0.5)\n"  # alone: at the current position; DPR 3 below RFP 5 -> bottom 2
            "CYCLE800(0,\"TC1\",0,57,0,0,0,0,90,0,0,0,0,-1,100,1)\n"  # swivel: drill along the new z
            "G0 X0 Y0 Z20\n"
            "MCALL CYCLE82(20,0,2,-4,,0.25)\n"
            "X10\nMCALL\nCYCLE800()\n")
    tp = read(text)
    z = [round(p[2] / MM, 9) for p in tp.points[:5]]
    assert z == [20, 6, 2, 6, 20]
    d = tp.events_of("dwell")
    assert [(e.name, e.value, e.line) for e in d] == [("CYCLE82", 0.5, 3), ("CYCLE82", 0.25, 7)]
    assert d[0].index == 3 and tp.points[d[0].index - 1][2] == pytest.approx(2 * MM)  # at the bottom
    R = Rotation.from_euler("XYZ", [0, 90, 0], degrees=True).as_matrix()
    prog = np.array([[0, 0, 20], [10, 0, 20], [10, 0, 2], [10, 0, -4], [10, 0, 2], [10, 0, 20]], float)
    assert np.allclose(tp.points[5:] / MM, prog @ R.T, rtol=0, atol=1e-9)
    assert np.allclose(tp.axes[5:], R[:, 2], atol=1e-12)
    # the hole axis is the swivelled z: every point of the hole on one line along it
    hole = tp.points[6:] / MM
    assert np.allclose(np.cross(hole - hole[0], R[:, 2]), 0.0, atol=1e-9)
    assert math.isclose(float(np.linalg.norm(hole[2] - hole[0])), 24.0, abs_tol=1e-9)  # 20 -> -4
