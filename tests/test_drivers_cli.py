"""`planner run` (planner.frontends.cli.run) against a simulated controller it starts itself, and run_demo_on_sim."""

from __future__ import annotations

import re

import pytest

from drivers.execute import run_demo_on_sim
from planner import PlanSettings, plan
from planner.frontends.cli.run import main

DEMO = "examples/nx_first_pass.cls"
PART = "400mm,996.5mm,-100mm,0,0,0"


def test_planner_run_sim_program_mode_prints_the_report(capsys):
    rc = main(["run", DEMO, "--robot", "ur5e", "--part-frame", PART, "--cut-output", "standard:0", "--sim",
               "--mode", "program", "--sim-speed", "20", "--io", "modbus", "--progress"])
    captured = capsys.readouterr()
    out = captured.out
    assert rc == 0, out
    # the run's bar: job time done of the job's, with the pass and source line (the demo: one pass)
    bars = re.findall(r"execute: +\d+%\|[^|]*\| ([\d.]+)/([\d.]+) s of job time, (pass \d+|rapid|dwell|move), "
                      r"source line (\d+)", captured.err)
    assert bars, captured.err[-2000:]
    total = {float(b[1]) for b in bars}
    assert len(total) == 1 and all(0.0 <= float(b[0]) <= float(b[1]) for b in bars)
    assert any(b[2] == "pass 0" and int(b[3]) > 0 for b in bars), bars
    assert "simulated ur5e controller on 127." in out
    assert "execution (program): ok" in out
    assert "I/O: 2 of 2 switches made" in out
    err_mm = float(out.split("largest distance from the planned path ")[1].split(" mm")[0])
    assert err_mm <= 0.01  # the program's tolerance, 10 um


@pytest.mark.parametrize("args, message", [
    (["--robot", "ur5e"], "give the controller's address with --host"),
    (["--robot", "none", "--sim"], "--robot MODEL is needed"),
    (["--robot", "ur5e", "--host", "robot.local"], "--host must be an IP address"),
    (["--robot", "ur5e", "--sim", "--mode", "stream", "--sim-speed", "5"], "program mode only"),
])
def test_planner_run_refuses_bad_options_before_planning(capsys, args, message):
    assert main(["run", DEMO, *args]) == 2
    assert message in capsys.readouterr().err


def test_run_demo_on_sim():
    job = plan(DEMO, PlanSettings(robot="ur5e", part_frame=(0.4, 0.9965, -0.1, 0, 0, 0), cut_output=("standard", 0)))
    rep = run_demo_on_sim(job)
    assert rep.ok and rep.mode == "program", rep.describe()
    assert rep.max_path_error <= job.settings.tolerance
    assert all(e.switched and e.distance_mm < 1.0 for e in rep.io_events) and len(rep.io_events) == 2


def test_planner_run_sim_that_cannot_start_is_one_line(capsys):
    """The simulated controller's address taken (a listener on its RTDE port): one line and exit status 1, no
    traceback."""
    import socket

    from drivers.execute import free_loopback_host

    host = free_loopback_host()
    with socket.socket() as s:
        s.bind((host, 30004))
        s.listen()
        rc = main(["run", DEMO, "--robot", "ur5e", "--part-frame", PART, "--sim", "--host", host])
    err = capsys.readouterr().err
    assert rc == 1
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("planner run: error: cannot start a simulated controller on "
                                                   f"{host}"), err
    assert "Traceback" not in err


def test_planner_run_refuses_a_job_the_robot_cannot_make_before_starting_a_controller(capsys, monkeypatch):
    """No part frame: the part's origin at the robot's base, both moves out of reach (issue 27: a simulator was
    started and the run failed with exit 1 and "2 unreachable poses" where the summary counted moves). Exit 2, the
    reason in the summary's unit, and no controller started (``start_sim`` is never reached: it raises here)."""
    import planner.frontends.cli.run as run

    def no_controller(*a, **k):
        raise AssertionError("a controller was started for a job that cannot run")

    monkeypatch.setattr(run, "start_sim", no_controller)
    assert main(["run", DEMO, "--robot", "ur5e", "--sim"]) == 2
    out, err = capsys.readouterr()
    assert "ur5e: 2 moves with problems" in out and "simulated" not in out
    assert err.startswith("planner run: error: the robot cannot make 2 of the job's moves (first: nx_first_pass.cls "
                          "rapid at line 14: pose has no inverse kinematics solution") and err.count("\n") == 1
    assert err.endswith("; nothing is executed\n")
