"""The offline job end to end: plan() on waypoints and the `planner` command line on real CAM data."""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from planner import PlanSettings, plan
from planner.frontends.cli.main import DEMO_PART_FRAME, EXAMPLE_CLS, build_parser, example_path, main
from planner.frontends.cli.options import settings_from_args
from planner.motion import MotionLimits


def test_waypoints_without_robot_keep_a_planar_tool_vertical():
    th = np.linspace(0, np.pi, 15)
    wp = np.c_[0.2 * np.cos(th), 0.2 * np.sin(th), np.zeros_like(th)]
    job = plan(wp, PlanSettings(feed=0.1, limits=MotionLimits(0.25, 0.5, 5.0, None)))
    assert job.settings.path == "interpolate" and job.settings.axes == "path"
    c = job.trajectory().collect()
    R = Rotation.from_rotvec(c.poses[:, 3:]).as_matrix()
    # the RMF of a planar curve keeps the plane normal (the planar PH fit stays in the plane)
    assert np.abs(c.poses[:, 2]).max() < 1e-9
    assert np.abs(R[:, :, 2] - [0, 0, -1]).max() < 1e-8
    assert c.joints is None and job.reachable is None
    cut = job.moves[0]
    assert job.summary()["cut_length_mm"] == pytest.approx(1e3 * cut.path.length)
    assert job.duration > cut.path.length / 0.1  # ramps make it longer than at constant feed


def test_waypoints_with_approach_axes_and_robot_are_reachable():
    th = np.linspace(0, np.pi / 2, 12)
    wp = np.c_[0.1 * np.cos(th), 0.1 * np.sin(th), np.zeros_like(th)]
    axes = np.c_[0.3 * np.cos(th), 0.3 * np.sin(th), -np.ones_like(th)]  # approach axes, tilted outwards
    s = PlanSettings(robot="ur5e", part_frame=(0.4, 0.0, 0.2, 0.0, 0.0, 0.0), feed=0.05, axes="approach")
    job = plan(wp, s, axes=axes)
    assert job.reachable and not job.problems
    c = job.trajectory().collect()
    assert np.isfinite(c.joints).all() and c.joints.shape == (job.n_samples(), 6)
    unit = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    cut = job.moves[0]
    z = cut.frames.frames(cut.path.waypoint_knots)[:, :, 2]
    assert np.abs(z - unit).max() < 1e-12


def test_unreachable_waypoints_are_reported_at_the_first_one():
    wp = np.c_[np.linspace(0, 0.1, 5), np.zeros(5), np.zeros(5)]
    job = plan(wp, PlanSettings(robot="ur5e", part_frame=(3.0, 0.0, 0.0, 0.0, 0.0, 0.0)))
    assert job.reachable is False
    assert re.search(r"<waypoints> pass 0 \(lines 0-4\), line 0: pose has no inverse kinematics", job.problems[0])


def test_cli_defaults_are_the_plan_settings_defaults():
    args = build_parser().parse_args(["plan", "x.csv"])
    assert settings_from_args(args) == PlanSettings().checked()


def test_cli_plan_writes_program_and_plot(tmp_path, capsys):
    script, png = tmp_path / "job.script", tmp_path / "job.png"
    code = main(["plan", str(example_path(EXAMPLE_CLS)), "--pass", "longest", "--robot", "ur5e",
                 "--part-frame", DEMO_PART_FRAME, "-o", str(script), "--plot", str(png)])
    out = capsys.readouterr().out
    assert code == 0
    assert "every move reachable" in out and "254.2 mm of cut" in out
    assert float(re.search(r"from the CAM polyline ([0-9.]+) mm", out).group(1)) <= 0.01
    n = int(re.search(r"\((\d+) movep, 1 movej\)", out).group(1))  # the pass alone: no rapid before it
    assert script.read_text().count("  movep(") == n > 10
    assert png.stat().st_size > 50_000
    # the program's moves were checked for the joint limits before the figures were printed (none slowed here)
    assert "  slowed    program: no statement slowed for the joint limits" in out
    assert out.index("  slowed    program:") < out.index("  wrote     ")


def test_cli_plan_csv_trajectory(tmp_path):
    out = tmp_path / "job.csv"
    assert main(["plan", str(example_path()), "--feed", "20", "-o", str(out)]) == 0
    rows = [r for r in out.read_text().splitlines() if r and not r.startswith("#")]
    assert rows[0] == "t,x,y,z,rx,ry,rz,move,pass,line"
    data = np.array([[float(x) for x in r.split(",")] for r in rows[1:]])
    assert data.shape[0] > 1000 and np.all(np.diff(data[:, 0]) > 0)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["plan", "missing.apt"], "missing.apt"),
        (["plan", "EXAMPLE", "--pass", "7"], "passes: nx_first_pass.cls has passes 0..0, not 7"),
        (["plan", "EXAMPLE", "--pass", "x"], "--pass x: must be pass numbers K[,K...], 'longest' or 'all'"),
        (["plan", "EXAMPLE", "--part-frame", "1,2,3"], "--part-frame 1,2,3: must be six values"),
        (["plan", "EXAMPLE", "-o", "x.docx"], "unknown output type"),
        (["plan", "EXAMPLE", "-o", "x.script"], "needs the reachability check: give --robot MODEL"),
        (["plan", "EXAMPLE", "--feed", "nan"], "--feed nan: must be at least 0.001 mm/s"),
        (["plan", "EXAMPLE", "--axes", "path", "--path", "cam", "--frame", "juttler"], "frame='juttler' needs"),
        (["plan", "EXAMPLE", "--robot", "ur99"], "ur99"),
    ],
)
def test_cli_errors_are_one_line_with_exit_code_2(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv = [str(example_path(EXAMPLE_CLS)) if a == "EXAMPLE" else a for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("planner: error:") and message in err and "Traceback" not in err
    assert err.count("\n") == 1, err


def test_cli_plans_a_whole_multi_pass_file(tmp_path, capsys):
    from tests.cam_excerpts import NX_HEAD

    src = tmp_path / "head.cls"
    src.write_text(NX_HEAD)
    out = tmp_path / "job.csv"
    assert main(["plan", str(src), "-o", str(out), "--progress"]) == 0
    captured = capsys.readouterr()
    text = captured.out
    assert re.search(r"plan: +100%\|[^|]*\| 3/3 ", captured.err) and re.search(r"samples: +100%\|", captured.err)  # tqdm
    assert re.search(r"-> \d+ pass(es)?, \d+ rapids?, ", text) and "largest deviation from the CAM polyline" in text
    rows = [r for r in out.read_text().splitlines() if r and r[0] not in "#t"]
    data = np.array([[float(x) for x in r.split(",")] for r in rows])
    assert np.all(np.diff(data[:, 0]) > 0) and set(np.unique(data[:, 8])) >= {0.0, 1.0}
    assert main(["plan", str(src), "-o", str(tmp_path / "job.script")]) == 2


def test_cli_fit_prints_figures(capsys):
    assert main(["fit", str(example_path()), "--method", "C2"]) == 0
    assert "C2 PH quintic spline" in capsys.readouterr().out


@pytest.mark.slow
@pytest.mark.parametrize(
    "name, extra",
    [
        ("nx_clsf_variable_contour_ust_a2.cls", []),
        ("solidworks_cam_apt_boss_3plus2.apt", []),
        ("nx2022_haas_umc750_5axis_gcode.txt", ["--machine", "haas-umc-750", "--units", "inch"]),
    ],
)
def test_cli_plans_each_shared_cam_file(name, extra, capsys):
    from tests.conftest import SHARED_DATA

    if not (SHARED_DATA / name).is_file():
        pytest.skip(f"{name} is not in {SHARED_DATA} (the whole-file tests need ../shared/data)")
    assert main(["plan", str(SHARED_DATA / name), *extra]) == 0
    out = capsys.readouterr().out
    assert re.search(r"-> \d+ passes", out)
    dev = float(re.search(r"largest deviation from the CAM polyline ([0-9.]+) mm", out).group(1))
    assert dev <= 0.01


def test_unplaced_part_gets_a_hint_and_repeated_warnings_are_grouped(capsys, tmp_path):
    from planner.frontends.cli.main import warning_lines

    assert main(["plan", str(example_path(EXAMPLE_CLS)), "--robot", "ur5e"]) == 0
    out = capsys.readouterr().out
    assert "moves with problems" in out and "hint      no part frame given" in out
    lines = warning_lines(("a.apt line 3: x", "a.apt line 3: x", "b"))
    assert lines == ["  warning   a.apt line 3: x (2 times)", "  warning   b"]


def test_planner_sim_passes_its_options_to_the_simulator_and_refuses_remote_hosts(capsys):
    assert main(["sim", "--host", "8.8.8.8"]) != 0
    captured = capsys.readouterr()
    assert "8.8.8.8 is not a loopback address" in captured.out + captured.err


def test_planner_run_returns_the_run_handlers_exit_status(capsys):
    # `planner run` through planner's own entry point: a refused run is exit 2, not 0
    assert main(["run", str(example_path(EXAMPLE_CLS)), "--robot", "none", "--sim"]) == 2
    assert "--robot MODEL is needed" in capsys.readouterr().err
