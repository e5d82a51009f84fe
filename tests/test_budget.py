"""The work budget checked before planning (planner.budget): absurd feeds, units, rates and arcs are refused
with one line naming the cause and its place; real jobs and a 10^8-pose job pass."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np
import pytest

from planner import PlannerError, PlanSettings, plan
from planner.budget import BudgetError, check_budget, estimate
from planner.io import Toolpath, read_toolpath
from planner.plan import resolve
from tests.cam_excerpts import NX_HEAD


def _nx(text: str = NX_HEAD) -> Toolpath:
    return read_toolpath(io.StringIO(text), format="apt")


def test_a_tiny_feed_is_refused_with_its_line():
    text = NX_HEAD.replace("FEDRAT/MMPM,250.0000", "FEDRAT/MMPM,1e-300")
    assert text != NX_HEAD
    with pytest.raises(BudgetError, match=r"line \d+: feed 1.67e-305 m/s is below 1 um/s"):
        plan(_nx(text))


def test_coordinates_of_a_unit_mistake_are_refused_with_their_line():
    tp = _nx()
    big = Toolpath(tp.points * 1e5, tp.axes, tp.axis_given, tp.feeds, tp.rapid, tp.lines, tp.events, "mm", "x.cls")
    with pytest.raises(BudgetError, match=r"x.cls line \d+: coordinate .* m is beyond any robot cell .*the file says mm"):
        plan(big)


def test_poses_beyond_the_budget_are_refused_naming_the_cause():
    with pytest.raises(BudgetError, match=r"about 1.\d+e\+06 poses at 10000 Hz .* more than max_poses = 1e\+06"):
        plan(_nx(), PlanSettings(rate=10_000.0, max_poses=1e6, feed=0.01))
    # one long slow span dominates: it is named by its line
    p = np.array([[0.0, 0.0, 0.0], [0.001, 0.0, 0.0], [2.0, 0.0, 0.0]])
    tp = Toolpath(p, None, None, np.array([np.nan, 0.05, 2e-6]), np.zeros(3, bool), np.array([1, 2, 3]),
                  source="slow.csv")
    with pytest.raises(BudgetError, match=r"slow.csv line 3: 2 m at 2e-06 m/s would need 5e\+08 poses"):
        plan(tp, PlanSettings(path="cam"))


def test_arcs_that_would_explode_are_refused_before_linearising():
    text = "UNITS/MM\nFEDRAT/MMPM,600\nGOTO/0,0,0\nCIRCLE/0,1000,0,0,0,1,1000\nGOTO/0,2000,0\n"
    with pytest.raises(BudgetError, match=r"linearised into about .* points .*arc_tolerance"):
        plan(read_toolpath(io.StringIO(text), format="apt"), PlanSettings(arc_tolerance=2e-9, max_points=1e4))


def test_real_jobs_and_a_hundred_million_pose_job_pass():
    s = resolve(PlanSettings(), "apt", True)
    b = check_budget(_nx(), s)
    assert b.poses == pytest.approx(b.seconds * 500.0) and 0 < b.poses < 1e6 and b.points == len(_nx())
    # 10^8 poses: 2e5 s at 500 Hz, a 100 m path (a track robot's, within MAX_COORDINATE) at 0.5 mm/s
    p = np.array([[-50.0, 0.0, 0.0], [50.0, 0.0, 0.0]])
    tp = Toolpath(p, None, None, np.array([np.nan, 0.5e-3]), np.zeros(2, bool), np.array([1, 2]), source="long.csv")
    b = check_budget(tp, resolve(PlanSettings(path="cam"), "csv", False))
    assert b.poses == pytest.approx(1e8) and estimate(tp, resolve(PlanSettings(), "csv", False)).length == 100.0


@pytest.mark.parametrize("field", ["max_poses", "max_points"])
def test_budget_settings_are_checked(field):
    with pytest.raises(PlannerError, match=f"{field} must be in"):
        PlanSettings(**{field: 0}).checked()


def test_a_file_feed_is_named_per_minute_in_the_files_units(tmp_path):
    """The refusal quotes the feed as the CAM file wrote it (per minute, in the file's length unit) beside SI."""
    from planner.frontends.cli.main import main

    text = (Path(__file__).resolve().parents[1] / "examples" / "nx_first_pass.cls").read_text()
    src = tmp_path / "slow.cls"
    src.write_text(text.replace("FEDRAT/MMPM,250.0000", "FEDRAT/MMPM,1e-300"))
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        assert main(["plan", str(src), "-o", str(tmp_path / "out.csv")]) == 2
    assert err.getvalue() == ("planner: error: slow.cls line 17: feed 1.67e-305 m/s is below 1 um/s (1e-300 mm/min): "
                              "no robot cell cuts at that feed (are the feed units right?)\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["slow.cls"]
