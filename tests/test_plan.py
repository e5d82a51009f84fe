"""plan(): whole CAM jobs, single passes and waypoints through one pipeline; moves, trajectory, part placement,
robot, the tool-axis convention of every input, settings refused by name, bad input."""

from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from planner import PlannerError, PlanSettings, plan
from planner.io import InputFileError, Toolpath, read_toolpath
from tests.cam_excerpts import NX_HEAD

FEED = 0.25 / 60.0  # FEDRAT/MMPM,250 in m/s


def nx_toolpath() -> Toolpath:
    return read_toolpath(io.StringIO(NX_HEAD), format="apt")


def cam(**kw) -> PlanSettings:
    """The settings of the former whole-job planner (CAM polyline, 0.01 m/s default feed)."""
    return PlanSettings(**{"path": "cam", "feed": 0.01, **kw})


def per_sample(job, rate=None):
    """(times, poses, move, pass, lines) of every sample of a job's trajectory."""
    chunks = list(job.trajectory(rate).chunks(joints=False))
    cat = np.concatenate
    return (cat([c.times for c in chunks]), cat([c.poses for c in chunks]),
            cat([np.full(len(c), c.move) for c in chunks]), cat([np.full(len(c), c.pass_index) for c in chunks]),
            cat([c.lines for c in chunks]))


def test_nx_excerpt_job_and_its_trajectory():
    job = plan(nx_toolpath(), cam(rate=500.0))
    assert job.settings.path == "cam" and job.settings.axes == "file"
    assert [m.kind for m in job.moves] == ["rapid", "cut", "rapid", "cut", "rapid", "cut"]
    assert len(job.passes) == 3 and job.max_deviation <= 1e-5
    assert [p.first_line for p in job.passes] == [14, 56, 98]
    times, poses, _, pass_index, lines = per_sample(job)
    n = times.size
    assert n == job.n_samples() == job.trajectory().n_samples
    assert n == pytest.approx(job.duration * 500.0, abs=len(job.moves) + 1)
    assert np.array_equal(times, np.arange(n) / 500.0)
    tp = job.toolpath
    assert np.abs(poses[0, :3] - tp.points[0]).max() <= 1e-15
    assert np.abs(poses[-1, :3] - tp.points[-1]).max() <= 1e-15
    step = np.linalg.norm(np.diff(poses[:, :3], axis=0), axis=1) * 500.0  # m/s
    cut = pass_index[1:] >= 0
    assert step[cut].max() <= FEED * (1 + 1e-6)  # the file's feed on the cuts
    assert step.max() <= 0.25 * (1 + 1e-6)  # rapid speed elsewhere
    assert np.abs(np.diff(poses[:, 3:], axis=0)).max() <= 1e-3  # continuous rotation vectors
    # samples carry the source lines of the records they execute
    assert set(np.unique(lines)) <= set(tp.lines.tolist())
    on_pass1 = lines[pass_index == 1]
    assert on_pass1.min() == 58 and on_pass1.max() == 95  # lines 56..95: the motion into 57, 58, ...
    # the tool points down (the MSYS turns the CAM -Z axis into +Z) and never spins about itself
    R = Rotation.from_rotvec(poses[:, 3:]).as_matrix()
    assert np.abs(R[:, :, 2] - [0.0, 0.0, -1.0]).max() <= 1e-12
    assert job.spin_deg <= 1e-9


def test_part_placement_is_applied_to_every_pose():
    tp = nx_toolpath()
    place = np.array([0.4, 1.3, -0.1, 0.1, -0.2, 2.0])
    a = plan(tp, cam()).trajectory().collect()
    b = plan(tp, cam(part_frame=tuple(place))).trajectory().collect()
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
    job = plan(three_passes(far=1.5), cam(robot="ur5e"))
    reach = [p.reachable for p in job.passes]
    assert reach == [True, False, True]
    msg = job.passes[1].reach_message
    assert msg.startswith("cell.apt pass 1 (lines 108-114), line 108:") and "no inverse kinematics" in msg
    assert job.reachable is False and any("rapid at line 108" in p for p in job.problems)
    assert job.summary()["unreachable_passes"] == [1]
    ok = plan(three_passes(far=0.45), cam(robot="ur5e"))
    assert ok.reachable and all(p.reachable for p in ok.passes) and not ok.problems
    assert plan(three_passes(far=1.5), cam()).passes[1].reachable is None  # no robot: not checked


def test_summary_names_passes_and_deviation():
    job = plan(nx_toolpath(), cam())
    text = "\n".join(job.describe())
    assert "3 passes" in text and "largest deviation from the CAM polyline" in text and "pass 0 (lines 14-53)" in text
    s = job.summary()
    assert s["passes"] == 3 and s["max_deviation_mm"] <= 0.01 and s["corners"] == 0
    # the planning time in a unit people read (a few ms here, not "0.00 s")
    m = re.search(r"planned in (\d+\.\d+) (ms|s)$", text.split("  motion    ")[1].split("\n")[0])
    assert m is not None and float(m.group(1)) > 0
    ms = m.group(2) == "ms"
    assert float(m.group(1)) * (1e-3 if ms else 1.0) == pytest.approx(s["planning_s"], abs=0.051e-3 if ms else 0.0051)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"tolerance": 0.0}, r"tolerance must be in \(0, 1\]"),
        ({"corner_deg": -5}, "corner_deg must be in"),
        ({"axis_jump_deg": 100}, "axis_jump_deg must be in"),
        ({"feed_override": 0}, "feed_override must be in"),
        ({"feed": float("nan")}, "feed must be in"),
        ({"rate": 1e7}, "rate must be in"),
        ({"part_frame": (1, 2, 3)}, "part_frame: must be a pose"),
        ({"part_frame": (0, 0, 0, np.nan, 0, 0)}, r"part_frame\[3\]: must be finite"),
        ({"limits": (0.1, 1, 10)}, "limits must be a planner.motion.MotionLimits"),
        ({"robot": "ur99"}, "ur99"),
        ({"path": "smooth"}, "path must be one of auto, interpolate, cam"),
        ({"axes": "normal"}, "axes must be one of"),
        ({"frame": "grm"}, r"frame='grm' sets the spin about the path tangent and needs .*axes='path'"),
        ({"frame": "juttler", "axes": "path"}, r"frame='juttler' needs a G1 PH cubic spline .*path='interpolate'"),
        ({"cut_output": ("standard", 8)}, "cut_output must be"),
        ({"passes": (7,)}, r"passes: <stream> has passes 0..2, not 7|passes: .* has passes 0..2, not 7"),
        ({"passes": (-1,)}, "passes must be pass numbers"),
    ],
)
def test_bad_settings_are_refused_by_name(options, message):
    with pytest.raises(PlannerError, match=message):
        plan(nx_toolpath(), cam(**options))


def test_bad_sources_and_bad_file(tmp_path):
    with pytest.raises(PlannerError, match="read_options are for a file name"):
        plan(nx_toolpath(), read_options={"units": "mm"})
    with pytest.raises(PlannerError, match="settings must be a PlanSettings"):
        plan(nx_toolpath(), {"path": "cam"})
    with pytest.raises(PlannerError, match="waypoint"):
        plan(np.zeros((3, 3)))  # coincident waypoints
    bad = tmp_path / "bad.apt"
    bad.write_text("GOTO/0,0,0\nGOTO/1,x,0\n")
    with pytest.raises(InputFileError, match="bad.apt line 2"):
        plan(bad)
    job = plan(nx_toolpath(), cam())
    with pytest.raises(PlannerError, match="max_samples"):
        job.trajectory().collect(max_samples=100)


def test_job_from_a_file_name_records_the_parse_time(tmp_path):
    f = tmp_path / "head.cls"
    f.write_text(NX_HEAD)
    job = plan(f)
    assert job.settings.path == "cam" and job.source == "head.cls" and job.timings["parse"] > 0.0 and len(job.passes) == 3


def test_planning_errors_name_the_file_and_lines():
    tp = three_passes(far=0.45)
    feeds = tp.feeds.copy()
    feeds[6] = 0.0  # a zero feed inside pass 1 (file lines 108-114): the motion into line 112
    bad = Toolpath(tp.points, tp.axes, tp.axis_given, feeds, tp.rapid, tp.lines, source="cell.apt")
    with pytest.raises(PlannerError, match=r"cell.apt line 112: feed 0 m/s is below 1 um/s"):
        plan(bad)  # refused by the work budget before planning, naming the line of the motion


def test_three_axis_file_without_axes_points_the_tool_down():
    tp = three_passes(far=0.45)
    flat = Toolpath(tp.points, None, None, tp.feeds, tp.rapid, tp.lines, source="flat.nc")
    job = plan(flat)
    assert job.settings.axes == "fixed"
    R = Rotation.from_rotvec(job.trajectory().collect().poses[:, 3:]).as_matrix()
    assert np.abs(R[:, :, 2] - [0.0, 0.0, -1.0]).max() <= 1e-15


# -- one pipeline, one convention per concept ----------------------------------------------------------------


def _s_curve(n: int = 25) -> np.ndarray:
    """n waypoints (m) on an S-shaped bead with a gentle tilt of the tool axis along it."""
    t = np.linspace(0.0, 1.0, n)
    return np.column_stack((0.3 * t, 0.05 * np.sin(2 * np.pi * t), 0.02 * np.cos(3 * np.pi * t)))


def _axes_along(p: np.ndarray) -> np.ndarray:
    """CAM tool axes (tip towards spindle): +Z tilted by up to 20 deg about x along the path."""
    a = np.radians(20.0) * np.linspace(-1.0, 1.0, len(p))
    return np.column_stack((np.zeros(len(p)), -np.sin(a), np.cos(a)))


def _write_three(tmp_path, p: np.ndarray, ax: np.ndarray):
    """The same points and tool axes as a CSV, a JSON and an APT file (mm)."""
    mm = 1e3 * p
    csv = tmp_path / "bead.csv"
    csv.write_text("x,y,z,i,j,k\n" + "\n".join(",".join(f"{v:.10f}" for v in (*q, *a)) for q, a in zip(mm, ax, strict=True)))
    js = tmp_path / "bead.json"
    js.write_text('{"units": "mm", "points": ' + str(mm.tolist()) + ', "axes": ' + str(ax.tolist()) + "}")
    apt = tmp_path / "bead.apt"
    apt.write_text("UNITS/MM\nFEDRAT/MMPM,3000\n" + "\n".join(
        "GOTO/" + ",".join(f"{v:.10f}" for v in (*q, *a)) for q, a in zip(mm, ax, strict=True)) + "\nFINI\n")
    return csv, js, apt


@pytest.mark.parametrize("path_model", ["interpolate", "cam"])
def test_every_input_type_gives_the_same_tool_axes_in_every_mode(tmp_path, path_model):
    p = _s_curve()
    ax = _axes_along(p)
    files = _write_three(tmp_path, p, ax)
    settings = PlanSettings(path=path_model, feed=0.05)
    jobs = [plan(f, settings) for f in files] + [plan(p, settings, axes=ax)]
    for job in jobs:
        assert job.settings.axes == "file" and job.settings.path == path_model
        assert len(job.passes) == 1 and job.max_axis_error_deg <= 1e-9
    zs = []
    for job in jobs:
        m = next(m for m in job.moves if m.kind == "cut")
        F = m.frames.frames(m.path.waypoint_knots)
        zs.append(F[:, :, 2])
        # the tool z is the negative of the CAM vector (the tool approaches the part) at every point
        assert np.abs(F[:, :, 2] + ax).max() <= 1e-9
    for z in zs[1:]:
        assert np.abs(z - zs[0]).max() <= 1e-9
    # the same axes taken as approach axes: the opposite tool z, everywhere
    flipped = plan(files[0], PlanSettings(path=path_model, axes="approach"))
    m = next(m for m in flipped.moves if m.kind == "cut")
    assert np.abs(m.frames.frames(m.path.waypoint_knots)[:, :, 2] - ax).max() <= 1e-9


def test_waypoints_are_interpolated_by_a_c2_spline_by_default():
    p = _s_curve(25)
    job = plan(p)
    assert job.settings.path == "interpolate" and job.settings.axes == "path"
    cut = next(m for m in job.moves if m.kind == "cut")
    assert cut.path.n_segments == 24  # one PH quintic per span, not a polyline fit with hundreds of segments
    assert job.max_waypoint_error <= 1e-12
    assert "interpolate: C2 PH spline through the points" in "\n".join(job.describe())
    polyline = plan(p, PlanSettings(path="cam"))
    assert polyline.passes[0].max_deviation <= 1e-5 and polyline.moves[0].path.n_segments > 24


@pytest.mark.parametrize("frame", ["rmf", "grm", "er", "double-reflection", "juttler"])
def test_frames_about_the_path_report_their_twist_against_the_exact_rmf(frame):
    job = plan(_s_curve(), PlanSettings(axes="path", frame=frame))
    twist = job.summary()["max_twist_vs_exact_rmf_deg"]
    if frame == "rmf":
        assert twist == 0.0
    elif frame == "er":  # the ER frame is not rotation-minimizing: far more twist than the GRM frame's
        grm = plan(_s_curve(), PlanSettings(axes="path", frame="grm")).summary()["max_twist_vs_exact_rmf_deg"]
        assert twist > 0.05 and twist > 5.0 * grm
    else:
        assert 0.0 < twist < 1.0
    cut = next(m for m in job.moves if m.kind == "cut")
    F = cut.frames.frames(np.linspace(cut.path.knots[0], cut.path.knots[-1], 101))
    assert np.abs(np.einsum("nij,nik->njk", F, F) - np.eye(3)).max() <= 1e-12  # orthonormal
    t = cut.path.tangent(np.linspace(cut.path.knots[0], cut.path.knots[-1], 101))
    normal_tol = 1e-6 if frame == "double-reflection" else 1e-9  # discrete, slerped between dense samples
    assert np.abs(np.einsum("ni,ni->n", F[:, :, 2], t)).max() <= normal_tol  # the tool z is normal to the path
    assert F[0, 2, 2] < -0.9  # starting nearest -Z


def test_selected_pass_keeps_the_cam_axes_of_the_whole_job():
    whole = plan(nx_toolpath(), cam())
    one = plan(nx_toolpath(), cam(passes=(1,)))
    assert len(one.passes) == 1 and one.passes[0].first_line == whole.passes[1].first_line == 56
    a = next(m for m in whole.moves if m.pass_index == 1)
    b = next(m for m in one.moves if m.kind == "cut")
    u = np.linspace(a.path.knots[0], a.path.knots[-1], 257)
    assert np.abs(a.path.points(u) - b.path.points(u)).max() <= 1e-15
    assert np.abs(a.frames.axis(u) - b.frames.axis(u)).max() <= 1e-15
    longest = plan(nx_toolpath(), cam(passes="longest"))
    assert len(longest.passes) == 1


def test_cut_output_is_on_exactly_during_cuts():
    job = plan(nx_toolpath(), cam(cut_output=("tool", 1)))
    bit = 1 << 17
    for c in job.trajectory().chunks():
        if c.kind == "cut":
            assert (c.io[:-1] == bit).all() and c.io[-1] == 0
        else:
            assert (c.io == 0).all()


def test_settings_round_trip_through_plain_values():
    s = PlanSettings(path="cam", robot="ur10e", part_frame=(0.1, 0.2, 0.3, 0.0, 0.0, 1.0), cut_output=("standard", 3),
                     passes=(2, 0))
    d = s.to_dict()
    import json

    back = PlanSettings.from_dict(json.loads(json.dumps(d)))
    assert back.checked() == s.checked()
    with pytest.raises(PlannerError, match="unknown setting feedrate"):
        PlanSettings.from_dict({"feedrate": 1.0})


def test_reader_options_that_do_not_apply_are_refused_by_name(tmp_path):
    f = tmp_path / "head.cls"
    f.write_text(NX_HEAD)
    with pytest.raises(PlannerError, match="option 'machine' does not apply to apt files \\(it is for gcode files\\)"):
        plan(f, read_options={"machine": "haas-umc-750"})
    with pytest.raises(PlannerError, match="option 'colour' does not apply to apt files$"):
        plan(f, read_options={"colour": "red"})


def test_progress_counts_the_passes_planned_of_the_passes():
    """A CAM file of 33 passes: every call counts cutting passes (total 33), each stage's count never goes back and
    reaches the total, and the stages come in order (fit, then plan)."""
    calls: list[tuple[str, int, int]] = []
    src = Path(__file__).parent / "data" / "nx_clsf_ust_a2_excerpt.cls"
    job = plan(src, PlanSettings(), progress=lambda *c: calls.append(c))
    n = job.summary()["passes"]
    assert n == 33 and {total for _, _, total in calls} == {n}
    assert [stage for stage, _, _ in calls] == sorted((stage for stage, _, _ in calls), key=["fit", "plan"].index)
    for stage in ("fit", "plan"):
        done = [d for st, d, _ in calls if st == stage]
        assert done[0] == 0 and done[-1] == n and all(a <= b for a, b in zip(done, done[1:], strict=False)), stage
    assert len([d for st, d, _ in calls if st == "plan"]) == n + 1  # one call per pass: the bar moves pass by pass
