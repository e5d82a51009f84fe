"""URDriver's faults end to end through real ur_rtde into the simulated controller (sim.SimController): a servo
target that jumps (too fast for the joints), an emergency stop pressed mid-stream and mid-program, a stop from
the dashboard mid-program, and local control refused before the arm moves. Each run ends with the arm stopped
and the reason, with the job's time, planned pose and source line, in the report.

(tests/test_drivers_ur.py covers an unreachable target, the dashboard stop mid-stream, the controller dropping,
cancellation and a period overrun.)"""

from __future__ import annotations

import threading
import time

import dashboard_client
import numpy as np
import pytest
import rtde_receive

from drivers.base import EmergencyStopError, NotReadyError, ProtectiveStopError
from drivers.report import planned_path
from drivers.ur import ProgramStoppedError, URDriver
from planner import PlanSettings, plan
from tests import sim_fixtures
from tests.jumping_job import JumpingJob
from tests.sim_fixtures import eventually

make_sim = sim_fixtures.make_sim  # fixture

DEMO = "examples/nx_first_pass.cls"
PART = (0.4, 0.9965, -0.1, 0.0, 0.0, 0.0)
FAST = {"approach_speed": 2.0, "approach_acceleration": 3.0}
JUMP_AT = 1.0  # s into the cut
JUMP = 0.25  # rad on the elbow: within its position limits, far from where the arm is

# Streams at the controller rate: run on their own, after the parallel run (./run test).
pytestmark = pytest.mark.realtime


@pytest.fixture(scope="module")
def fast_job():
    """The demo pass at 4x its feed (16 s)."""
    return plan(DEMO, PlanSettings(robot="ur5e", part_frame=PART, cut_output=("standard", 0), feed_override=4.0))


@pytest.fixture(scope="module")
def demo_job():
    return plan(DEMO, PlanSettings(robot="ur5e", part_frame=PART, cut_output=("standard", 0)))


def _at_rest(host: str) -> float:
    r = rtde_receive.RTDEReceiveInterface(host)
    try:
        time.sleep(0.05)
        return float(np.abs(np.asarray(r.getActualQd())).max())
    finally:
        r.disconnect()


def _located(job, err, t_lo: float, t_hi: float) -> None:
    """The failure carries the job time in [t_lo, t_hi], the planned pose at that time and its source line."""
    pt, pp, _, lines, _ = planned_path(job)
    assert err.t is not None and t_lo <= err.t <= t_hi, (err.t, t_lo, t_hi)
    k = int(round(err.t * job.settings.rate))
    np.testing.assert_allclose(err.pose, pp[k], atol=1e-9)
    assert err.line == lines[k] and err.line > 0
    assert f"source line {err.line}" in str(err)


def _run_in_thread(d: URDriver, job, mode: str = "stream"):
    out: dict = {}
    th = threading.Thread(target=lambda: out.update(rep=d.execute(job, mode=mode)))
    th.start()
    return th, out


def _wait_mode(d: URDriver, mode: str, then: float, timeout: float = 30.0) -> None:
    end = time.monotonic() + timeout
    while d._mode != mode:
        assert time.monotonic() < end, "the run did not start"
        time.sleep(0.01)
    time.sleep(then)


def _wait_job_program(sim, then: float, timeout: float = 30.0) -> None:
    """Until the controller runs the job's own program (not ur_rtde's control script), then ``then`` s more."""
    assert eventually(lambda: sim.state()["program"] == "planner_job", timeout=timeout), "the program did not start"
    time.sleep(then)


def test_servo_target_that_jumps_is_a_protective_stop_with_time_pose_and_line(make_sim, fast_job):
    sim = make_sim()
    # the former servo settings, targets sent unshaped: the controller's answer to a target that jumps, not the servo
    # model's inverse (which would amplify the jump into a target beyond the joint's limits)
    with URDriver(sim.host, "ur5e", compensate=False, lookahead=0.1, gain=300.0, **FAST) as d:
        rep = d.execute(JumpingJob(fast_job, joint=2, jump=JUMP, after_s=JUMP_AT), mode="stream")
        assert d.state().protective_stop
        # the controller ends the program a few periods after the protective stop
        assert eventually(lambda: not d.state().program_running, timeout=2.0)
    assert not rep.ok
    err = rep.failure
    assert isinstance(err, ProtectiveStopError), rep.describe()
    assert "protective stop" in err.reason and "Safetystatus: PROTECTIVE_STOP" in err.reason
    cut0 = fast_job.trajectory().moves()[1]["t_start"]
    _located(fast_job, err, cut0 + JUMP_AT, cut0 + JUMP_AT + 0.05)  # within a few periods of the jump
    # the controller's reason: following the target would exceed the elbow's limits
    st = sim.state()
    stops = [m[2] for m in st["log"] if m[2].startswith("Protective stop")]
    assert len(stops) == 1 and "servoj: joint 2 acceleration" in stops[0], stops
    gap = float(stops[0].split("target (")[1].split(" rad")[0])
    assert JUMP <= gap < JUMP + 0.01, stops  # the jump, plus the arm's lag behind its targets
    # the arm stopped on the path, before following the jump
    assert rep.max_path_error < 0.5e-3, rep.describe()
    assert _at_rest(sim.host) == 0.0
    assert st["digital_out"] & 1 == 0  # the cut's output switched off


def test_emergency_stop_mid_stream(make_sim, fast_job):
    sim = make_sim()
    with URDriver(sim.host, "ur5e", **FAST) as d:
        th, out = _run_in_thread(d, fast_job)
        _wait_mode(d, "stream", 1.5)  # into the cut
        sim.press_emergency_stop()
        th.join(30)
        assert not th.is_alive()
        rep = out["rep"]
        state = d.state()
    err = rep.failure
    assert isinstance(err, EmergencyStopError), rep.describe()
    assert "emergency stop" in err.reason and "ROBOT_EMERGENCY_STOP" in err.reason
    _located(fast_job, err, 1.0, 3.0)  # pressed 1.5 s (wall) after the stream began
    assert state.emergency_stop and state.robot_mode == 3  # powered off
    assert _at_rest(sim.host) == 0.0
    assert rep.max_path_error < 0.2e-3, rep.describe()  # on the path up to the stop
    assert sim.state()["digital_out"] & 1 == 0


def test_emergency_stop_mid_program(make_sim, demo_job):
    sim = make_sim(speed=5.0)
    with URDriver(sim.host, "ur5e", **FAST) as d:
        th, out = _run_in_thread(d, demo_job, mode="program")
        _wait_job_program(sim, 1.0)
        sim.press_emergency_stop("system")
        th.join(30)
        assert not th.is_alive()
        rep = out["rep"]
        assert d.state().emergency_stop and not d.state().program_running
    err = rep.failure
    assert isinstance(err, EmergencyStopError), rep.describe()
    assert "SYSTEM_EMERGENCY_STOP" in err.reason
    assert err.t is not None and 0.0 <= err.t < rep.planned_duration and err.line is not None and err.pose
    assert _at_rest(sim.host) == 0.0
    assert rep.max_path_error <= demo_job.settings.tolerance, rep.describe()
    assert sim.state()["digital_out"] & 1 == 0


def test_stop_from_the_dashboard_mid_program(make_sim, demo_job):
    sim = make_sim(speed=5.0)
    with URDriver(sim.host, "ur5e", **FAST) as d:
        th, out = _run_in_thread(d, demo_job, mode="program")
        _wait_job_program(sim, 1.0)
        dash = dashboard_client.DashboardClient(sim.host)
        dash.connect()
        dash.stop()
        dash.disconnect()
        th.join(30)
        assert not th.is_alive()
        rep = out["rep"]
        assert d.state().runtime_state == 2  # ur_rtde's control script is back for the next move
    err = rep.failure
    assert isinstance(err, ProgramStoppedError), rep.describe()
    assert "stop from the dashboard" in err.reason and "mm from the job's last pose" in err.reason
    assert err.t is not None and 0.0 <= err.t < rep.planned_duration and err.line is not None and err.pose
    assert _at_rest(sim.host) == 0.0
    assert sim.state()["digital_out"] & 1 == 0


def test_local_control_is_refused_before_moving(make_sim, fast_job):
    sim = make_sim(remote_control=False)
    q0 = sim.state()["q"]
    with pytest.raises(NotReadyError, match="not in remote control"):
        URDriver(sim.host, "ur5e", **FAST).connect()
    d = URDriver(sim.host, "ur5e", **FAST)
    with pytest.raises(NotReadyError, match="not in remote control"):
        with d:
            d.execute(fast_job)
    st = sim.state()
    np.testing.assert_array_equal(st["q"], q0)  # nothing moved
    assert st["program"] is None and st["digital_out"] == 0
    # switched to remote control on the pendant: the same driver runs
    sim.set_remote_control(True)
    with URDriver(sim.host, "ur5e", **FAST) as d:
        assert d.state().ready
