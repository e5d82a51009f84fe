"""Whole CAM jobs (planner.cam.plan_cam_job): moves, pose stream, part placement, robot, bad input."""

from __future__ import annotations

import io

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from planner.cam import CamInputError, plan_cam_job
from planner.errors import PlannerError
from planner.io import InputFileError, Toolpath, read_toolpath
from tests.cam_excerpts import NX_HEAD

FEED = 0.25 / 60.0  # FEDRAT/MMPM,250 in m/s


def nx_toolpath() -> Toolpath:
    return read_toolpath(io.StringIO(NX_HEAD), format="apt")


def test_nx_excerpt_job_and_its_pose_stream():
    job = plan_cam_job(nx_toolpath(), rate=500.0)
    assert [m.kind for m in job.moves] == ["rapid", "cut", "rapid", "cut", "rapid", "cut"]
    assert len(job.passes) == 3 and job.max_deviation <= 1e-5
    assert [p.first_line for p in job.passes] == [14, 56, 98]
    stream = job.pose_stream()
    n = len(stream)
    assert n == job.n_samples() and n == pytest.approx(job.duration * 500.0, abs=len(job.moves) + 1)
    assert np.array_equal(stream.times, np.arange(n) / 500.0)
    tp = job.toolpath
    assert np.abs(stream.poses[0, :3] - tp.points[0]).max() <= 1e-15
    assert np.abs(stream.poses[-1, :3] - tp.points[-1]).max() <= 1e-15
    step = np.linalg.norm(np.diff(stream.poses[:, :3], axis=0), axis=1) * 500.0  # m/s
    cut = stream.pass_index[1:] >= 0
    assert step[cut].max() <= FEED * (1 + 1e-6)  # the file's feed on the cuts
    assert step.max() <= 0.25 * (1 + 1e-6)  # rapid speed elsewhere
    assert np.abs(np.diff(stream.poses[:, 3:], axis=0)).max() <= 1e-3  # continuous rotation vectors
    # samples carry the source lines of the records they execute
    assert set(np.unique(stream.lines)) <= set(tp.lines.tolist())
    on_pass1 = stream.lines[stream.pass_index == 1]
    assert on_pass1.min() == 58 and on_pass1.max() == 95  # lines 56..95: the motion into 57, 58, ...
    # the tool points down (the MSYS turns the CAM -Z axis into +Z) and never spins about itself
    R = Rotation.from_rotvec(stream.poses[:, 3:]).as_matrix()
    assert np.abs(R[:, :, 2] - [0.0, 0.0, -1.0]).max() <= 1e-12
    assert job.spin_deg <= 1e-9


def test_part_placement_is_applied_to_every_pose():
    tp = nx_toolpath()
    place = np.array([0.4, 1.3, -0.1, 0.1, -0.2, 2.0])
    a = plan_cam_job(tp).pose_stream()
    b = plan_cam_job(tp, part_frame=place).pose_stream()
    R = Rotation.from_rotvec(place[3:]).as_matrix()
    assert np.array_equal(a.times, b.times)
    assert np.abs(b.poses[:, :3] - (a.poses[:, :3] @ R.T + place[:3])).max() <= 1e-14
    Ra = Rotation.from_rotvec(a.poses[:, 3:]).as_matrix()
    Rb = Rotation.from_rotvec(b.poses[:, 3:]).as_matrix()
    assert np.abs(Rb - R @ Ra).max() <= 1e-12


def three_passes(far: float) -> Toolpath:
    """Three straight passes along y at x = 0.4, far, 0.4 m (part frame), joined by rapids."""
    rows, rapid = [], []
    for k, x in enumerate((0.4, far, 0.4)):
        for j in range(4):
            rows.append([x, -0.1 + 0.05 * j + 0.01 * k, 0.2])
            rapid.append(j == 0 and k > 0)
    n = len(rows)
    return Toolpath(points=np.array(rows), axes=np.tile([0.0, 0.0, 1.0], (n, 1)), axis_given=np.ones(n, bool),
                    feeds=np.full(n, 0.02), rapid=np.array(rapid), lines=np.arange(100, 100 + 2 * n, 2),
                    source="cell.apt")


def test_unreachable_pass_is_reported_with_its_pass_and_line():
    job = plan_cam_job(three_passes(far=1.5), robot="ur5e")
    reach = [p.reachable for p in job.passes]
    assert reach == [True, False, True]
    msg = job.passes[1].reach_message
    assert msg.startswith("cell.apt pass 1 (lines 108-114), line 108:") and "no inverse kinematics" in msg
    assert job.reachable is False and any("rapid at line 108" in p for p in job.problems)
    assert job.summary()["unreachable_passes"] == [1]
    ok = plan_cam_job(three_passes(far=0.45), robot="ur5e")
    assert ok.reachable and all(p.reachable for p in ok.passes) and not ok.problems
    assert plan_cam_job(three_passes(far=1.5)).passes[1].reachable is None  # no robot: not checked


def test_summary_names_passes_and_deviation():
    job = plan_cam_job(nx_toolpath())
    text = "\n".join(job.describe())
    assert "3 passes" in text and "largest deviation from the CAM polyline" in text and "pass 0 (lines 14-53)" in text
    s = job.summary()
    assert s["passes"] == 3 and s["max_deviation_mm"] <= 0.01 and s["corners"] == 0


@pytest.mark.parametrize(
    ("options", "error", "message"),
    [
        ({"tolerance": 0.0}, CamInputError, r"tolerance must be in \(0, inf\]"),
        ({"corner_deg": -5}, CamInputError, "corner_deg must be in"),
        ({"axis_jump_deg": 100}, CamInputError, "axis_jump_deg must be in"),
        ({"feed_override": 0}, CamInputError, "feed_override must be in"),
        ({"part_frame": (1, 2, 3)}, CamInputError, "part_frame: must be a pose"),
        ({"part_frame": (0, 0, 0, np.nan, 0, 0)}, CamInputError, r"part_frame\[3\]: must be finite"),
        ({"limits": (0.1, 1, 10)}, CamInputError, "limits must be a planner.motion.MotionLimits"),
        ({"robot": "ur99"}, PlannerError, "ur99"),
        ({"read_options": {"units": "mm"}}, CamInputError, "read_options are for a file name"),
    ],
)
def test_bad_parameters_are_named(options, error, message):
    with pytest.raises(error, match=message):
        plan_cam_job(nx_toolpath(), **options)


def test_bad_toolpath_and_bad_file(tmp_path):
    with pytest.raises(CamInputError, match="toolpath must be a planner.io.Toolpath or a file name"):
        plan_cam_job(np.zeros((3, 3)))
    bad = tmp_path / "bad.apt"
    bad.write_text("GOTO/0,0,0\nGOTO/1,x,0\n")
    with pytest.raises(InputFileError, match="bad.apt line 2"):
        plan_cam_job(bad)
    job = plan_cam_job(nx_toolpath())
    with pytest.raises(CamInputError, match="max_samples"):
        job.pose_stream(max_samples=100)


def test_job_from_a_file_name_records_the_parse_time(tmp_path):
    f = tmp_path / "head.cls"
    f.write_text(NX_HEAD)
    job = plan_cam_job(f)
    assert job.source == "head.cls" and job.timings["parse"] > 0.0 and len(job.passes) == 3


def test_planning_errors_name_the_file_and_lines():
    tp = three_passes(far=0.45)
    feeds = tp.feeds.copy()
    feeds[6] = 0.0  # a zero feed inside pass 1 (file lines 108-114): the motion into line 112
    bad = Toolpath(tp.points, tp.axes, tp.axis_given, feeds, tp.rapid, tp.lines, source="cell.apt")
    with pytest.raises(CamInputError, match=r"cell.apt lines 108-114 \(pass 1, lines 108-114\): span_feeds\[1\]"):
        plan_cam_job(bad)


def test_three_axis_file_without_axes_points_the_tool_down():
    tp = three_passes(far=0.45)
    flat = Toolpath(tp.points, None, None, tp.feeds, tp.rapid, tp.lines, source="flat.nc")
    stream = plan_cam_job(flat).pose_stream()
    R = Rotation.from_rotvec(stream.poses[:, 3:]).as_matrix()
    assert np.abs(R[:, :, 2] - [0.0, 0.0, -1.0]).max() <= 1e-15
