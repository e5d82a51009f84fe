"""The simulated controller's faults through the real clients: protective stops for motions beyond the joint
limits (a servoJ target that jumps, a servo stream faster than a joint can go, a movej with too high a speed or
acceleration), the emergency stop (SimController's control channel and ``python -m sim``'s console), and local
control mode (dashboard refusals, script ports refusing programs, ur_rtde's own remote-control check)."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import dashboard_client
import numpy as np
import pytest
import rtde_control
import rtde_receive

from drivers.ur import _realtime_loop, _restore_scheduling
from planner.kinematics import forward, get_model
from sim import SimController
from sim.__main__ import command
from sim.dashboard import LOCAL_REFUSAL
from sim.motion import HOME, JOINT_ACCEL_MAX
from tests import sim_fixtures
from tests.sim_fixtures import eventually, next_host, signal_state

make_sim = sim_fixtures.make_sim  # fixture
REPO = Path(__file__).resolve().parents[1]
UR5E_SPEED = get_model("ur5e").speed_limits


def _raw(host: str, *lines: str) -> list[str]:
    """Dashboard replies to ``lines`` on a raw socket (greeting first)."""
    with socket.create_connection((host, 29999), timeout=3) as s:
        f = s.makefile("rw", newline="\n")
        replies = [f.readline().rstrip("\n")]
        for line in lines:
            f.write(line + "\n")
            f.flush()
            replies.append(f.readline().rstrip("\n"))
        return replies


def _send_program(host: str, text: str) -> None:
    with socket.create_connection((host, 30002)) as s:
        s.sendall(text.encode())


def _protective_stop_seen(sim, r, d, why: str) -> str:
    """Checks every sign of a protective stop a real controller gives; returns its text message."""
    assert eventually(r.isProtectiveStopped)
    assert r.getSafetyMode() == 3
    assert r.getSafetyStatusBits() & (1 << 2) and r.getSafetyStatusBits() & (1 << 10)
    assert not r.getSafetyStatusBits() & 1  # not in normal mode
    assert d.safetystatus() == "Safetystatus: PROTECTIVE_STOP"
    assert eventually(lambda: r.getRuntimeState() == 1)  # the program stopped
    assert eventually(lambda: np.abs(r.getActualQd()).max() == 0.0)  # the arm at rest
    msgs = [m[2] for m in sim.state()["log"] if m[1] == "Safety" and m[2].startswith("Protective stop")]
    assert len(msgs) == 1 and why in msgs[0], msgs
    return msgs[0]


def _unlock_after_5s(sim, d, speed: float) -> None:
    with pytest.raises(RuntimeError, match="5s after occurrence"):
        d.unlockProtectiveStop()
    time.sleep(5.2 / speed)
    d.unlockProtectiveStop()
    assert d.safetystatus() == "Safetystatus: NORMAL"


@pytest.fixture
def arm(make_sim):
    """A controller at 4x speed (the 5 s before an unlock pass in 1.25 s) with ur_rtde's three clients."""
    sim = make_sim(speed=4.0)
    c = rtde_control.RTDEControlInterface(sim.host)
    r = rtde_receive.RTDEReceiveInterface(sim.host)
    d = dashboard_client.DashboardClient(sim.host)
    d.connect()
    yield sim, c, r, d
    for x in (c, r, d):
        x.disconnect()


def test_servoj_target_that_jumps_is_a_protective_stop(arm):
    sim, c, r, d = arm
    q0 = np.asarray(r.getActualQ())
    jump = q0 + [0.0, 0.0, 0.3, 0.0, 0.0, 0.0]  # within the joint limits, 0.3 rad from the arm
    assert c.servoJ(jump.tolist(), 0.0, 0.0, 0.002, 0.1, 300.0)  # real-time command: sent, not waited for
    text = _protective_stop_seen(sim, r, d, "servoj: joint 2 acceleration")
    assert "+0.3000 rad from the actual position" in text
    # stopped at once: the arm did not follow the jump
    assert np.abs(np.asarray(r.getActualQ()) - q0).max() < 1e-3
    assert not c.isProgramRunning()
    _unlock_after_5s(sim, d, 4.0)
    # the servoJ command is still in ur_rtde's command register (a real-time command is never cleared): a
    # re-uploaded script would run it again, as on a real controller. servoStop, refused with the script
    # stopped, clears it first
    assert not c.servoStop(10.0)
    assert c.reuploadScript() and eventually(c.isProgramRunning)
    assert c.moveJ((q0 + 0.05).tolist(), 1.0, 2.0)  # moving again after the unlock
    assert r.getSafetyMode() == 1


@pytest.mark.realtime  # a 500 Hz stream whose pace matters: alone on the machine, not beside the parallel run
@pytest.mark.realtime
def test_servoj_stream_faster_than_a_joint_can_go_is_a_protective_stop(make_sim):
    """A smooth stream (acceleration 8 rad/s^2, under the limit) that passes the base joint's 3.14 rad/s: the arm
    follows it until the joint would need more than its speed limit, then stops (at the controller's own pace:
    a 500 Hz stream is one target per control period). Streamed SCHED_FIFO as the driver streams (ur_rtde's
    threads, started by the interfaces, inherit it), in the test command's real-time step: from an ordinary thread
    on a loaded machine the stream missed periods and the arm was stopped further on."""
    sim = make_sim()
    before = _realtime_loop()
    try:
        c = rtde_control.RTDEControlInterface(sim.host)
        r = rtde_receive.RTDEReceiveInterface(sim.host)
        d = dashboard_client.DashboardClient(sim.host)
        d.connect()
        try:
            _stream_too_fast(sim, c, r, d)
        finally:
            for x in (c, r, d):
                x.disconnect()
    finally:
        if before is not None:
            _restore_scheduling(before)


def _stream_too_fast(sim, c, r, d) -> None:
    q0 = np.asarray(r.getActualQ())
    acc = 8.0
    ok = True
    for k in range(1, 400):  # 0.8 s of targets: 6.4 rad/s at the end
        t0 = c.initPeriod()
        t = k * 0.002
        q = q0 + [0.5 * acc * t * t, 0, 0, 0, 0, 0]
        ok = c.servoJ(q.tolist(), 0.0, 0.0, 0.002, 0.1, 300.0)
        c.waitPeriod(t0)
        if not ok or r.isProtectiveStopped():
            break
    text = _protective_stop_seen(sim, r, d, "servoj: joint 0 speed")
    speed = float(text.split("speed ")[1].split(" rad/s")[0])
    assert UR5E_SPEED[0] < speed < 1.01 * UR5E_SPEED[0]  # stopped as it passed the limit
    moved = float(np.asarray(r.getActualQ())[0] - q0[0])
    # it had followed the stream up to about where the lagging joint reached its limit
    assert 0.3 < moved < 0.5 * UR5E_SPEED[0] ** 2 / acc + 0.1


def _program(*lines: str) -> str:
    return "def fault_job():\n" + "".join(f"  {ln}\n" for ln in lines) + "end\n"


@pytest.mark.parametrize("move, why, moves", [
    # leading joint 2 rad at 5 rad/s: beyond the 3.14 rad/s limit once it has accelerated
    ("movej([{q0}, -1.5708, 1.5708, -1.5708, -1.5708, 0.0], a=10.0, v=5.0)", "movej: joint 0 speed", True),
    # 100 rad/s^2 from the first period: the arm does not move
    ("movej([{q0}, -1.5708, 1.5708, -1.5708, -1.5708, 0.0], a=100.0, v=1.0)", "movej: joint 0 acceleration",
     False),
])
def test_movej_beyond_the_joint_limits_in_a_program_is_a_protective_stop(arm, move, why, moves):
    sim, c, r, d = arm
    c.stopScript()
    assert eventually(lambda: r.getRuntimeState() == 1)
    _send_program(sim.host, _program("set_standard_digital_out(0, True)", move.format(q0=HOME[0] + 2.0)))
    text = _protective_stop_seen(sim, r, d, why)
    q = np.asarray(r.getActualQ())
    if moves:
        assert 0.3 < q[0] - HOME[0] < 2.0  # stopped on the way
        assert float(text.split("speed ")[1].split(" rad/s")[0]) > UR5E_SPEED[0]
    else:
        np.testing.assert_allclose(q, HOME, atol=1e-12)
        assert float(text.split("acceleration ")[1].split(" rad/s")[0]) > JOINT_ACCEL_MAX
    assert sim.state()["program"] is None


def test_movel_too_fast_in_a_program_is_a_protective_stop(arm):
    """A 3 m/s linear move across the workspace needs more than the joints' speed limits."""
    sim, c, r, d = arm
    c.stopScript()
    assert eventually(lambda: r.getRuntimeState() == 1)
    p = forward("ur5e", HOME) + [0.0, 0.35, -0.2, 0.0, 0.0, 0.0]
    _send_program(sim.host, _program(f"movel(p[{', '.join(f'{x:.6f}' for x in p)}], a=20.0, v=3.0)"))
    _protective_stop_seen(sim, r, d, "movel: joint")


def test_emergency_stop_mid_move_powers_the_arm_off(arm):
    sim, c, r, d = arm
    q0 = np.asarray(r.getActualQ())
    assert c.moveJ((q0 + [1.5, 0, 0, 0, 0, 0]).tolist(), 0.5, 1.0, True)  # async: 3+ s
    assert eventually(lambda: np.abs(r.getActualQd()).max() > 0.2)
    sim.press_emergency_stop()
    assert eventually(lambda: r.getSafetyMode() == 7)  # ROBOT_EMERGENCY_STOP
    bits = r.getSafetyStatusBits()
    assert bits & (1 << 6) and bits & (1 << 7) and bits & (1 << 10) and not bits & 1
    assert r.isEmergencyStopped() and not r.isProtectiveStopped()
    assert r.getRobotMode() == 3 and not r.getRobotStatus() & 1  # powered off
    assert r.getRuntimeState() == 1 and not c.isProgramRunning()
    assert np.abs(r.getActualQd()).max() == 0.0
    q_stop = np.asarray(r.getActualQ())
    time.sleep(0.2)
    np.testing.assert_array_equal(np.asarray(r.getActualQ()), q_stop)  # stays where it stopped
    assert d.safetystatus() == "Safetystatus: ROBOT_EMERGENCY_STOP" and d.robotmode() == "Robotmode: POWER_OFF"
    st = sim.state()
    assert any(m[1] == "Safety" and "emergency stop" in m[2] for m in st["log"])
    # nothing restarts the arm while the button is pressed
    d.powerOn()
    assert d.robotmode() == "Robotmode: POWER_OFF"
    c.reuploadScript()  # sent; the controller does not start it
    time.sleep(0.1)
    assert not c.isProgramRunning()
    assert any("not started: robot is POWER_OFF" in m[2] for m in sim.state()["log"])
    # released: normal safety, still powered off until power on and brake release
    assert sim.release_emergency_stop() and not sim.release_emergency_stop()
    assert eventually(lambda: r.getSafetyMode() == 1) and r.getRobotMode() == 3
    d.powerOn()
    d.brakeRelease()
    assert d.robotmode() == "Robotmode: RUNNING"
    assert c.reuploadScript() and eventually(c.isProgramRunning)
    assert c.moveJ(q0.tolist(), 1.0, 2.0)


def test_system_emergency_stop_mid_program(arm):
    sim, c, r, d = arm
    c.stopScript()
    assert eventually(lambda: r.getRuntimeState() == 1)
    _send_program(sim.host, _program("set_standard_digital_out(0, True)", "sleep(5.0)"))
    assert eventually(lambda: r.getRuntimeState() == 2)
    sim.press_emergency_stop("system")
    assert eventually(lambda: r.getSafetyMode() == 6)  # SYSTEM_EMERGENCY_STOP
    bits = r.getSafetyStatusBits()
    assert bits & (1 << 5) and bits & (1 << 7) and not bits & (1 << 6)
    assert r.getRuntimeState() == 1 and r.getRobotMode() == 3
    assert d.safetystatus() == "Safetystatus: SYSTEM_EMERGENCY_STOP"
    with pytest.raises(Exception, match="kind must be"):
        sim.press_emergency_stop("pendant")


def test_python_m_sim_console_presses_and_releases_the_emergency_stop():
    host = sim_fixtures.next_host()
    p = subprocess.run([sys.executable, "-m", "sim", "--host", host, "--no-modbus"], cwd=REPO, text=True,
                       input="estop\nstate\nrelease\nrelease\nlocal\nstate\nbogus\nquit\n", capture_output=True,
                       timeout=60)
    out = p.stdout
    assert p.returncode == 0, p.stderr
    assert "emergency stop pressed (robot)" in out
    assert "robot POWER_OFF, safety ROBOT_EMERGENCY_STOP" in out
    assert "emergency stop released" in out and "no emergency stop is pressed" in out
    assert "safety NORMAL" in out and "local control" in out.split("emergency stop released")[1]
    assert "estop    press the teach pendant's emergency stop" in out  # 'bogus': the command list


def test_console_commands_on_a_running_controller(make_sim):
    sim = make_sim()
    assert "estop system" in command(sim, "estop pendant")  # refused, with the right spelling
    assert command(sim, "estop system").startswith("emergency stop pressed (system)")
    assert sim.state()["safety_mode"] == "SYSTEM_EMERGENCY_STOP"
    assert command(sim, "release").startswith("emergency stop released")
    assert command(sim, "remote") == "remote control" and sim.state()["remote_control"] is True


def test_local_control_mode_refuses_motion_commands_and_programs(make_sim):
    sim = make_sim(remote_control=False)
    replies = _raw(sim.host, "is in remote control", "robotmode", "safetystatus", "running", "power off",
                   "power on", "brake release", "play", "load job.urp", "load installation default.installation",
                   "unlock protective stop", "stop", "pause", "PolyscopeVersion")
    assert replies[1:5] == ["false", "Robotmode: RUNNING", "Safetystatus: NORMAL", "Program running: false"]
    assert replies[5:14] == [LOCAL_REFUSAL] * 9
    assert replies[14].startswith("URSoftware 5.11")
    assert LOCAL_REFUSAL.startswith("Command is not allowed due to safety reasons")
    # ur_rtde's own check refuses the control interface (the host is not 127.0.0.1)
    with pytest.raises(RuntimeError, match="enable remote control"):
        rtde_control.RTDEControlInterface(sim.host)
    d = dashboard_client.DashboardClient(sim.host)
    d.connect()
    assert not d.isInRemoteControl()
    with pytest.raises(RuntimeError, match="Command is not allowed"):
        d.play()
    d.disconnect()
    # the script ports take no program: nothing runs, nothing moves
    _send_program(sim.host, _program("set_standard_digital_out(0, True)",
                                     "movej([0.3, -1.5708, 1.5708, -1.5708, -1.5708, 0.0], a=1.0, v=1.0)"))
    time.sleep(0.3)
    st = sim.state()
    assert st["runtime_state"] == "STOPPED" and st["program"] is None and st["digital_out"] == 0
    np.testing.assert_allclose(st["q"], HOME, atol=0)
    assert any("local control mode" in m[2] and "port 30002" in m[2] for m in st["log"]), st["log"]
    # switched to remote control on the pendant: the same program runs
    sim.set_remote_control(True)
    assert _raw(sim.host, "is in remote control")[1] == "true"
    _send_program(sim.host, _program("set_standard_digital_out(0, True)"))
    assert eventually(lambda: sim.state()["digital_out"] & 1 == 1)


def test_local_control_switched_on_mid_program_lets_it_run_and_refuses_the_next(make_sim):
    sim = make_sim(speed=4.0)
    _send_program(sim.host, _program("sleep(1.0)", "set_standard_digital_out(1, True)"))
    assert eventually(lambda: sim.state()["runtime_state"] == "PLAYING")
    sim.set_remote_control(False)
    assert eventually(lambda: sim.state()["digital_out"] & 2 == 2)  # ran to its end
    _send_program(sim.host, _program("set_standard_digital_out(2, True)"))
    time.sleep(0.3)
    st = sim.state()
    assert st["digital_out"] & 4 == 0 and st["runtime_state"] == "STOPPED"


def test_speed_changed_while_running(make_sim):
    """Fast-forward switched on through the control channel: simulated time runs 20x the wall clock from then."""
    sim = make_sim()
    with pytest.raises(ValueError, match="speed must be a number > 0"):
        sim.set_speed(0)
    t0, w0 = sim.state()["time"], time.monotonic()
    time.sleep(0.5)
    t1, w1 = sim.state()["time"], time.monotonic()
    sim.set_speed(20.0)
    time.sleep(0.5)
    t2, w2 = sim.state()["time"], time.monotonic()
    assert (t1 - t0) / (w1 - w0) == pytest.approx(1.0, rel=0.2)
    assert (t2 - t1) / (w2 - w1) == pytest.approx(20.0, rel=0.25)


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"speed": float("inf")}, "speed must be a number > 0 and <= 10000, got inf"),
    ({"speed": float("nan")}, "speed must be a number > 0 and <= 10000, got nan"),
    ({"speed": 1e6}, "speed must be a number > 0 and <= 10000"),
    ({"speed": True}, "speed must be a number"),
    ({"record": "run.txt"}, "record: use a .npz or .csv file name"),
    ({"modbus_port": 70000}, "modbus_port must be within 0..65535"),
])
def test_absurd_controller_arguments_are_refused_before_a_process_starts(kwargs, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        SimController("127.0.0.2", **kwargs)


def test_record_naming_a_directory_is_refused(tmp_path):
    (tmp_path / "d.npz").mkdir()
    with pytest.raises(ValueError, match="is a directory"):
        SimController("127.0.0.2", record=tmp_path / "d.npz")


def test_the_command_line_says_when_the_recording_could_not_be_written(tmp_path):
    """``python -m sim --record`` into a place the child cannot write (/proc): an error naming the file and
    the reason, exit status 1, never 'recording written'."""
    host = next_host()
    proc = subprocess.Popen([sys.executable, "-m", "sim", "--host", host, "--no-modbus", "--record", "/proc/run.npz"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=REPO)
    try:
        assert "simulated ur5e on" in proc.stdout.readline()
        proc.send_signal(signal.SIGINT)
        try:
            out, err = proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            pytest.fail(f"python -m sim ran on 30 s after SIGINT; its signals: {signal_state(proc.pid)}, this "
                        f"process's: {signal_state(os.getpid())}")
    finally:
        proc.kill()
    assert proc.returncode == 1, (out, err)
    assert "recording written" not in out
    assert "error: the recording was not written to /proc/run.npz" in err and "run.npz" in err


def test_the_command_channel_refuses_malformed_commands_and_keeps_serving():
    """The parent's JSON command channel of ``python -m sim.server``: READY first, then one reply per line; a
    malformed command gets an error naming it and the channel goes on."""
    host = next_host()
    proc = subprocess.Popen([sys.executable, "-m", "sim.server", "--host", host, "--no-realtime"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                            cwd=REPO)
    try:
        lines = ['{"cmd": "emergency_stop", "pressed": 1}', '{"cmd": "remote_control"}', '{"cmd": "speed", "speed": '
                 '"fast"}', '{"cmd": "speed", "speed": 1e300}', '{"cmd": "warp"}', 'not json', '[1, 2]', '{"cmd": "state"}']
        proc.stdin.write("\n".join(lines) + "\n")
        proc.stdin.flush()
        assert proc.stdout.readline().startswith("READY ")
        replies = [json.loads(proc.stdout.readline()) for _ in lines]
        proc.stdin.write('{"cmd": "stop"}\n')
        proc.stdin.flush()
        assert proc.wait(20) == 0
    finally:
        proc.kill()
    assert replies[0] == {"error": "emergency_stop: 'pressed' must be true or false, got 1"}
    assert replies[1] == {"error": "remote_control: missing field 'on'"}
    assert replies[2]["error"].startswith("speed must be a number > 0 and <= 10000, got 'fast'")
    assert replies[3]["error"].startswith("speed must be a number > 0 and <= 10000, got 1e+300")
    assert replies[4] == {"error": "unknown command 'warp'"}
    assert "error" in replies[5]
    assert replies[6] == {"error": "a command is a JSON object, got '[1, 2]'"}
    assert replies[7]["safety_mode"] == "NORMAL" and replies[7]["runtime_state"] == "STOPPED"
