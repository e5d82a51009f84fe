"""G-code reader and table-table kinematics: excerpts of the NX 2022 Haas UMC-750 program, hand poses."""

from __future__ import annotations

import io
import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from planner.io import (
    HAAS_UMC_750,
    Arc,
    InputFileError,
    InputFileWarning,
    TableTableKinematics,
    linearize_arcs,
    machine_kinematics,
    read_gcode,
)

IN = 0.0254
IPM = 0.0254 / 60.0


def read(text: str, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputFileWarning)
        return read_gcode(io.StringIO(text), source="t.nc", **kw)


# Lines 1-21 and 41-60 of shared/data/nx2022_haas_umc750_5axis_gcode.txt (BOM, listing header, "%",
# program name, tool table comments), then its last lines; blocks in between left out.
HAAS_HEAD = (
    "\ufeffInformation listing created by\t11dha\n"
    "Date\t15-Apr-2023 14:45:48\n"
    "Current work part\tD:\\DHANUSH_FILES\\Final Part with Operations .prt\n"
    "Node name\tdhanushkk\n"
    "\n"
    "%\n"
    "OFinal ToolPath\n"
    "(PART  FILE  NAME: FINAL PART WITH OPERATIONS .PRT )\n"
    "(PROGRAMMED  UNIT: IN)\n"
    " \n"
    "N5 G40 G17 G94 G98 G90 G00 G49 G20\n"
    " \n"
    "( *** TOOL CHANGE: T01: MILL *** )\n"
    " \n"
    "( OPER: CAVITY_MILL_INSIDE )\n"
    "N10 G53 G00 Z0.0\n"
    "N15 G91 G28 X0.0 Y0.0\n"
    "N20 G91 G28 B0.0 C0.0\n"
    "N25 G90\n"
    "N30 T1 M06\n"
    "N35 T2\n"
    "N50 S1253 M03\n"
    "N70 G00 B0.0 C0.0\n"
    "N85 G90 G00 X2.3803 Y2.2763 M08\n"
    "N90 G43 H01 D01 Z3.1\n"
    "N95 G01 X2.2701 Y2.3302 Z3.0671 F9.8\n"
    "N100 X2.1471 Y2.3384 Z3.0342\n"
    "N120 X1.849 Y2. Z2.9026\n"
    "N125 Y1.849\n"
    "N130 X2.151\n"
    "N180 X.799\n"
    "N185 Y.8754\n"
    "N190 G03 X.8154 Y.8153 I.0932 J-.0067\n"
    "N195 G03 X.8729 Y.799 I.0517 J.0725\n"
    "N200 G01 X3.1246\n"
    "N255 G01 Z3.0026\n"
    "N260 G00 Z3.1394\n"
    "N265 X1.7237 Y2.4127\n"
    "N270 Z3.0026\n"
    "N80205 M30\n"
    "%\n"
    "Tool Path Listing has 16115 lines.\n"
)


def test_haas_head_points_units_and_modal_words():
    tp = read(HAAS_HEAD)
    want = [
        [2.3803, 2.2763, 3.1],  # N90: Z known again after G53/G28, X and Y from N85
        [2.2701, 2.3302, 3.0671],
        [2.1471, 2.3384, 3.0342],
        [1.849, 2.0, 2.9026],
        [1.849, 1.849, 2.9026],  # N125: only Y given
        [2.151, 1.849, 2.9026],
        [0.799, 1.849, 2.9026],
        [0.799, 0.8754, 2.9026],
        [0.8154, 0.8153, 2.9026],
        [0.8729, 0.799, 2.9026],
        [3.1246, 0.799, 2.9026],
        [3.1246, 0.799, 3.0026],
        [3.1246, 0.799, 3.1394],
        [1.7237, 2.4127, 3.1394],
        [1.7237, 2.4127, 3.0026],
    ]
    np.testing.assert_allclose(tp.points, np.array(want) * IN, rtol=0, atol=1e-15)
    assert tp.lines.tolist()[:3] == [25, 26, 27]
    assert tp.units == "inch" and tp.axes is None and tp.rotary is None  # never tilts: no axes


def test_haas_head_rapids_and_feeds():
    tp = read(HAAS_HEAD)
    assert tp.rapid.tolist() == [True] + [False] * 11 + [True, True, True]
    assert np.isnan(tp.feeds[tp.rapid]).all()
    np.testing.assert_allclose(tp.feeds[~tp.rapid], 9.8 * IPM, rtol=1e-15)


def test_haas_head_events():
    tp = read(HAAS_HEAD)
    kinds = [(e.kind, e.line) for e in tp.events if not isinstance(e, Arc)]
    assert kinds[:4] == [("listing", 1), ("partno", 7), ("cutcom", 11), ("units", 11)]
    assert tp.events_of("operation")[0].name == "CAVITY_MILL_INSIDE"
    assert [(e.line, e.value) for e in tp.events_of("tool_change")] == [(20, 1.0)]
    assert [(e.line, e.value) for e in tp.events_of("tool_select")] == [(21, 2.0)]
    (sp,) = tp.events_of("spindle")
    assert sp.name == "CLW" and sp.value == pytest.approx(1253 * 2 * math.pi / 60, rel=1e-15)
    assert [e.name for e in tp.events_of("home")] == ["G53", "G28", "G28"]
    assert tp.events_of("coolant")[0].name == "FLOOD"
    assert tp.events_of("end")[0].line == 40
    assert tp.events[-1].kind == "listing" and tp.events[-1].line == 42
    assert tp.events_of("partno")[0].name == "Final ToolPath"


def test_haas_ijk_arcs_are_kept_with_centre_and_plane():
    tp = read(HAAS_HEAD)
    a1, a2 = tp.arcs
    assert (a1.line, a1.start, a1.index) == (33, 7, 8)
    np.testing.assert_allclose(a1.centre, np.array([0.799 + 0.0932, 0.8754 - 0.0067, 2.9026]) * IN, atol=1e-15)
    assert a1.axis == (0.0, 0.0, 1.0)  # G03 in G17: counter-clockwise about +Z
    for a in (a1, a2):
        r0 = np.linalg.norm(tp.points[a.start] - a.centre)
        r1 = np.linalg.norm(tp.points[a.index] - a.centre)
        assert abs(r0 - r1) < 2e-4 * IN  # the file rounds to 4 decimals


@pytest.mark.parametrize(
    "block, centre, axis",
    [
        ("G03 X0 Y1 R1", (0, 0, 0), (0, 0, 1)),  # short way, counter-clockwise
        ("G03 X0 Y1 R-1", (1, 1, 0), (0, 0, 1)),  # long way (270 degrees)
        ("G02 X0 Y1 R1", (1, 1, 0), (0, 0, -1)),  # clockwise the short way
        ("G02 X0 Y1 I0 J1", (1, 1, 0), (0, 0, -1)),
        ("G18 G03 X0 Z1 I-1 K0", (0, 0, 0), (0, 1, 0)),  # G18: about +Y
        ("G19 G02 Y1 Z1 J0 K1", (1, 0, 1), (-1, 0, 0)),
    ],
)
def test_arc_forms_and_planes(block, centre, axis):
    tp = read(f"G21 G90 G17 G01 X1 Y0 Z0 F100\n{block}\n")
    (arc,) = tp.arcs
    np.testing.assert_allclose(arc.centre, np.array(centre) * 1e-3, atol=1e-15)
    assert arc.axis == pytest.approx(axis)
    p = linearize_arcs(tp, 1e-7).points
    c, n = np.array(arc.centre), np.array(arc.axis)
    r = np.linalg.norm(np.cross(p - c, n), axis=1)
    np.testing.assert_allclose(r, r[0], rtol=1e-9)
    # The motion turns counter-clockwise about the axis: consecutive cross products point along it.
    turn = np.cross(p[:-1] - c, p[1:] - c) @ n
    assert np.all(turn > 0)


def test_helical_arc_linearised_climbs_linearly():
    tp = read("G21 G90 G17 G01 X1 Y0 Z0 F100\nG03 X1 Y0 Z2 I-1 J0\n", arc_tolerance=1e-6)
    p = tp.points
    ang = np.unwrap(np.arctan2(p[:, 1], p[:, 0]))
    assert ang[-1] - ang[0] == pytest.approx(2 * math.pi, abs=1e-12)  # a full turn
    np.testing.assert_allclose(p[:, 2] / 2e-3, (ang - ang[0]) / (2 * math.pi), atol=1e-12)


def test_machine_moves_make_position_unknown():
    tp = read("G21 G90 G00 X1 Y2 Z3\nG53 Z0\nX4 Y5\nG01 Z6 F100\nG91 G28 X0 Y0\nG90 G01 Z7\nX1 Y1\n")
    np.testing.assert_allclose(tp.points / 1e-3, [[1, 2, 3], [4, 5, 6], [1, 1, 7]], atol=1e-12)
    assert tp.rapid.tolist() == [True, True, True]


def test_incremental_moves():
    tp = read("G21 G90 G01 X1 Y1 Z1 F60\nG91 X1 Z-2\nY-3\n")
    np.testing.assert_allclose(tp.points / 1e-3, [[1, 1, 1], [2, 1, -1], [2, -2, -1]], atol=1e-12)
    np.testing.assert_allclose(tp.feeds, 1e-3, rtol=1e-15)


# ---------------------------------------------------------------------------- kinematics
def closed_form_axis(b, c):
    """UMC-750 (ISO table senses): a = Rz(c) Ry(b) z, written out."""
    return np.stack([np.sin(b) * np.cos(c), np.sin(b) * np.sin(c), np.cos(b)], axis=-1)


@pytest.mark.parametrize(
    "b_deg, c_deg, axis",
    [(0, 0, (0, 0, 1)), (0, 137, (0, 0, 1)), (90, 0, (1, 0, 0)), (90, 90, (0, 1, 0)), (90, 180, (-1, 0, 0)),
     (90, -90, (0, -1, 0)), (-90, 0, (-1, 0, 0)), (45, 0, (math.sqrt(0.5), 0, math.sqrt(0.5)))],
)  # fmt: skip
def test_umc750_tool_axis_hand_poses(b_deg, c_deg, axis):
    a = HAAS_UMC_750.tool_axis(math.radians(b_deg), math.radians(c_deg))
    np.testing.assert_allclose(a[0], axis, atol=1e-15)


@settings(max_examples=50, deadline=None)
@given(b=st.floats(-2.0, 2.0), c=st.floats(-12.0, 12.0))
def test_umc750_axis_matches_closed_form_and_is_periodic_in_c(b, c):
    a = HAAS_UMC_750.tool_axis(b, c)[0]
    np.testing.assert_allclose(a, closed_form_axis(b, c), atol=1e-14)
    np.testing.assert_allclose(HAAS_UMC_750.tool_axis(b, c + 2 * math.pi)[0], a, atol=1e-13)
    # Positive signs give the mirrored formula (-sin b cos c, sin b sin c, cos b).
    plus = TableTableKinematics(tilt_sign=1, rotary_sign=1).tool_axis(b, c)[0]
    np.testing.assert_allclose(plus, [-math.sin(b) * math.cos(c), math.sin(b) * math.sin(c), math.cos(b)], atol=1e-14)


@settings(max_examples=40, deadline=None)
@given(
    b=st.floats(-2.0, 2.0),
    c=st.floats(-7.0, 7.0),
    p=st.lists(st.floats(-0.5, 0.5), min_size=3, max_size=3),
    qb=st.lists(st.floats(-0.3, 0.3), min_size=3, max_size=3),
    qc=st.lists(st.floats(-0.3, 0.3), min_size=3, max_size=3),
)
def test_part_points_invert_the_table_motion(b, c, p, qb, qc):
    kin = TableTableKinematics(tilt_point=tuple(qb), rotary_point=tuple(qc))
    rb = Rotation.from_rotvec(-b * np.array([0.0, 1.0, 0.0])).as_matrix()
    rc = Rotation.from_rotvec(-c * np.array([0.0, 0.0, 1.0])).as_matrix()
    p, qb, qc = np.array(p), np.array(qb), np.array(qc)
    # Forward model written out: turn the C table about its axis, then the trunnion about the B axis.
    prog = qb + rb @ (qc + rc @ (p - qc) - qb)
    np.testing.assert_allclose(kin.part_points(prog[None], [b], [c], "machine")[0], p, atol=1e-13)
    np.testing.assert_allclose(kin.part_points((rb @ rc @ p)[None], [b], [c], "dwo")[0], p, atol=1e-13)
    np.testing.assert_allclose(kin.part_points(p[None], [b], [c], "tcpc")[0], p, atol=0)


def test_kinematics_validation_and_presets():
    assert machine_kinematics("Haas UMC-750") is HAAS_UMC_750
    assert machine_kinematics("haas_umc750") is HAAS_UMC_750
    with pytest.raises(ValueError, match="unknown machine"):
        machine_kinematics("dmu-50")
    with pytest.raises(ValueError, match="tilt_axis must be a unit vector"):
        TableTableKinematics(tilt_axis=(0, 2, 0))
    with pytest.raises(ValueError, match="tilt_sign must be -1 or \\+1"):
        TableTableKinematics(tilt_sign=0.5)
    with pytest.raises(ValueError, match="must differ"):
        TableTableKinematics(tilt_word="C")


# Lines 1386-1410 of the Haas file (POCKETING_SIDE_OVAL, a 3+2 pocket under G254 DWO), after a preamble.
DWO = """\
N5 G40 G17 G94 G98 G90 G00 G49 G20
( OPER: POCKETING_SIDE_OVAL )
N6785 G255
N6790 G53 G00 Z0.0
N6795 S1146 M03
N6800 M11 ( C-AXIS UNLOCK )
N6805 M13 ( B-AXIS UNLOCK )
N6810 G00 B82.875 C-180.
N6815 G254
N6820 M10 ( C-AXIS LOCK )
N6825 M12 ( B-AXIS LOCK )
N6830 G54 G90 G00 X-1.9222 Y-2.3215
N6835 G43 H01 D01 Z.2772
N6840 G01 Y-2.5254 Z.2665 F9.8
N6845 X-1.9451 Y-2.5648 Z.2641
N6850 X-1.9846 Y-2.5876 Z.2617
N6855 X-2.0314 Y-2.5875 Z.2592
N7060 X-2.0935 Y-1.4785 Z-.0592
N7065 Y-2.0019 Z-.0866
N7070 Y-2.5019
N7075 G03 X-1.9222 Y-2.5019 I.0856 J0.0
N7105 G01 Z.0134
"""


def test_dwo_block_converted_to_part_frame():
    tp = read(DWO, machine="haas-umc-750")
    b, c = math.radians(82.875), math.radians(-180.0)
    prog = np.array([[-1.9222, -2.3215, 0.2772], [-1.9222, -2.5254, 0.2665], [-1.9451, -2.5648, 0.2641]])
    # p_part = Q^T p_prog with Q^T = Rz(c) Ry(b) for the UMC-750 (written out here).
    ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    rz = np.array([[math.cos(c), -math.sin(c), 0], [math.sin(c), math.cos(c), 0], [0, 0, 1]])
    np.testing.assert_allclose(tp.points[:3], prog @ (rz @ ry).T * IN, atol=1e-15)
    np.testing.assert_allclose(tp.axes, np.broadcast_to(closed_form_axis(b, c), tp.axes.shape), atol=1e-15)
    # The pocket sits in the -X face (x = 0) of the 4 in block, entered from outside (x < 0.01 in).
    x = tp.points[:, 0] / IN
    assert -0.05 < x.min() < 0.01 and 0.3 < x.max() < 0.4
    assert tp.axes[0] @ [-1, 0, 0] > math.cos(math.radians(8))
    assert not tp.axis_given.any()  # B and C were set before the points, in a block of their own
    np.testing.assert_allclose(np.degrees(tp.rotary[0]), [82.875, -180.0], atol=1e-12)
    (arc,) = tp.arcs
    np.testing.assert_allclose(arc.axis, closed_form_axis(b, c), atol=1e-15)  # G17 plane turned with Q
    r0 = np.linalg.norm(tp.points[arc.start] - arc.centre)
    assert r0 == pytest.approx(np.linalg.norm(tp.points[arc.index] - arc.centre), abs=2e-4 * IN)
    assert [e.name for e in tp.events_of("frame")] == ["DWO off", "DWO on", "G54"]


# Lines 1670-1692 of the Haas file (CONTOUR_PROFILE_OUTSIDE, simultaneous 5-axis under G234 TCPC).
TCPC = """\
N5 G40 G17 G94 G98 G90 G00 G49 G20
N8110 S1000 M03
N8120 M11 ( C-AXIS UNLOCK )
N8130 G00 B7.125 C0.0
N8135 G234 H02
N8140 G90 X-.1818 Y1.625 Z3.476
N8145 X-.4347 Z1.4531
N8150 G01 X-.4287 Y1.6354 Z1.4055 F10. M08
N8190 X-.337 Y2. Z1.3275
N8195 Y2.1908 B7.168 C-6.309
N8200 Y2.3815 B7.295 C-12.47
N8210 Y2.763 B7.784 C-23.876
"""


def test_tcpc_blocks_keep_xyz_and_convert_angles():
    tp = read(TCPC, machine=HAAS_UMC_750)
    np.testing.assert_allclose(tp.points[-1], np.array([-0.337, 2.763, 1.3275]) * IN, atol=1e-15)
    bc = np.radians([[7.125, 0.0]] * 4 + [[7.168, -6.309], [7.295, -12.47], [7.784, -23.876]])
    np.testing.assert_allclose(tp.rotary, bc, atol=1e-15)
    np.testing.assert_allclose(tp.axes, closed_form_axis(bc[:, 0], bc[:, 1]), atol=1e-15)
    assert tp.axis_given.tolist() == [False] * 4 + [True] * 3
    np.testing.assert_allclose(tp.feeds[2:], 10 * IPM, rtol=1e-15)
    assert tp.rapid.tolist() == [True, True] + [False] * 5


def test_uncompensated_tilted_blocks_warn_and_use_dwo_frame():
    with pytest.warns(InputFileWarning, match="without G234/G254"):
        tp = read_gcode(io.StringIO("G21 G90 G00 B90. C0\nG01 X1 Y2 Z3 F100\n"), machine="haas-umc-750")
    # Q^T p = Rz(0) Ry(90 deg) (1, 2, 3) = (3, 2, -1): programmed Z (the tool direction) is part +X.
    np.testing.assert_allclose(tp.points[0], [3e-3, 2e-3, -1e-3], atol=1e-15)


def test_rotary_words_at_zero_need_no_machine():
    tp = read("G21 G90 G00 B0.0 C0.0\nG01 X1 Y2 Z3 F100\n")
    assert tp.axes is None and len(tp) == 1


def test_unknown_g_code_warns_with_line():
    with pytest.warns(InputFileWarning, match=r"t\.nc line 2: G12 not understood"):
        read_gcode(io.StringIO("G21 G01 X1 Y1 Z1 F10\nG12\n"), source="t.nc")


@pytest.mark.parametrize(
    "text, line, field, problem",
    [
        ("G21\nN10 G01 X1.2.3 Y0 Z0 F10\n", 2, "word X", "'1.2.3' is not a number"),
        ("G21\nG01 X Y0 Z0 F10\n", 2, "word X", "has no value"),
        ("G01 X1_0 Y0 Z0 F10\n", 1, "word X", "'1_0' is not a number"),
        ("G01 X1 Y0 Z0 F-5\n", 1, "word F", "feed rate must be positive"),
        ("G01 X1 X2 Y0 Z0 F10\n", 1, "word X", "appears twice"),
        ("X1 Y0 Z0\n", 1, "block", "no motion mode"),
        ("#100=1\n", 1, "block", "unexpected text"),
        ("G01 X0 Y0 Z0 F10\nG00 B45. C0\n", 2, "word B", "name the machine kinematics"),
        ("G01 X0 Y0 Z0 F10\nG02 X1 Y1\n", 2, "block", "has neither I/J nor R"),
        ("G01 X0 Y0 Z0 F10\nG03 X10 Y0 R1\n", 2, "word R", "smaller than half the chord"),
        ("G01 X0 Y0 Z0 F10\nG68 X0 Y0 R45\n", 2, "word G", "coordinate rotation"),
        ("G53 Z0\nG02 X1 Y1 Z0 I1 J0\n", 2, "word G", "arc from an unknown position"),
    ],
)
def test_broken_blocks_name_file_line_and_word(text, line, field, problem):
    with pytest.raises(InputFileError) as exc:
        read(text)
    err = exc.value
    assert (err.source, err.line, err.field) == ("t.nc", line, field)
    assert str(err).startswith(f"t.nc line {line}, {field}: ")
    assert problem in str(err)


def test_program_without_motion_is_an_error():
    with pytest.raises(InputFileError, match=r"^t\.nc: holds no motion block"):
        read("%\nG21\nG53 Z0\n%\n")


def test_axis_the_machine_lacks_is_an_error():
    with pytest.raises(InputFileError, match=r"t\.nc line 1, word A: machine 'Haas UMC-750' has no A axis"):
        read("G01 X0 Y0 Z0 A30. F10\n", machine="haas-umc-750")
