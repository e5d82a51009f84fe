"""``part_frame="auto"``: the part placed for the robot (translation and turn about the base z), the job reachable
at the frame found, its margins reported and reusable, and a clear refusal when no placement works."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner import PlanSettings, plan
from planner.cam.placement import Placement, job_samples, place_part
from planner.errors import PlannerError
from planner.frontends.cli.options import parse_pose
from planner.kinematics import get_model
from tests.cam_excerpts import NX

DRILL = """FEDRAT/MMPM,500
GOTO/0,0,50
CYCLE/DRILL,FEDTO,-10,RAPTO,3,RTRCTO,5,DWELL,0.5,MMPM,120
GOTO/10,0,0
GOTO/60,0,0
GOTO/60,80,-2
CYCLE/OFF
GOTO/0,80,30
"""


def _factors(model: str, q: np.ndarray) -> np.ndarray:
    """Elbow, wrist and shoulder singularity factors (n, 3) of joints q (n, 6) (see planner.cam.placement)."""
    m = get_model(model)
    sh = np.abs(m.a2 * np.cos(q[:, 1]) + m.a3 * np.cos(q[:, 1] + q[:, 2]) + m.d5 * np.sin(q[:, 1:4].sum(axis=1)))
    return np.column_stack((np.abs(np.sin(q[:, 2])), np.abs(np.sin(q[:, 4])), sh / (abs(m.a2) + abs(m.a3))))


@pytest.fixture(scope="module")
def drill(tmp_path_factory):
    path = tmp_path_factory.mktemp("auto") / "holes.apt"
    path.write_text(DRILL)
    return path


def test_auto_places_the_part_where_every_pose_is_reachable_with_margin(drill):
    job = plan(drill, PlanSettings(path="cam", robot="ur5e", part_frame="auto"))
    p = job.placement
    assert isinstance(p, Placement)
    assert job.problems == () and job.reachable
    frame = job.settings.part_frame
    assert frame == p.part_frame and len(frame) == 6 and frame[3:5] == (0.0, 0.0)  # a turn about the base z only
    # the margins are real: over every sample of the stream (not only the rated ones), the smallest factor is
    # near the reported one and the joints stay inside their limits by at least the reported margin (less the
    # turns the stream makes between rated poses)
    q = np.concatenate([c.joints for c in job.trajectory(125.0).chunks()])
    assert np.isfinite(q).all()
    f = _factors("ur5e", q)
    assert f.min() >= 0.8 * p.singularity_margin > 0.3
    assert p.singularity_margin == pytest.approx(min(p.factors), abs=1e-12)
    m = get_model("ur5e")
    assert np.minimum(m.upper - q, q - m.lower).min() > 0.0
    # printed so it can be reused: the line names the option, and planning with it gives the same job
    line = next(x for x in job.describe() if x.strip().startswith("placed"))
    assert f"--part-frame {p.option}" in line and "singularity margin" in line and "joint-limit margin" in line
    again = plan(drill, PlanSettings(path="cam", robot="ur5e", part_frame=parse_pose(p.option)))
    assert again.reachable and np.allclose(again.settings.part_frame, frame, atol=1e-6)
    s = job.summary()["part_frame_auto"]
    assert s["option"] == p.option and s["singularity_margin"] == p.singularity_margin


def test_auto_is_no_worse_than_hand_placements(drill):
    """The search's rating of its frame beats hand placements rated the same way (a maximum, not any frame)."""
    from planner.cam.placement import _Rater

    job = plan(drill, PlanSettings(path="cam", robot="ur5e", part_frame="auto"))
    pos, frames = job_samples(job.moves)
    rater = _Rater("ur5e", None, pos, frames)
    p = job.placement
    c, s = math.cos(p.part_frame[5]), math.sin(p.part_frame[5])
    cx, cy, cz = rater.centre
    best = [np.hypot(p.part_frame[0] + c * cx - s * cy, p.part_frame[1] + s * cx + c * cy), p.part_frame[2] + cz,
            p.part_frame[5]]
    mine = rater.rate([best])[0]
    assert mine == pytest.approx(min(p.singularity_margin, p.joint_margin / math.pi), abs=1e-9)
    hands = [[r, h, t] for r in (0.3, 0.45, 0.6) for h in (-0.1, 0.1, 0.3) for t in (0.0, 1.0, 2.5)]
    rated = rater.rate(hands)
    assert rated.max() > 0.0  # some hand placements work: the comparison means something
    assert mine >= rated.max() - 1e-12


def test_auto_on_the_nx_excerpt_makes_the_job_reachable():
    job = plan(NX.path, PlanSettings(robot="ur5e", part_frame="auto", feed=0.05))
    assert job.placement is not None and job.placement.singularity_margin > 0.2
    assert job.problems == ()
    assert job.settings.part_frame == job.placement.part_frame


def test_no_placement_is_refused_with_the_reason(tmp_path):
    path = tmp_path / "wide.csv"
    path.write_text("x,y,z\n0,0,0\n1500,0,0\n1500,1500,0\n")  # mm: 1.5 m x 1.5 m, beyond a UR3e
    with pytest.raises(PlannerError) as exc:
        plan(path, PlanSettings(robot="ur3e", part_frame="auto", path="cam"))
    msg = str(exc.value)
    assert msg.startswith("wide.csv: part_frame='auto' found no placement where the ur3e reaches every pose")
    assert "1.500 x 1.500 x 0.000 m" in msg and "--part-frame " in msg and "% of" in msg


def test_auto_needs_a_robot_and_other_strings_are_refused():
    with pytest.raises(PlannerError, match=r"part_frame='auto' places the part for a robot: set robot"):
        PlanSettings(part_frame="auto").checked()
    with pytest.raises(PlannerError, match=r"part_frame must be 6 numbers .* 'auto' or None; got 'center'"):
        PlanSettings(robot="ur5e", part_frame="center").checked()
    s = PlanSettings(robot="ur5e", part_frame="auto")
    assert s.checked().part_frame == "auto"
    assert PlanSettings.from_dict(s.to_dict()) == s


def test_place_part_refuses_a_job_without_motion():
    with pytest.raises(PlannerError, match="no motion to place"):
        place_part([], "ur5e")
