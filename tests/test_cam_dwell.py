"""Dwells held in the plan: a drill cycle's DWELL and G04 make the tool wait at rest at the pose for the
dwell's time, in the stream, the whole-job program (``sleep``), the tables, the budget and the summary."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from planner import PlanSettings, plan
from planner.budget import BudgetError
from planner.export.job_script import job_program
from planner.export.tables import csv_text, json_text
from sim.urscript import compile_program

MM = 1e-3
RATE = 500.0
PART = (0.4, 0.1, 0.2, 0.0, 0.0, 0.0)  # the part 0.4 m in front of a UR5e, 0.2 m up

APT_DWELL = """FEDRAT/MMPM,500
GOTO/0,0,50
CYCLE/DRILL,FEDTO,-10,RAPTO,3,RTRCTO,5,DWELL,0.5,MMPM,120
GOTO/10,0,0
GOTO/20,0,0
GOTO/30,5,-2
CYCLE/OFF
"""
HOLES = ((10, 0, 0, 4), (20, 0, 0, 5), (30, 5, -2, 6))  # x, y, top (mm), source line

GCODE_DWELL = """%
G21 G90 G17
G00 X0 Y0 Z5
G01 Z0 F600
G01 X10
G04 P0.75
G01 X20 Y5
G99 G82 X30 Y0 Z-4 R2 P250 F120
G80
G00 Z20
M30
%
"""


def _file(tmp_path, name: str, text: str):
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def drill_job(tmp_path_factory):
    path = _file(tmp_path_factory.mktemp("dwell"), "drill.apt", APT_DWELL)
    return plan(path, PlanSettings(path="cam", robot="ur5e", part_frame=PART, rate=RATE))


def test_the_stream_holds_the_bottom_pose_for_exactly_the_dwell(drill_job):
    job = drill_job
    assert [m.kind for m in job.moves].count("dwell") == 3
    chunks = list(job.trajectory().chunks())
    dwells = [k for k, c in enumerate(chunks) if c.kind == "dwell"]
    assert len(dwells) == 3
    base = np.array(PART[:3])
    for k, (x, y, top, line) in zip(dwells, HOLES, strict=True):
        c, before, after = chunks[k], chunks[k - 1], chunks[k + 1]
        bottom = base + np.array([x, y, top - 10]) * MM  # FEDTO -10 below the hole, part frame = base + offset
        assert before.kind == "cut" and after.kind == "rapid"  # plunge, dwell, retract
        # every sample of the dwell, and the first sample after it, is the bottom pose, tool axis down
        held = np.vstack((c.poses, after.poses[:1]))
        assert np.abs(held[:, :3] - bottom).max() < 1e-12
        assert np.abs(held - held[0]).max() < 1e-12
        assert np.abs(np.vstack((c.joints, after.joints[:1])) - c.joints[0]).max() < 1e-12
        # the hold lasts exactly the dwell: 0.5 s = 250 periods at 500 Hz, on the job clock
        assert len(c) == 250
        assert after.times[0] - c.times[0] == pytest.approx(0.5, abs=1e-9)
        assert np.allclose(np.diff(c.times), 1.0 / RATE, rtol=0, atol=1e-9)
        assert (c.lines == line).all() and c.pass_index == -1
        # the plunge ended there: its last sample is within a micrometre of the bottom (at rest)
        assert np.linalg.norm(before.poses[-1, :3] - bottom) < 1e-6
    s = job.summary()
    assert s["dwells"] == 3 and s["dwell_s"] == pytest.approx(1.5)
    assert "3 dwells (1.5 s)" in job.describe()[0]
    # the job's duration counts the dwells; the stream's last sample agrees within one period per move
    assert job.duration == pytest.approx(sum(m.duration for m in job.moves))
    assert 0.0 <= job.trajectory().duration - job.duration < len(job.moves) / RATE


def test_the_program_sleeps_at_the_bottom_and_compiles(drill_job):
    prog = job_program(drill_job)
    lines = [x.strip() for x in prog.splitlines()]
    sleeps = [i for i, x in enumerate(lines) if x.startswith("sleep(")]
    assert len(sleeps) == 3
    for i in sleeps:
        assert float(lines[i][6:-1]) == pytest.approx(0.5, abs=1e-12)
        # after the plunge (movep ending with r = 0) and before the retract (movel)
        prev = next(x for x in reversed(lines[:i]) if x and not x.startswith("#"))
        nxt = next(x for x in lines[i + 1:] if x and not x.startswith("#"))
        assert prev.startswith("movep(") and prev.endswith("r=0.000000000000)")
        assert nxt.startswith("movel(")
    assert '"dwells": 3' in prog
    statements = compile_program(prog)  # the simulator's URScript subset runs it
    assert sum(1 for st in statements if st.name == "sleep") == 3


def test_tables_carry_the_dwell(drill_job):
    tr = drill_job.trajectory()
    doc = json.loads("".join(json_text(tr)))
    moves = [m for m in doc["moves"] if m["kind"] == "dwell"]
    assert doc["parameters"]["dwells"] == 3
    assert [(m["first_line"], m["duration_s"], m["samples"]) for m in moves] == [(4, 0.5, 250), (5, 0.5, 250),
                                                                                  (6, 0.5, 250)]
    kind = doc["columns"].index("kind")
    rows = [r for r in doc["samples"] if r[kind] == "dwell"]
    assert len(rows) == 750
    assert len({tuple(r[1:7]) for r in rows}) == 3  # one pose per dwell
    csv_rows = [r for r in "".join(csv_text(tr)).splitlines() if r and not r.startswith("#")]
    assert len(csv_rows) - 1 == tr.n_samples == len(doc["samples"])


def test_g04_in_a_pass_stops_it_and_g82_dwells_at_the_bottom(tmp_path):
    job = plan(_file(tmp_path, "dwell.nc", GCODE_DWELL), PlanSettings(path="cam", rate=RATE))
    kinds = [m.kind for m in job.moves]
    d = [m for m in job.moves if m.kind == "dwell"]
    assert [(m.item.name, m.item.seconds, m.line) for m in d] == [("G04", 0.75, 6), ("G82", 0.25, 8)]
    # G04 between two feed moves: the pass stops at X10, waits, and goes on from the same point
    k = kinds.index("dwell")
    a, b = job.moves[k - 1], job.moves[k + 1]
    assert a.kind == b.kind == "cut" and a.item.end_reason == "dwell" and b.item.start_reason == "dwell"
    assert np.allclose(a.item.points[-1], [10 * MM, 0, 0]) and np.allclose(b.item.points[0], [10 * MM, 0, 0])
    assert np.allclose(d[0].point, [10 * MM, 0, 0]) and np.allclose(d[1].point, [30 * MM, 0, -4 * MM])
    # the held pose equals the cut's end pose, frame included (no jump into or out of the dwell)
    chunks = {c.move: c for c in job.trajectory().chunks()}
    assert np.abs(chunks[k].poses - chunks[k + 1].poses[0]).max() < 1e-12
    assert np.abs(chunks[k].poses[0] - chunks[k - 1].poses[-1]).max() < 1e-6
    assert len(chunks[k]) == round(0.75 * RATE)
    assert job.summary()["dwell_s"] == pytest.approx(1.0)


def test_dwell_before_any_motion_takes_the_first_frame(tmp_path):
    job = plan(_file(tmp_path, "first.nc", "G21 G90\nG04 P1.0\nG01 X0 Y0 Z0 F600\nG01 X10\n"),
               PlanSettings(path="cam", rate=RATE))
    assert [m.kind for m in job.moves] == ["dwell", "cut"]
    c0, c1 = list(job.trajectory().chunks())
    assert len(c0) == RATE and np.abs(c0.poses - c1.poses[0]).max() < 1e-12


def test_the_budget_counts_the_dwells_and_names_an_absurd_one(tmp_path):
    from planner.budget import estimate
    from planner.io import read_gcode
    from planner.plan import resolve

    tp = read_gcode(io.StringIO(GCODE_DWELL), source="d.nc")
    s = resolve(PlanSettings(), "gcode", False)
    b = estimate(tp, s)
    feeds = np.where(np.isnan(tp.feeds[1:]), s.feed, tp.feeds[1:])
    speeds = np.where(tp.rapid[1:], s.rapid_speed, np.minimum(feeds, s.limits.speed))
    motion = float(np.sum(np.linalg.norm(np.diff(tp.points, axis=0), axis=1) / speeds))
    assert b.seconds == pytest.approx(motion + 1.0, rel=1e-12)
    path = _file(tmp_path, "long.nc", "G21 G90\nG01 X0 Y0 Z0 F600\nG01 X10\nG04 P10000.\nG01 X20\n")
    with pytest.raises(BudgetError, match=r"long.nc line 4: a dwell of 1e\+04 s would need 5e\+06 poses"):
        plan(path, PlanSettings(path="cam", max_poses=1e6))


def test_apt_delay_and_dwell_records(tmp_path):
    text = ("FEDRAT/MMPM,600\nGOTO/0,0,0\nDELAY/1.5\nGOTO/10,0,0\nSPINDL/RPM,3000,CLW\nDELAY/100,REV\n"
            "GOTO/20,0,0\nDWELL/0.25\nDELAY\n")
    job = plan(_file(tmp_path, "delay.apt", text), PlanSettings(path="cam", rate=RATE))
    d = [m for m in job.moves if m.kind == "dwell"]
    assert [(m.item.name, m.line) for m in d] == [("DELAY", 3), ("DELAY", 6), ("DWELL", 8)]
    assert [m.item.seconds for m in d] == pytest.approx([1.5, 2.0, 0.25])  # 100 rev at 50 rev/s
    assert np.allclose([m.point for m in d], np.array([[0, 0, 0], [10, 0, 0], [20, 0, 0]]) * MM)
    assert [e.name for e in job.toolpath.events_of("machine")] == ["DELAY"]  # a bare DELAY: an operator pause
    from planner.io import InputFileError

    with pytest.raises(InputFileError, match=r"line 3.*DELAY.*spindle speed"):
        plan(_file(tmp_path, "rev.apt", "GOTO/0,0,0\nGOTO/1,0,0\nDELAY/5,REV\n"), PlanSettings(path="cam"))


def test_selected_passes_keep_their_dwells(tmp_path):
    path = _file(tmp_path, "sel.apt", APT_DWELL)
    job = plan(path, PlanSettings(path="cam", passes=(1,), rate=RATE))
    assert [m.kind for m in job.moves] == ["cut", "dwell"]  # the plunge of hole 2 and its dwell
    (d,) = [m for m in job.moves if m.kind == "dwell"]
    assert d.line == 5 and d.item.seconds == 0.5 and np.allclose(d.point, np.array([20, 0, -10]) * MM)


def test_the_simulated_controller_waits_at_each_bottom(drill_job):
    """The whole-job program run by the simulator's URScript interpreter (SimDriver, program mode): the arm
    stands within a micrometre of each hole bottom for the dwell (plus the movep stop and the retract start)."""
    from drivers.sim import SimDriver

    with SimDriver(record=True) as d:
        report = d.execute(drill_job, mode="program")
        rec = d.recording
    assert report.ok, "\n".join(report.describe())
    assert report.duration == pytest.approx(drill_job.duration, rel=0.01)  # the three sleeps included
    base = np.array(PART[:3])
    for x, y, top, _ in HOLES:
        bottom = base + np.array([x, y, top - 10]) * MM
        at = np.flatnonzero(np.linalg.norm(rec["tcp"][:, :3] - bottom, axis=1) < 1e-6)
        assert at.size and (np.diff(at) == 1).all()  # one visit
        assert 0.5 <= rec["t"][at[-1]] - rec["t"][at[0]] < 0.55
