"""The offline job end to end: plan_job and the `planner` command line on real CAM data."""

from __future__ import annotations

import re

import numpy as np
import pytest

from planner.cli import DEMO_PART_FRAME, EXAMPLE_CLS, example_path, main
from planner.job import JobSettings, plan_job


def test_plan_job_without_robot_keeps_a_planar_tool_vertical():
    th = np.linspace(0, np.pi, 15)
    wp = np.c_[0.2 * np.cos(th), 0.2 * np.sin(th), np.zeros_like(th)]
    job = plan_job(wp, settings=JobSettings(robot=None, feed=0.1, angular_speed=None))
    R = job.stream.rotations
    # the RMF of a planar curve keeps the plane normal (the spatial PH fit leaves the plane by ~1e-10 m)
    assert np.abs(job.stream.positions[:, 2]).max() < 1e-9
    assert np.abs(R[:, :, 2] - [0, 0, -1]).max() < 1e-8
    assert job.joints is None and job.reachability is None
    assert job.summary()["length_mm"] == pytest.approx(1e3 * job.path.length)
    assert job.stream.s[-1] == pytest.approx(job.path.length, rel=1e-12)
    assert job.profile.duration > job.path.length / 0.1  # ramps make it longer than at constant feed


def test_plan_job_with_axes_and_robot_reports_reachability():
    th = np.linspace(0, np.pi / 2, 12)
    wp = np.c_[0.1 * np.cos(th), 0.1 * np.sin(th), np.zeros_like(th)]
    axes = np.c_[0.3 * np.cos(th), 0.3 * np.sin(th), -np.ones_like(th)]  # tilted outwards
    s = JobSettings(robot="ur5e", base=(0.4, 0.0, 0.2, 0.0, 0.0, 0.0), feed=0.05)
    job = plan_job(wp, axes, s)
    assert job.reachability.ok
    assert np.isfinite(job.joints).all() and job.joints.shape == (job.stream.times.size, 6)
    unit = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    z = job.frames.frames(job.path.waypoint_knots)[:, :, 2]
    assert np.abs(z - unit).max() < 1e-12


def test_unreachable_job_is_reported_at_the_first_sample():
    wp = np.c_[np.linspace(0, 0.1, 5), np.zeros(5), np.zeros(5)]
    job = plan_job(wp, settings=JobSettings(robot="ur5e", base=(3.0, 0.0, 0.0, 0.0, 0.0, 0.0)))
    assert not job.reachability.ok
    assert "sample 0" in job.reachability.message and "no inverse kinematics" in job.reachability.message


def test_cli_plan_writes_program_and_plot(tmp_path, capsys):
    script, png = tmp_path / "job.script", tmp_path / "job.png"
    code = main(["plan", str(example_path(EXAMPLE_CLS)), "--pass", "longest", "--part-frame", DEMO_PART_FRAME,
                 "-o", str(script), "--plot", str(png)])
    out = capsys.readouterr().out
    assert code == 0
    assert "all" in out and "reachable" in out and "length 254.2" in out
    assert float(re.search(r"from the CAM polyline ([0-9.]+) mm", out).group(1)) <= 0.01
    text = script.read_text()
    n = int(re.search(r"(\d+) poses at 500 Hz", out).group(1))
    assert text.count("servoj(") == n
    assert png.stat().st_size > 50_000


def test_cli_plan_csv_pose_stream(tmp_path):
    out = tmp_path / "job.csv"
    assert main(["plan", str(example_path()), "--robot", "none", "--feed", "20", "-o", str(out)]) == 0
    rows = [r for r in out.read_text().splitlines() if r and not r.startswith("#")]
    data = np.array([[float(x) for x in r.split(",")] for r in rows[1:]])
    assert data.shape[0] > 1000 and np.all(np.diff(data[:, 0]) > 0)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["plan", "missing.apt"], "missing.apt"),
        (["plan", "EXAMPLE", "--pass", "7"], "--pass 7: nx_first_pass.cls has passes 0..0"),
        (["plan", "EXAMPLE", "--pass", "x"], "--pass must be a pass number, 'longest' or 'all'"),
        (["plan", "EXAMPLE", "--part-frame", "1,2,3"], "--part-frame must be six"),
        (["plan", "EXAMPLE", "-o", "x.docx"], "unknown output type"),
        (["plan", "EXAMPLE", "--robot", "none", "-o", "x.script"], "needs joint targets"),
    ],
)
def test_cli_errors_are_one_line_with_exit_code_2(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv = [str(example_path(EXAMPLE_CLS)) if a == "EXAMPLE" else a for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("planner: error:") and message in err and "Traceback" not in err


def test_cli_plans_a_whole_multi_pass_file(tmp_path, capsys):
    from tests.cam_excerpts import NX_HEAD

    src = tmp_path / "head.cls"
    src.write_text(NX_HEAD)
    out = tmp_path / "job.csv"
    assert main(["plan", str(src), "--robot", "none", "-o", str(out), "--progress"]) == 0
    captured = capsys.readouterr()
    text = captured.out
    assert re.search(r"moves +\[#+ *\] +\d+\.\d %", captured.err)  # the progress bar
    assert re.search(r"-> \d+ passes, \d+ rapids", text) and "largest deviation from the CAM polyline" in text
    rows = [r for r in out.read_text().splitlines() if r and r[0] not in "#t"]
    data = np.array([[float(x) for x in r.split(",")] for r in rows])
    assert np.all(np.diff(data[:, 0]) > 0) and set(np.unique(data[:, 8])) >= {0.0, 1.0}
    assert main(["plan", str(src), "--robot", "none", "-o", str(tmp_path / "job.script")]) == 2


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
        pytest.skip("shared/data not present")
    assert main(["plan", str(SHARED_DATA / name), "--robot", "none", *extra]) == 0
    out = capsys.readouterr().out
    assert re.search(r"-> \d+ passes", out)
    dev = float(re.search(r"largest deviation from the CAM polyline ([0-9.]+) mm", out).group(1))
    assert dev <= 0.01
