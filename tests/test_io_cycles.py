"""Canned drilling cycles expanded into moves (APT CYCLE/..., G-code G73/G81-G89): every point checked against
the cycle's values, one plunge pass per hole through plan(), refusals naming the line and the cycle."""

from __future__ import annotations

import io
import math
import warnings

import numpy as np
import pytest

from planner import PlanSettings, plan
from planner.io import InputFileError, InputFileWarning, ReaderWarning, read_apt, read_gcode

MM = 1e-3
MMPM = 1e-3 / 60.0


def apt(text: str, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputFileWarning)
        return read_apt(io.StringIO(text), source="t.apt", **kw)


def nc(text: str, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputFileWarning)
        return read_gcode(io.StringIO(text), source="t.nc", **kw)


def assert_rows(actual, expect):
    """Rows equal: coordinates and feeds within 1e-9 (mm, mm/min), flags and lines exactly."""
    assert len(actual) == len(expect), (actual, expect)
    for k, (a, e) in enumerate(zip(actual, expect, strict=True)):
        assert a[3:4] + a[5:] == tuple(e[3:4]) + tuple(e[5:]), (k, a, e)
        assert np.allclose(a[:3], e[:3], rtol=0, atol=1e-9), (k, a, e)
        assert (a[4] is None) == (e[4] is None) and (a[4] is None or abs(a[4] - e[4]) <= 1e-9), (k, a, e)


def rows(tp):
    """(x, y, z in mm, rapid, feed in mm/min, line) of every point."""
    return [(*np.round(p / MM, 9).tolist(), bool(r), None if math.isnan(f) else round(f / MMPM, 9), int(n))
            for p, r, f, n in zip(tp.points, tp.rapid, tp.feeds, tp.lines, strict=True)]


APT_DRILL = """FEDRAT/MMPM,500
GOTO/0,0,50
CYCLE/DRILL,FEDTO,-10,RAPTO,3,RTRCTO,5,MMPM,120
GOTO/10,0,0
GOTO/20,0,0
GOTO/30,5,-2
CYCLE/OFF
GOTO/40,0,50
"""


def test_apt_drill_three_holes_point_by_point():
    tp = apt(APT_DRILL)
    expect = [(0, 0, 50, False, 500, 2)]
    z_prev = 50
    for x, y, top, line in ((10, 0, 0, 4), (20, 0, 0, 5), (30, 5, -2, 6)):
        expect += [
            (x, y, z_prev, True, None, line),  # traverse at the current level
            (x, y, top + 3, True, None, line),  # rapid to RAPTO above the hole
            (x, y, top - 10, False, 120, line),  # feed to FEDTO depth at the cycle's feed
            (x, y, top + 3, True, None, line),  # rapid out to the clearance level
            (x, y, top + 5, True, None, line),  # then to RTRCTO
        ]
        z_prev = top + 5
    expect.append((40, 0, 50, False, 500, 8))  # FEDRAT resumes after CYCLE/OFF
    assert_rows(rows(tp), expect)
    assert [e.name for e in tp.events_of("cycle")] == ["DRILL", "OFF"]


def test_apt_peck_dwell_and_units():
    tp = apt("UNITS/INCH\nGOTO/0,0,1\nCYCLE/DRILL,DEEP,FEDTO,0.5,RAPTO,0.1,STEP,0.2,DWELL,1.5,IPM,10\n"
             "GOTO/1,0,0\nCYCLE/OFF\n")
    z = [round(p[2] / 0.0254, 9) for p in tp.points]
    # traverse, R, peck to -0.1, out to R, back to 0.5 mm above -0.1, peck to -0.3, ..., bottom -0.5, out
    c = 0.5e-3 / 0.0254
    assert z == pytest.approx([1, 1, 0.1, -0.1, 0.1, -0.1 + c, -0.3, 0.1, -0.3 + c, -0.5, 0.1])
    assert tp.rapid.tolist() == [False, True, True, False, True, True, False, True, True, False, True]
    assert np.allclose(tp.feeds[~tp.rapid][1:], 10 * 0.0254 / 60)
    (dwell,) = tp.events_of("dwell")
    assert dwell.value == 1.5 and dwell.index == 10 and dwell.line == 4  # after the bottom point (index 9)


def test_apt_break_chip_tap_and_auto_retract_on_a_tilted_axis():
    a = np.array([0.0, -0.6, 0.8])
    tp = apt("GOTO/0,0,20,0,0,1\nCYCLE/BRKCHP,FEDTO,-4,RAPTO,2,STEP,2,RTRCTO,AUTO,MMPM,100\n"
             f"GOTO/10,10,0,{a[0]},{a[1]},{a[2]}\nCYCLE/TAP,FEDTO,-3,RAPTO,1,MMPM,60\nGOTO/30,0,0,0,0,1\nCYCLE/OFF\n")
    hole = np.array([10.0, 10.0, 0.0])
    rel = tp.points[1:10] / MM - hole
    lv = rel @ a  # levels along the hole's tool axis
    came = float((np.array([0, 0, 20]) - hole) @ a)  # 22 mm: where the tool came from (RTRCTO,AUTO)
    assert np.abs(rel - lv[:, None] * a).max() < 1e-9 and np.allclose(tp.axes[1:10], a)
    # R 2, pecks of 2 from R to 0, -2, -4, backing off 0.5 mm between them, out to R, then back to 22
    assert lv == pytest.approx([came, 2, 0, 0.5, -2, -1.5, -4, 2, came])
    assert tp.rapid[1:10].tolist() == [True, True, False, True, False, True, False, True, True]
    assert np.allclose(tp.feeds[1:10][~tp.rapid[1:10]], 100 * MMPM)
    # TAP feeds in and out at its feed, retracting to RAPTO (no RTRCTO)
    z_now = (hole + came * a)[2]
    assert_rows(rows(tp)[10:], [(30, 0, z_now, True, None, 5), (30, 0, 1, True, None, 5),
                                           (30, 0, -3, False, 60, 5), (30, 0, 1, False, 60, 5)])


def test_apt_real_nx_drill_form_without_earlier_motion():
    # NX DRILLING operation as posted (first record of the motion is the cycle; FEDTO 0 is the hole top)
    tp = apt("CYCLE/DRILL,RAPTO,3.0000,FEDTO,0.0000,MMPM,250.0000\n"
             "GOTO/66.0000,0.0000,240.0000,0.0000000,0.0000000,1.0000000\nGOTO/-255.0000,0.0000,240.0000\n"
             "CYCLE/OFF\n")
    assert_rows(rows(tp), [
        (66, 0, 243, True, None, 2), (66, 0, 240, False, 250, 2), (66, 0, 243, True, None, 2),
        (-255, 0, 243, True, None, 3), (-255, 0, 240, False, 250, 3), (-255, 0, 243, True, None, 3)])


GCODE_DRILL = """%
G90 G17 G21 G94
G00 X0 Y0 Z50
G98 G81 X10 Y0 Z-10 R3 F120
X20
G99 X30 Y5 Z-2 R1
G80
G00 Z50
M30
%
"""


def test_gcode_g81_three_holes_point_by_point():
    tp = nc(GCODE_DRILL)
    assert_rows(rows(tp), [
        (0, 0, 50, True, None, 3),
        (10, 0, 50, True, None, 4), (10, 0, 3, True, None, 4), (10, 0, -10, False, 120, 4),
        (10, 0, 3, True, None, 4), (10, 0, 50, True, None, 4),  # G98: back to the initial level
        (20, 0, 50, True, None, 5), (20, 0, 3, True, None, 5), (20, 0, -10, False, 120, 5),
        (20, 0, 3, True, None, 5), (20, 0, 50, True, None, 5),
        (30, 5, 50, True, None, 6), (30, 5, 1, True, None, 6), (30, 5, -2, False, 120, 6),
        (30, 5, 1, True, None, 6),  # G99: stays at R
        (30, 5, 50, True, None, 8),
    ])
    assert [e.name for e in tp.events_of("cycle")] == ["G81", "G80"]


def test_gcode_g83_g73_pecks_g82_dwell_and_incremental_repeats():
    tp = nc("G90 G21 G00 X0 Y0 Z10\nG99 G83 X0 Y0 Z-5 R2 Q3 F100\nG73 X5 Z-5 R2 Q3\nG82 X9 Z-1 R2 P250\n"
            "G82 X12 P1.5\nG91 G81 X4 Z-3 R-8 L2\nG80\n")
    z = [round(p[2] / MM, 9) for p in tp.points]
    c = 0.5  # the default peck clearance, mm
    g83 = [10, 2, -1, 2, -1 + c, -4, 2, -4 + c, -5, 2]  # full retract to R between pecks of 3 from R
    g73 = [2, -1, -1 + c, -4, -4 + c, -5, 2]  # traverse at R to X5, pecks backing off by c
    g82 = [2, -1, 2]  # traverse at R (G99), R already reached, feed, out
    g91 = [2, -1, 2, 2, -1, 2]
    assert z == pytest.approx(g83 + g73 + g82 + g82 + g91)
    dwell = tp.events_of("dwell")
    assert [d.value for d in dwell] == [0.25, 1.5]  # P250 ms, P1.5 s
    # G91 G81 X4 Z-3 R-8 L2 from (12, 0, 2): initial level 10 (the cycle started at Z10), R = 10 - 8 = 2,
    # bottom R - 3 = -1; two holes 4 mm apart
    tail = rows(tp)[-6:]
    assert_rows(tail, [(16, 0, 2, True, None, 6), (16, 0, -1, False, 100, 6), (16, 0, 2, True, None, 6),
                                  (20, 0, 2, True, None, 6), (20, 0, -1, False, 100, 6), (20, 0, 2, True, None, 6)])


@pytest.mark.parametrize(
    "reader, text, line, words",
    [
        (apt, "GOTO/0,0,9\nCYCLE/FOO,FEDTO,-3\nGOTO/1,0,0\n", 2, ["CYCLE/FOO", "'FOO'"]),
        (apt, "GOTO/0,0,9\nCYCLE/BORE,BACK,FEDTO,-3\nGOTO/1,0,0\n", 2, ["CYCLE/BORE,BACK", "back boring"]),
        (apt, "GOTO/0,0,9\nCYCLE/DRILL,RAPTO,3\nGOTO/1,0,0\n", 2, ["CYCLE/DRILL", "no FEDTO"]),
        (apt, "GOTO/0,0,9\nCYCLE/DRILL,FEDTO,-3,SPIRAL,2\n", 2, ["'SPIRAL'", "CYCLE/DRILL"]),
        (apt, "GOTO/0,0,9\nCYCLE/DRILL,FEDTO,-3\nCIRCLE/0,0,0,0,0,1\n", 3, ["CIRCLE", "CYCLE/DRILL"]),
        (nc, "G0 X0 Y0 Z9\nG76 X1 Z-3 R1 Q0.1\n", 2, ["G76", "fine boring"]),
        (nc, "G0 X0 Y0 Z9\nG87 X1 Z-3 R1\n", 2, ["G87", "back boring"]),
        (nc, "G0 X0 Y0 Z9\nG84.1 X1 Z-3 R1\n", 2, ["G84.1", "canned cycle"]),
        (nc, "G0 X0 Y0 Z9\nG83 X1 Z-3 R1 F50\n", 2, ["G83", "Q"]),
        (nc, "G0 X0 Y0 Z9\nG81 X1 Z3 R1 F50\n", 2, ["G81", "not below the clearance"]),
        (nc, "G0 X0 Y0 Z9\nG81 X1 R1 F50\n", 2, ["G81", "no Z level"]),
    ],
)
def test_refused_cycles_name_line_and_cycle(reader, text, line, words):
    with pytest.raises(InputFileError) as exc:
        reader(text)
    assert exc.value.line == line and str(exc.value).startswith(f"{exc.value.source} line {line}")
    for w in words:
        assert w in str(exc.value)


@pytest.mark.parametrize("form", ["apt", "gcode"])
def test_plan_gives_one_plunge_pass_per_hole_and_no_cut_between_holes(form, tmp_path):
    if form == "apt":
        path = tmp_path / "drill.apt"
        path.write_text(APT_DRILL.replace("CYCLE/OFF\nGOTO/40,0,50\n", "CYCLE/OFF\n"))
    else:
        path = tmp_path / "drill.nc"
        path.write_text(GCODE_DRILL)
    job = plan(path, PlanSettings(path="cam", feed=0.01))
    cuts = [m for m in job.moves if m.kind == "cut"]
    assert len(cuts) == 3  # one plunge a hole
    holes = [(10, 0), (20, 0), (30, 5)]
    for m, (x, y) in zip(cuts, holes, strict=True):
        pts = m.item.points / MM
        assert np.allclose(pts[:, :2], (x, y), atol=1e-9)  # on the hole axis, never across holes
        assert pts[0, 2] > pts[-1, 2]  # downwards
        assert np.allclose(m.item.feeds[1:], 120 * MMPM)
    # the trajectory moves between holes only in rapids: every sample off a hole axis is outside a pass
    chunks = list(job.trajectory(250.0).chunks(joints=False))
    xy = np.concatenate([c.poses[:, :2] for c in chunks]) / MM
    in_pass = np.concatenate([np.full(len(c), c.pass_index) for c in chunks]) >= 0
    on_axis = np.zeros(len(xy), bool)
    for x, y in holes:
        on_axis |= np.hypot(xy[:, 0] - x, xy[:, 1] - y) < 1e-6
    assert on_axis[in_pass].all()


def test_reader_warnings_are_one_self_contained_line(tmp_path):
    text = "GOTO/0,0,9\nCYCLE/DRILL,DEEP,FEDTO,-3,RAPTO,1\nGOTO/1,0,0\nCYCLE/OFF\n" + "FOO/1\n" * 7
    with pytest.warns(ReaderWarning) as rec:
        read_apt(io.StringIO(text), source="t.apt")
    msgs = [w.message for w in rec if issubclass(w.category, ReaderWarning)]
    first = msgs[0]
    assert isinstance(first, InputFileWarning) and (first.source, first.line) == ("t.apt", 2)
    assert str(first) == "t.apt line 2: CYCLE/DRILL,DEEP gives no STEP: each hole is drilled in one feed"
    assert [str(m) for m in msgs[1:]] == [f"t.apt line {n}: unknown record 'FOO/1' skipped" for n in range(5, 10)] + [
        "t.apt: 2 more 'FOO' records (last at line 11) not listed"]
    assert all("\n" not in str(m) for m in msgs)
    assert str(ReaderWarning("f.nc", 3, "two\nlines")) == "f.nc line 3: two lines"
    # plan() keeps the same one-line messages for the front ends
    path = tmp_path / "t.apt"
    path.write_text("FEDRAT/MMPM,100\n" + text.replace("FOO/1\n", "") + "GOTO/5,0,9\nGOTO/9,0,9\n")
    job = plan(path, PlanSettings(path="cam"))
    assert job.warnings == ("t.apt line 3: CYCLE/DRILL,DEEP gives no STEP: each hole is drilled in one feed",)


def test_apt_holes_follow_the_msys_frame_and_gcode_holes_the_plane():
    # MSYS: CL x along part +Y, CL y along part -X, origin (100, 0, 0); the holes are expanded in the CL frame
    tp = apt("MSYS/100,0,0,0,1,0,-1,0,0\nGOTO/0,0,30\nCYCLE/DRILL,FEDTO,-4,RAPTO,2,MMPM,100\nGOTO/10,5,0\nCYCLE/OFF\n")
    expect_cl = np.array([[0, 0, 30], [10, 5, 30], [10, 5, 2], [10, 5, -4], [10, 5, 2]], float)
    rot = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], float)  # columns: the CL axes in the part frame
    assert np.allclose(tp.points / MM, expect_cl @ rot.T + [100, 0, 0], rtol=0, atol=1e-12)
    # G18: the drilling axis is Y (R and the bottom are Y levels), the hole position X and Z
    tp = nc("G90 G18 G21 G0 X0 Y50 Z0\nG99 G81 X10 Z5 Y-3 R2 F60\nX20\nG80\n")
    assert_rows(rows(tp)[1:], [
        (10, 50, 5, True, None, 2), (10, 2, 5, True, None, 2), (10, -3, 5, False, 60, 2), (10, 2, 5, True, None, 2),
        (20, 2, 5, True, None, 3), (20, -3, 5, False, 60, 3), (20, 2, 5, True, None, 3)])


def test_peck_clearance_option():
    text = "G90 G21 G0 X0 Y0 Z10\nG99 G73 X0 Y0 Z-5 R2 Q3 F100\nG80\n"
    z = nc(text, peck_clearance=0.2e-3).points[:, 2] / MM
    assert z == pytest.approx([10, 2, -1, -0.8, -4, -3.8, -5, 2])
    with pytest.raises(ValueError, match="peck_clearance"):
        nc(text, peck_clearance=0.0)
    apt_z = apt("GOTO/0,0,9\nCYCLE/BRKCHP,FEDTO,-4,RAPTO,1,STEP,2\nGOTO/0,0,0\n", peck_clearance=1e-3).points[:, 2]
    assert apt_z / MM == pytest.approx([9, 1, -1, 0, -3, -2, -4, 1])
