"""SOLIDWORKS CAM's drilling cycles as its APT post writes them (``CYCLE/INIT``, ``CYCLE/DEEP2`` with ``1STPECK`` and
``SUBPECK``, ``CYCLE/DRILL`` with ``DWELL,0``), on two whole real files kept verbatim in tests/data (see SOURCES.md
there): every hole expanded point by point, the plan's plunge passes, and refusals that name the word."""

from __future__ import annotations

import hashlib
import io
import re
import warnings

import numpy as np
import pytest

from planner import PlanSettings, plan
from planner.io import InputFileError, InputFileWarning, read_apt
from planner.io.cycles import DrillCycle
from tests.conftest import EXCERPT_DATA

MM = 1e-3
MMPM = 1e-3 / 60.0
SIDE_DRILL = EXCERPT_DATA / "solidworks_cam_apt_side_drill.apt"
HOLE_ROW = EXCERPT_DATA / "solidworks_cam_apt_hole_row.apt"


def read(path_or_text, **kw):
    """A file or APT text read with every reader warning an error (these files must read cleanly)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputFileWarning)
        if isinstance(path_or_text, str):
            return read_apt(io.StringIO(path_or_text), source="t.apt", **kw)
        return read_apt(path_or_text, **kw)


def deep2_levels(top: float, rapto: float, fedto: float, first: float, sub: float) -> list[tuple[float, bool]]:
    """(z in mm, fed) of the points of a full-retract peck hole on a +Z axis, written out: a rapid to the RAPTO level,
    the first peck ``first`` below it, then ``sub`` at a time; between pecks rapids out to RAPTO and back down to
    0.5 mm above the last depth; a rapid out to RAPTO at the end."""
    r, bottom = top + rapto, top - fedto
    depths, d = [], r - first
    while d > bottom + 1e-9:
        depths.append(d)
        d -= sub
    depths.append(bottom)
    z = [(r, False)]
    for k, depth in enumerate(depths):
        if k:
            z += [(r, False), (depths[k - 1] + 0.5, False)]
        z.append((depth, True))
    return z + [(r, False)]


def test_the_files_are_the_ones_sources_md_describes():
    text = (EXCERPT_DATA / "SOURCES.md").read_text(encoding="utf-8")
    for path in (SIDE_DRILL, HOLE_ROW):
        data = path.read_bytes()
        row = re.search(rf"^\| {re.escape(path.name)} \| ([\d,]+) \| (\d+) \| ([0-9a-f]{{64}}) \|$", text, re.M)
        assert row is not None, path.name
        assert (len(data), data.count(b"\n"), hashlib.sha256(data).hexdigest()) == (
            int(row[1].replace(",", "")), int(row[2]), row[3])


def test_side_drill_file_every_hole_point_by_point():
    tp = read(SIDE_DRILL)
    # line 14: RAPID/ GOTO/20.,125.,25.; then three holes at z 0 (RTRCTO 25) and, after line 25's rapid to the
    # same point, three at z -38 (RTRCTO 63: back to z 25); DEEP2,FEDTO,5.03163,1STPECK,5.,SUBPECK,2.,RAPTO,3.
    expect_xyz, expect_fed, expect_lines = [(20.0, 125.0, 25.0)], [False], [14]
    for first_line, top, rtrcto in ((17, 0.0, 25.0), (28, -38.0, 63.0)):
        if first_line == 28:
            expect_xyz.append((20.0, 125.0, 25.0))
            expect_fed.append(False)
            expect_lines.append(25)
        for k, y in enumerate((125.0, 75.0, 25.0)):
            levels = deep2_levels(top, 3.0, 5.03163, 5.0, 2.0) + [(top + rtrcto, False)]
            if k:  # the traverse to the next hole at the level the tool retracted to
                levels = [(top + rtrcto, False)] + levels
            expect_xyz += [(20.0, y, v) for v, _ in levels]
            expect_fed += [fed for _, fed in levels]
            expect_lines += [first_line + k] * len(levels)
    assert np.allclose(tp.points / MM, expect_xyz, rtol=0, atol=1e-9)
    assert tp.lines.tolist() == expect_lines
    # a plunge is a feed at the cycle's MMPM, every other move of a hole a rapid
    assert (~tp.rapid[1:]).tolist() == expect_fed[1:]
    assert np.allclose(tp.feeds[~tp.rapid][1:], 382.27 * MMPM, rtol=1e-12)
    assert [e.name for e in tp.events_of("cycle")] == ["INIT", "DEEP2", "OFF"] * 2
    assert tp.events_of("dwell") == ()
    # 3 pecks a hole: 5 mm from RAPTO, then 2 mm, then the last 1.03163 mm to the bottom
    assert int((~tp.rapid[1:]).sum()) == 18


def test_hole_row_file_drill_with_dwell_0_then_deep2_with_22_pecks():
    tp = read(HOLE_ROW)
    xs = (8.0, 27.0, 43.0, 62.0, 78.0, 97.0, 113.0, 132.0)
    fed = np.flatnonzero(~tp.rapid[1:]) + 1  # the moves at a feed (point 0 has no move into it)
    drill, deep = fed[:8], fed[8:]
    # CYCLE/DRILL,FEDTO,7.85788,MMPM,326.770115,RAPTO,3.,RTRCTO,25.,DWELL,0: one feed from z 3 to -7.85788
    assert np.allclose(tp.points[drill] / MM, [(x, 15.0, -7.85788) for x in xs], rtol=0, atol=1e-9)
    assert np.allclose(tp.points[drill - 1, 2] / MM, 3.0) and np.allclose(tp.feeds[drill], 326.770115 * MMPM)
    assert tp.events_of("dwell") == ()  # DWELL,0: no wait at the bottom
    # CYCLE/DEEP2,FEDTO,42.01108,1STPECK,5.,SUBPECK,2.: pecks to -2, -4, ..., -42, then the bottom -42.01108
    assert len(deep) == 8 * 22
    per_hole = tp.points[deep, 2].reshape(8, 22) / MM
    assert np.allclose(per_hole, [-2.0 - 2.0 * k for k in range(21)] + [-42.01108], rtol=0, atol=1e-9)
    assert np.allclose(tp.points[deep, 0].reshape(8, 22) / MM, np.array(xs)[:, None])
    assert np.allclose(tp.feeds[deep], 432.103657 * MMPM)
    first_hole = tp.points[tp.lines == 40, 2] / MM  # GOTO/8.,15.,0 of the DEEP2 cycle
    assert first_hole == pytest.approx([v for v, _ in deep2_levels(0.0, 3.0, 42.01108, 5.0, 2.0)] + [25.0], abs=1e-9)


@pytest.mark.parametrize("name, passes, rapids, cut_mm",
                         # side drill: 6 holes of 3 pecks (5 + 2.5 + 1.53163 mm fed); hole row: 8 drills of
                         # 10.85788 mm, 8 holes of 22 pecks (5 + 20 x 2.5 + 0.51108 mm fed)
                         [("solidworks_cam_apt_side_drill.apt", 18, 47, 6 * 9.03163),
                          ("solidworks_cam_apt_hole_row.apt", 184, 399, 8 * 10.85788 + 8 * 55.51108)])
def test_plan_makes_one_pass_per_peck_on_the_hole_axes(name, passes, rapids, cut_mm):
    job = plan(EXCERPT_DATA / name, PlanSettings(path="cam"))
    cuts = [m for m in job.moves if m.kind == "cut"]
    assert (len(cuts), job.count("rapid")) == (passes, rapids)
    tp = read(EXCERPT_DATA / name)
    holes = {(round(p[0] / MM, 6), round(p[1] / MM, 6)) for p in tp.points[~tp.rapid][1:]}
    for m in cuts:
        pts = m.item.points / MM
        assert np.ptp(pts[:, 0]) < 1e-9 and np.ptp(pts[:, 1]) < 1e-9  # along the tool axis only
        assert (round(pts[0, 0], 6), round(pts[0, 1], 6)) in holes and pts[0, 2] > pts[-1, 2]
    assert sum(float(np.linalg.norm(np.diff(m.item.points, axis=0), axis=1).sum()) for m in cuts) / MM == \
        pytest.approx(cut_mm, abs=1e-6)


def test_peck_depths_first_then_later():
    base = {"name": "t", "line": 1, "clearance": 3 * MM, "bottom": -45.25282 * MM, "peck_mode": "full"}
    # the real SOLIDWORKS form FEDTO 45.25282, 1STPECK 5., SUBPECK 30.: a 5 mm peck, a 30 mm one, then the rest
    assert np.allclose(DrillCycle(**base, peck=5 * MM, peck_next=30 * MM).peck_levels(),
                       np.array([-2.0, -32.0, -45.25282]) * MM, rtol=0, atol=1e-15)
    assert DrillCycle(**base, peck=60 * MM, peck_next=2 * MM).peck_levels() == [-45.25282 * MM]  # one feed
    # 1STPECK alone pecks by it all the way; SUBPECK alone too
    one = read("GOTO/0,0,20\nCYCLE/DEEP2,FEDTO,7.,1STPECK,3.,RAPTO,1.,MMPM,100\nGOTO/0,0,0\nCYCLE/OFF\n")
    sub = read("GOTO/0,0,20\nCYCLE/DEEP2,FEDTO,7.,SUBPECK,3.,RAPTO,1.,MMPM,100\nGOTO/0,0,0\nCYCLE/OFF\n")
    for tp in (one, sub):
        assert tp.points[~tp.rapid][1:, 2] / MM == pytest.approx([-2.0, -5.0, -7.0])
    problem = DrillCycle(**base, peck=5 * MM, peck_next=1e-9 * MM).problem()
    assert "100000 pecks" in problem
    assert "later pecks" in DrillCycle(**base, peck=5 * MM, peck_next=-1 * MM).problem()


def test_cycle_init_sets_up_and_ends_a_cycle_in_effect():
    tp = read("FEDRAT/MMPM,600\nGOTO/0,0,10\nCYCLE/DRILL,FEDTO,2.,RAPTO,1.,MMPM,60\nGOTO/5,0,0\nCYCLE/INIT\n"
              "GOTO/9,0,5\nCYCLE/CLEAR\nCYCLE/DEEP2,FEDTO,3.,1STPECK,2.,SUBPECK,1.,RAPTO,1.\nGOTO/9,9,0\nCYCLE/OFF\n")
    by_line = {int(n): tp.points[tp.lines == n] / MM for n in np.unique(tp.lines)}
    assert by_line[6].tolist() == [[9.0, 0.0, 5.0]]  # after CYCLE/INIT a GOTO is a point of the path again
    assert tp.feeds[tp.lines == 6] == pytest.approx([600 * MMPM])  # at the modal FEDRAT
    assert by_line[9][~tp.rapid[tp.lines == 9], 2] == pytest.approx([-1.0, -2.0, -3.0])  # DEEP2 at FEDRAT
    assert [e.name for e in tp.events_of("cycle")] == ["DRILL", "INIT", "CLEAR", "DEEP2", "OFF"]


@pytest.mark.parametrize(
    "record, field, words",
    [
        ("CYCLE/INITX", 1, ["'INITX'", "CYCLE/INIT", "DEEP2", "DRILL", "CYCLE/OFF"]),
        ("CYCLE/PECK,FEDTO,9.", 1, ["'PECK'", "CYCLE/INIT", "DEEP2"]),
        ("CYCLE/DEEP2,FEDTO,9.,2NDPECK,5.,MMPM,100", 4, ["'2NDPECK'", "1STPECK", "SUBPECK", "FEDTO", "MMPM"]),
        ("CYCLE/DEEP2,FEDTO,9.,1STPECK,5.,SUBPECK,2.,SPIRAL,MMPM,100", 8, ["'SPIRAL'", "1STPECK", "CYCLE/DEEP2"]),
        ("CYCLE/DEEP2,FEDTO,9.,1STPECK,5.x,MMPM,100", 5, ["'5.x' is not a number", "1STPECK"]),
        ("CYCLE/DEEP2,FEDTO,9.,1STPECK,MMPM,100", 4, ["1STPECK needs one peck depth"]),
        ("CYCLE/DEEP2,FEDTO,9.,1STPECK,5.,6.,MMPM,100", 4, ["1STPECK needs one peck depth"]),
        ("CYCLE/DEEP2,FEDTO,9.,1STPECK,-1.,MMPM,100", None, ["peck depth must be positive"]),
        ("CYCLE/DEEP2,FEDTO,9.,1STPECK,5.,SUBPECK,-2.,MMPM,100", None, ["later pecks must be positive"]),
        ("CYCLE/INIT,3", None, ["CYCLE/INIT takes no values"]),
        ("CYCLE/DRILL,,FEDTO,3.", 2, ["empty"]),
    ],
)
def test_refusals_name_the_line_and_the_word(record, field, words):
    with pytest.raises(InputFileError) as exc:
        read(f"GOTO/0,0,9\n{record}\nGOTO/1,0,0\nCYCLE/OFF\n")
    err = exc.value
    assert err.line == 2 and str(err).startswith("t.apt line 2, ")
    assert err.field == (f"field {field} of CYCLE" if field else "CYCLE record"), str(err)
    for w in words:
        assert w in str(err), (w, str(err))
    assert "\n" not in str(err)
