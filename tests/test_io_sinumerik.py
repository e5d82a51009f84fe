"""The Sinumerik 840D dialect of the G-code reader: a typical NX header (DEF, assignments, CYCLE800/832, SUPA, MSG,
T="name", TURN) and moves with expressions plan to the same path as their ISO equivalent; events kept; every
refused construct named with its line."""

from __future__ import annotations

import io
import math
import warnings

import numpy as np
import pytest

from planner import PlanSettings, plan
from planner.io import InputFileError, InputFileWarning, read_apt, read_gcode, read_toolpath

MM = 1e-3

SINUMERIK = """%_N_PART_MPF
;$PATH=/_N_MPF_DIR
; NX post, Sinumerik 840D
N10 DEF REAL _camtolerance
N20 DEF REAL _X0=10, _Z_HOME=300
N30 _camtolerance=.02
N40 G40 G17 G710 G94 G90 G60 G601 FNORM
N50 CYCLE800(1,"TC1",0,57,0,0,0,0,0,0,0,0,0,-1,100,1)
N60 CYCLE832(_camtolerance,_ORI_FINISH,1)
N70 SUPA G0 Z=_Z_HOME D0
N80 TRAFOOF
N90 COMPOF
N100 MSG("ROUGHING ; FLOOR")
N110 T="MILL_10" ; tool by name
N120 M6
N130 TURN=0
N140 S5000 M3
N150 G0 X=_X0 Y=2*5 Z=_X0/2
N160 G1 Z=-1 F=100*2
N170 X=IC(20) Y=(_X0-5)*2 G64
N180 G2 X=_X0+30 Y=20 CR=10
N190 G3 X40 Y40 I=AC(40) J=AC(30)
N200 R1=SQRT(POT(3)+POT(4)) R2=7 DIV 2 R3=7 MOD 2
N210 G1 X=40+R1*R2 Y=40-R3 F=300
N220 G4 F1.5
N230 X=ROUND(SIN(30)*100) Y=ATAN2(1,1)
N240 G0 Z50
N250 M30
"""

ISO = """%
G40 G17 G21 G94 G90
G53 G0 Z0
M6
S5000 M3
G0 X10 Y10 Z5
G1 Z-1 F200
X30 Y10
G2 X40 Y20 R10
G3 X40 Y40 I0 J10
G1 X55 Y39 F300
G4 P1500
X50 Y45
G0 Z50
M30
%
"""


def read(text: str, name: str = "t.mpf", **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputFileWarning)
        return read_gcode(io.StringIO(text), source=name, **kw)


def test_sinumerik_program_reads_as_its_iso_equivalent():
    sin, iso = read(SINUMERIK), read(ISO, "t.nc")
    assert np.abs(sin.points - iso.points).max() <= 1e-15
    assert sin.rapid.tolist() == iso.rapid.tolist()
    assert np.array_equal(np.isnan(sin.feeds), np.isnan(iso.feeds))
    assert np.allclose(sin.feeds[~sin.rapid], iso.feeds[~iso.rapid], rtol=1e-15, atol=0)
    assert len(sin.arcs) == len(iso.arcs) == 2
    assert np.allclose([a.centre + a.axis for a in sin.arcs], [a.centre + a.axis for a in iso.arcs], rtol=0, atol=1e-15)
    assert np.allclose(sin.points[-3:] / MM, [[55, 39, -1], [50, 45, -1], [50, 45, 50]], rtol=0, atol=1e-12)


def test_sinumerik_and_iso_plan_to_the_same_trajectory(tmp_path):
    (tmp_path / "part.mpf").write_text(SINUMERIK)
    (tmp_path / "part.nc").write_text(ISO)
    settings = PlanSettings(path="cam")
    jobs = [plan(tmp_path / name, settings) for name in ("part.mpf", "part.nc")]
    poses = []
    for job in jobs:
        chunks = list(job.trajectory(250.0).chunks(joints=False))
        poses.append(np.concatenate([c.poses for c in chunks]))
    assert len(jobs[0].passes) == len(jobs[1].passes) >= 2
    assert poses[0].shape == poses[1].shape and poses[0].shape[0] > 100
    assert np.abs(poses[0] - poses[1]).max() <= 1e-12


def test_header_constructs_are_kept_as_events():
    tp = read(SINUMERIK)
    ev = {(e.kind, e.name): e for e in tp.events if e.kind != "arc"}
    assert ev[("setting", "CYCLE832")].value == pytest.approx(0.02 * MM)  # tolerance in metres
    assert ev[("setting", "CYCLE832")].line == 9
    assert ev[("frame", "CYCLE800")].line == 8  # the swivel reset
    assert ev[("home", "G53")].line == 10  # SUPA: machine coordinates, not a part point
    assert ev[("insert", "ROUGHING ; FLOOR")].line == 13  # a ';' inside the string is not a comment
    assert ev[("tool_select", "MILL_10")].line == 14 and ev[("tool_change", "MILL_10")].line == 15
    assert ev[("setting", "TURN")].value == 0.0
    assert {("setting", w) for w in ("FNORM", "G60", "G601", "COMPOF", "G64")} <= set(ev)
    assert ("frame", "TRAFOOF") in ev and ev[("units", "mm")].line == 7  # G710: metric
    assert ev[("dwell", "G4")].value == 1.5  # G4 F1.5: seconds, and not a feed
    assert tp.rapid[0]  # the first point after SUPA is reached by a rapid
    # G4 F1.5 left the feed at F=300 (mm/min)
    assert tp.feeds[-2] == pytest.approx(300 * MM / 60)


def test_dialect_selection():
    # by name
    assert read(SINUMERIK, "p.SPF").points.shape == read(SINUMERIK).points.shape
    # by option, on a stream with another name
    tp = read_gcode(io.StringIO(SINUMERIK), source="p.nc", dialect="sinumerik")
    assert len(tp) == len(read(SINUMERIK)) == 8
    # by content ("auto"), and read_toolpath sniffs such a .txt file as G-code
    assert len(read(SINUMERIK, "p.txt")) == 8
    # ISO keeps its dialect: parentheses are comments, G70 is refused (a bolt-hole pattern there)
    assert len(read("G0 X1 Y2 Z3 (MSG, a comment)\nG1 X2\n", "p.nc")) == 2
    with pytest.raises(InputFileError, match=r"line 1, word G: G70 \(bolt hole circle\)"):
        read("G70 X1 Y2\n", "p.nc", dialect="iso")
    with pytest.raises(ValueError, match="dialect must be"):
        read("G0 X1\n", dialect="heidenhain")


def test_read_toolpath_by_suffix(tmp_path):
    path = tmp_path / "job.MPF"
    path.write_text(SINUMERIK)
    assert len(read_toolpath(path)) == 8
    txt = tmp_path / "job.txt"
    txt.write_text(SINUMERIK.replace("%_N_PART_MPF\n", ""))
    assert len(read_toolpath(txt)) == 8


def test_expressions_and_incremental_words():
    tp = read("DEF INT I=3\nDEF REAL A1=(I+1)*2.5, B1=-I/2\nR10=A1 MOD 3\nG90 G0 X=A1 Y=B1 Z=R10\n"
              "G1 X=IC(-A1) Y=AC(1) Z=COS(60)*4 F=1000\nG91 G1 X=AC(20) Y5\nX=IC(1)\n")
    assert np.allclose(tp.points / MM, [[10, -1.5, 1], [0, 1, 2], [20, 6, 2], [21, 6, 2]], rtol=0, atol=1e-12)


def test_undeclared_global_variable_warns_once_with_its_line():
    with pytest.warns(InputFileWarning, match=r"^t\.mpf line 1: variable _GUD assigned without DEF") as rec:
        tp = read_gcode(io.StringIO("_GUD=5\nG0 X=_GUD Y0 Z0\n"), source="t.mpf")
    assert len([w for w in rec if issubclass(w.category, InputFileWarning)]) == 1
    assert tp.points[0, 0] == pytest.approx(5 * MM)


@pytest.mark.parametrize(
    "text, line, construct, words",
    [
        ("G0 X0 Y0 Z0\nCYCLE800(1,\"TC1\",0,249,0,0,0,0,30,0,0,0,0,-1,100,1)\n", 2, "CYCLE800 _MODE",
         ["_MODE=249", "direct", "kinematics"]),
        ("G0 X0 Y0 Z0\nCYCLE800(1,\"TC1\",0,121,0,0,0,0,30,0,0,0,0,-1,100,1)\n", 2, "CYCLE800 _MODE",
         ["solid angle", "axis by axis"]),
        ("G0 X0 Y0 Z0\nCYCLE800(1,\"TC1\",0,53,0,0,0,0,30,0,0,0,0,-1,100,1)\n", 2, "CYCLE800 _MODE",
         ["_MODE=53", "axis sequence"]),
        ("G0 X0 Y0 Z0\nCYCLE800(1,\"TC1\",2,57,0,0,0,0,30,0,0,0,0,-1,100,1)\n", 2, "CYCLE800 _ST", ["_ST=2"]),
        ("G0 X0 Y0 Z0\nMCALL CYCLE83(10,0,1,-5,,-2,,1,0,0,1,1)\n", 2, "CYCLE83", ["deep-hole", "not read"]),
        ("G0 X0 Y0 Z0\nMCALL CYCLE81(10,,1,-5)\n", 2, "CYCLE81 RFP", ["RFP is not given"]),
        ("G0 X0 Y0 Z0\nCYCLE82(0.5,0,1,-5,,1)\n", 2, "CYCLE82 RTP", ["below the reference plane"]),
        ("G0 X0 Y0 Z0\nCYCLE81(10,0,1)\n", 2, "CYCLE81 DP", ["neither the depth"]),
        ("G0 X0 Y0 Z0\nMCALL G1 X5\n", 2, "MCALL", ["one cycle call"]),
        ("G0 X0 Y0 Z0\nG2 X10 Y0 CR=5 TURN=2\n", 2, "TURN", ["TURN=2", "helical"]),
        ("TRANS X10\nG0 X0 Y0 Z0\n", 1, "TRANS", ["frame"]),
        ("ROT Z=45\nG0 X0 Y0 Z0\n", 1, "ROT", ["frame"]),
        ("G0 X0 Y0 Z0\nIF R1>0 GOTOF END\n", 2, "IF", ["program flow"]),
        ("G0 X0 Y0 Z0\nMARK1:\n", 2, "MARK1:", ["label"]),
        ("$P_UIFR[1]=CTRANS(X,10)\nG0 X0 Y0 Z0\n", 1, "$P_UIFR[1]", ["system variable"]),
        ("G1 X0 Y0 Z0 A3=0 B3=0 C3=1 F9\n", 1, "A3", ["without TRAORI"]),
        ("TRAORI\nG1 X0 Y0 Z0 A3=0 C3=1 F9\n", 2, "B3", ["B3 missing"]),
        ("TRAORI\nG1 X0 Y0 Z0 A3=0 B3=0 C3=0 F9\n", 2, "A3", ["zero"]),
        ("TRAORI\nG1 X0 Y0 Z0 A2=10 F9\n", 2, "A2", ["Euler/RPY"]),
        ("TRAORI\nG0 X0 Y0 Z0\nORIRESET(30,0)\n", 3, "ORIRESET", ["depends on the machine"]),
        ("G0 X0 Y0 Z0\nCIP X10 Y10 I1=5 J1=8\n", 2, "CIP", ["intermediate point"]),
        ("G0 X=_NOPE Y0 Z0\n", 1, "X=", ["variable _NOPE is not defined"]),
        ("G0 X0 Y0 Z0\nG58 X5\n", 2, "G58", ["programmable axial offset"]),
        ("G0 X0 Y0 Z0\nG3 X10 Y0 AR=90\n", 2, "AR", ["arc opening angle"]),
        ("G0 X0 Y0 Z0\nFOOBAR\n", 2, "FOOBAR", ["does not know"]),
        ("G0 X0 Y0 Z0\nX=(1+2\n", 2, "X=", ["missing ')'"]),
        ("G0 X0 Y0 Z0\nX=1/0\n", 2, "X=", ["division by zero"]),
        ("DEF REAL A[3]\n", 1, "DEF", ["no arrays"]),
        ("POCKET3(1,2,3)\n", 1, "POCKET3", ["technology cycle"]),
    ],
)
def test_refused_constructs_name_line_and_construct(text, line, construct, words):
    with pytest.raises(InputFileError) as exc:
        read(text)
    err = exc.value
    assert (err.line, err.field) == (line, construct)
    assert str(err).startswith(f"t.mpf line {line}, {construct}: ")
    for w in words:
        assert w in str(err)


def test_sinumerik_dwell_in_revolutions():
    tp = read("S600 M3\nG0 X0 Y0 Z0\nG1 X1 F100\nG4 S10\nX2\nG4 F=2*1.5\nX3\n")
    assert [d.value for d in tp.events_of("dwell")] == pytest.approx([1.0, 3.0])  # 10 rev at 600 rpm; 3 s
    assert np.allclose(tp.feeds[1:], 100 * MM / 60) and not math.isnan(tp.feeds[-1])  # F unchanged by G4


FIVE_AXIS = """; 5-axis finishing with tool vectors
DEF REAL _S=0.6
G17 G710 G90 G94
TRAORI
ORIWKS ORIVECT
G0 X0 Y0 Z20 A3=0 B3=0 C3=1
G1 Z0 F=500
X10 A3=0 B3=-_S C3=0.8
X20 Y5 A3=_S B3=0 C3=0.8
ORIRESET()
G0 Z30
TRAFOOF
M30
"""

FIVE_AXIS_APT = """RAPID
GOTO/0,0,20,0,0,1
FEDRAT/MMPM,500
GOTO/0,0,0
GOTO/10,0,0,0,-0.6,0.8
GOTO/20,5,0,0.6,0,0.8
GOTO/20,5,0,0,0,1
RAPID
GOTO/20,5,30
"""


def test_traori_tool_vectors_read_as_the_apt_tool_axes(tmp_path):
    sin = read(FIVE_AXIS)
    apt = read_apt(io.StringIO(FIVE_AXIS_APT), source="t.apt")
    assert np.abs(sin.points - apt.points).max() <= 1e-15 and sin.rapid.tolist() == apt.rapid.tolist()
    assert np.abs(sin.axes - apt.axes).max() <= 1e-15
    assert sin.axis_given.tolist() == apt.axis_given.tolist() == [True, False, True, True, True, False]
    assert np.allclose(sin.feeds[~sin.rapid], apt.feeds[~apt.rapid], rtol=1e-15, atol=0)
    (tmp_path / "five.mpf").write_text(FIVE_AXIS)
    (tmp_path / "five.apt").write_text(FIVE_AXIS_APT)
    jobs = [plan(tmp_path / n, PlanSettings(path="cam")) for n in ("five.mpf", "five.apt")]
    assert [m.kind for m in jobs[0].moves] == [m.kind for m in jobs[1].moves]
    assert "reorientation" in [m.kind for m in jobs[0].moves]  # the vector-only block turns the tool in place
    poses = [np.concatenate([c.poses for c in j.trajectory(250.0).chunks(joints=False)]) for j in jobs]
    assert poses[0].shape == poses[1].shape and np.abs(poses[0] - poses[1]).max() <= 1e-12
