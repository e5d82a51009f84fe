"""ur_rtde's RTDEControlInterface against the simulated controller: every move, servo and speed
command, kinematics queries, async progress, protective stops, and programs the simulator refuses."""

from __future__ import annotations

import socket
import time

import dashboard_client
import numpy as np
import pytest
import rtde_control
import rtde_receive

from planner.kinematics import forward, inverse
from sim.motion import HOME
from tests import sim_fixtures
from tests.sim_fixtures import eventually

make_sim = sim_fixtures.make_sim  # fixture

POS_TOL = 1e-4  # m (0.1 mm)
Q_TOL = 1e-4  # rad


@pytest.fixture
def arm(make_sim):
    """(sim, control client, receive client) on a fresh controller; the clients are closed after."""
    sim = make_sim()
    c = rtde_control.RTDEControlInterface(sim.host)
    r = rtde_receive.RTDEReceiveInterface(sim.host)
    yield sim, c, r
    try:
        if c.isProgramRunning():
            c.stopScript()
    finally:
        c.disconnect()
        r.disconnect()


def _settled(r, n=3):
    time.sleep(0.004 * n)
    return np.array(r.getActualQ()), np.array(r.getActualTCPPose())


def test_control_script_runs_and_reports(arm):
    sim, c, r = arm
    assert c.isConnected() and c.isProgramRunning()
    assert r.getRuntimeState() == 2 and r.getRobotStatus() & 2
    assert sim.state()["program"] == "rtde_control"


def test_movej_and_movel_reach_their_targets(arm):
    sim, c, r = arm
    q1 = HOME + np.array([0.3, -0.2, 0.25, 0.1, 0.2, -0.4])
    t = time.monotonic()
    assert c.moveJ(q1.tolist(), 1.0, 2.0)
    elapsed = time.monotonic() - t
    q, _ = _settled(r)
    np.testing.assert_allclose(q, q1, atol=Q_TOL)
    # the leading joint (0.4 rad) at v = 1, a = 2: a trapezoid of 0.4 + 0.5 = 0.9 s
    assert 0.85 < elapsed < 1.3
    p0 = np.array(r.getActualTCPPose())
    p1 = p0 + [0.05, -0.04, 0.06, 0.0, 0.0, 0.0]
    assert c.moveL(p1.tolist(), 0.2, 1.0)
    q, p = _settled(r)
    np.testing.assert_allclose(p[:3], p1[:3], atol=POS_TOL)
    np.testing.assert_allclose(forward("ur5e", q), p1, atol=1e-9)


def test_movel_is_straight_and_obeys_its_speed(arm, tmp_path):
    sim, c, r = arm
    p0 = np.array(r.getActualTCPPose())
    p1 = p0 + [0.0, 0.15, -0.05, 0.0, 0.0, 0.0]
    samples = []
    done = []
    c.moveL(p1.tolist(), 0.1, 0.5, True)
    t_end = time.monotonic() + 5
    while time.monotonic() < t_end and not done:
        samples.append(r.getActualTCPPose())
        if c.getAsyncOperationProgress() < 0 and len(samples) > 10:
            done.append(True)
        time.sleep(0.01)
    P = np.array(samples)[:, :3]
    d = p1[:3] - p0[:3]
    u = d / np.linalg.norm(d)
    off = (P - p0[:3]) - np.outer((P - p0[:3]) @ u, u)
    assert np.linalg.norm(off, axis=1).max() < 1e-4  # on the line to 0.1 mm
    speeds = np.linalg.norm(np.array([r.getActualTCPSpeed()[:3]]), axis=1)
    assert speeds.max() <= 0.1 + 1e-6


def test_movej_ik_and_movel_fk(arm):
    sim, c, r = arm
    pose = forward("ur5e", HOME + [0.2, 0.1, -0.2, 0.1, 0.1, 0.1])
    assert c.moveJ_IK(pose.tolist(), 1.0, 3.0)
    q, p = _settled(r)
    np.testing.assert_allclose(p, pose, atol=1e-9)
    q_target = q + [-0.1, 0.05, 0.05, 0.0, -0.1, 0.2]
    assert c.moveL_FK(q_target.tolist(), 0.2, 1.0)
    q, p = _settled(r)
    np.testing.assert_allclose(q, q_target, atol=Q_TOL)
    np.testing.assert_allclose(p, forward("ur5e", q_target), atol=1e-9)


def test_kinematics_queries_equal_planner_kinematics(arm):
    sim, c, r = arm
    q = HOME + np.array([0.4, -0.3, 0.5, 0.2, -0.3, 0.7])
    np.testing.assert_allclose(c.getForwardKinematics(q.tolist()), forward("ur5e", q), atol=1e-9)
    np.testing.assert_allclose(c.getForwardKinematics(), forward("ur5e", HOME), atol=1e-9)
    pose = forward("ur5e", q)
    ik = np.array(c.getInverseKinematics(pose.tolist(), q.tolist()))
    np.testing.assert_allclose(ik, q, atol=1e-9)  # the solution nearest qnear is q itself
    ik_default = np.array(c.getInverseKinematics(pose.tolist()))
    sols = inverse("ur5e", pose)
    wrapped = (ik_default + np.pi) % (2 * np.pi) - np.pi
    assert np.min(np.abs(sols - wrapped).max(axis=1)) < 1e-9  # one of planner.kinematics' solutions
    np.testing.assert_allclose(forward("ur5e", ik_default), pose, atol=1e-9)
    assert c.isPoseWithinSafetyLimits(pose.tolist())
    assert not c.isPoseWithinSafetyLimits([1.5, 0.0, 0.3, 0.0, 3.14, 0.0])
    assert c.isJointsWithinSafetyLimits(q.tolist())
    assert not c.isJointsWithinSafetyLimits((q + [7.0, 0, 0, 0, 0, 0]).tolist())


def test_set_tcp_moves_the_reported_tcp(arm):
    sim, c, r = arm
    tcp = [0.0, 0.02, 0.15, 0.0, 0.1, 0.0]
    assert c.setTcp(tcp)
    time.sleep(0.02)
    np.testing.assert_allclose(r.getActualTCPPose(), forward("ur5e", HOME, tcp), atol=1e-9)
    np.testing.assert_allclose(c.getTCPOffset(), tcp, atol=1e-12)
    target = forward("ur5e", HOME, tcp) + [0.03, 0.02, -0.02, 0, 0, 0]
    assert c.moveL(target.tolist(), 0.2, 1.0)
    _, p = _settled(r)
    np.testing.assert_allclose(p[:3], target[:3], atol=POS_TOL)


def test_async_moves_report_progress_and_stop(arm):
    sim, c, r = arm
    q1 = HOME + [1.0, 0, 0, 0, 0, 0]
    assert c.moveJ(q1.tolist(), 0.5, 1.0, True)
    time.sleep(0.3)
    st = c.getAsyncOperationProgressEx()
    assert st.isAsyncOperationRunning() and c.getAsyncOperationProgress() == 0
    c.stopJ(2.0, False)
    q_stop, _ = _settled(r)
    assert not c.getAsyncOperationProgressEx().isAsyncOperationRunning()
    assert c.getAsyncOperationProgress() < 0
    assert 0.055 < q_stop[0] < 0.9  # decelerated (at 2 rad/s^2) on the way
    assert np.abs(r.getActualQd()).max() == 0.0
    # a path: progress counts the waypoints as the arm passes them
    p0 = np.array(r.getActualTCPPose())
    path = [(p0 + [0.0, 0.04 * (k + 1), 0.0, 0, 0, 0]).tolist() + [0.1, 0.5, 0.0] for k in range(3)]
    assert c.moveL(path, True)
    seen = set()
    end = time.monotonic() + 10
    while time.monotonic() < end:
        st = c.getAsyncOperationProgressEx()
        if st.isAsyncOperationRunning():
            seen.add(st.progress())
        elif seen:
            break
        time.sleep(0.005)
    assert seen == {0, 1, 2}
    _, p = _settled(r)
    np.testing.assert_allclose(p[:3], path[-1][:3], atol=POS_TOL)


def test_paths_with_blends(arm):
    sim, c, r = arm
    p0 = np.array(r.getActualTCPPose())
    corners = [p0 + [0.08, 0, 0, 0, 0, 0], p0 + [0.08, 0.08, 0, 0, 0, 0], p0 + [0.0, 0.08, 0, 0, 0, 0]]
    path = [list(x) + [0.2, 1.0, 0.02] for x in corners]
    path[-1][-1] = 0.0
    t = time.monotonic()
    samples = []
    assert c.moveL(path, True)
    while c.getAsyncOperationProgress() >= 0 or time.monotonic() - t < 0.1:
        samples.append(r.getActualTCPPose()[:3])
        time.sleep(0.004)
    _, p = _settled(r)
    np.testing.assert_allclose(p[:3], corners[-1][:3], atol=POS_TOL)
    # the blend cuts the first corner by up to r (1 - 1/sqrt(2)) ... never passing through it
    d_corner = np.linalg.norm(np.array(samples) - corners[0][:3], axis=1).min()
    assert 0.002 < d_corner <= 0.02
    # and a joint-space path
    qs = [HOME + [0.2, 0, 0, 0, 0, 0], HOME + [0.2, -0.2, 0.2, 0, 0, 0], HOME + [0.0, -0.2, 0.2, 0, 0, 0]]
    assert c.moveJ([list(q) + [1.0, 2.0, 0.05] for q in qs[:-1]] + [list(qs[-1]) + [1.0, 2.0, 0.0]])
    q, _ = _settled(r)
    np.testing.assert_allclose(q, qs[-1], atol=1e-5)  # the path text has 6 significant digits


def test_servo_speed_and_stop_commands(arm):
    sim, c, r = arm
    q0 = np.array(r.getActualQ())
    for k in range(250):
        t0 = c.initPeriod()
        c.servoJ((q0 + [0.0002 * k, 0, 0, 0, 0, 0]).tolist(), 0.5, 0.5, 0.002, 0.1, 300)
        c.waitPeriod(t0)
    time.sleep(0.5)
    assert c.servoStop(5.0)
    q, _ = _settled(r)
    assert abs(q[0] - (q0[0] + 0.0002 * 249)) < 2e-3
    # servoL to a pose a little away
    p = np.array(r.getActualTCPPose())
    for k in range(250):
        t0 = c.initPeriod()
        c.servoL((p + [0.0, 0.0, -0.0001 * k, 0, 0, 0]).tolist(), 0.5, 0.5, 0.002, 0.1, 300)
        c.waitPeriod(t0)
    time.sleep(0.5)
    assert c.servoStop(5.0)
    _, pose = _settled(r)
    assert abs(pose[2] - (p[2] - 0.0249)) < 1e-3
    # speedJ then speedStop
    assert c.speedJ([0.2, 0, 0, 0, 0, 0], 1.0, 0.002)
    time.sleep(0.6)
    assert abs(r.getActualQd()[0] - 0.2) < 1e-6
    assert c.speedStop(2.0)
    assert np.abs(r.getActualQd()).max() == 0.0
    # speedL: the TCP moves at the commanded speed
    assert c.speedL([0.0, 0.0, 0.05, 0, 0, 0], 0.5, 0.002)
    time.sleep(0.6)
    v = np.array(r.getActualTCPSpeed())
    np.testing.assert_allclose(v[:3], [0.0, 0.0, 0.05], atol=1e-4)
    assert c.speedStop(1.0)
    # stopL while an async linear move runs
    p = np.array(r.getActualTCPPose())
    assert c.moveL((p + [0.0, 0.0, -0.1, 0, 0, 0]).tolist(), 0.1, 0.5, True)
    time.sleep(0.5)
    c.stopL(1.0, False)
    time.sleep(0.05)
    assert np.abs(r.getActualQd()).max() == 0.0


def test_unreachable_target_protective_stop_and_recovery(make_sim, capfd):
    sim = make_sim(speed=4.0)
    c = rtde_control.RTDEControlInterface(sim.host)
    r = rtde_receive.RTDEReceiveInterface(sim.host)
    d = dashboard_client.DashboardClient(sim.host)
    d.connect()
    try:
        # out of reach: a protective stop, which the client's own check reports (moveL returns False)
        capfd.readouterr()
        assert not c.moveL([1.6, 0.0, 0.3, 0.0, 3.14, 0.0], 0.25, 1.2)
        assert "script is not running" not in capfd.readouterr().err  # it was the protective-stop check
        assert eventually(r.isProtectiveStopped)  # the receive interface's next data packages
        assert r.getSafetyMode() == 3 and r.getSafetyStatusBits() & 4
        # the controller ends the program 0.1 s (simulated) after the stop
        assert eventually(lambda: not c.isProgramRunning())
        assert d.safetystatus() == "Safetystatus: PROTECTIVE_STOP"
        assert any("Protective stop" in m[2] for m in sim.state()["log"])
        # too soon to unlock, as on the controller (5 s); then released through the dashboard
        with pytest.raises(Exception, match="5s after occurrence"):
            d.unlockProtectiveStop()
        time.sleep(5.5 / 4.0)
        d.unlockProtectiveStop()
        assert d.safetystatus() == "Safetystatus: NORMAL"
        assert c.reuploadScript()
        assert eventually(c.isProgramRunning)
        assert c.moveJ((HOME + 0.1).tolist(), 1.0, 2.0)
        # a joint target beyond the limits is a protective stop too
        assert not c.moveJ((HOME + [7.0, 0, 0, 0, 0, 0]).tolist(), 1.0, 2.0)
        assert eventually(r.isProtectiveStopped)
    finally:
        c.disconnect()
        r.disconnect()
        d.disconnect()


def test_programs_replace_the_running_one_and_unknown_programs_are_refused(arm):
    sim, c, r = arm
    with socket.create_connection((sim.host, 30002)) as s:
        s.sendall(b'def not_ours():\n  popup("hello")\n  movej([0,0,0,0,0,0], a=1, v=1)\nend\n')
        time.sleep(0.2)
    st = sim.state()
    # the control script was replaced (stopped) and the new program refused whole: nothing moved
    assert st["runtime_state"] == "STOPPED" and st["program"] is None
    assert r.getRuntimeState() == 1
    assert any("Compile error" in m[2] and "not_ours" in m[2] for m in st["log"])
    np.testing.assert_allclose(st["q"], HOME, atol=1e-12)
    assert not c.isProgramRunning()
    assert not c.moveJ((HOME + 0.1).tolist())  # the client sees the script is gone
    assert c.reuploadScript()
    time.sleep(0.1)
    assert c.isProgramRunning() and c.moveJ((HOME + 0.1).tolist(), 1.0, 2.0)
    c.stopScript()
    time.sleep(0.05)
    assert r.getRuntimeState() == 1


def test_upper_range_registers(make_sim):
    sim = make_sim()
    flags = rtde_control.RTDEControlInterface.Flags
    c = rtde_control.RTDEControlInterface(sim.host, -1.0, flags.FLAG_UPLOAD_SCRIPT | flags.FLAG_UPPER_RANGE_REGISTERS)
    try:
        q1 = (HOME + [0.1, -0.1, 0.1, 0.0, 0.0, 0.2]).tolist()
        assert c.moveJ(q1, 1.0, 3.0)
        np.testing.assert_allclose(sim.state()["q"], q1, atol=1e-9)
        st = sim.state()
        assert st["out_int"][24] in (1, 2) and st["out_int"][0] == 0  # the script answers on register 24
        np.testing.assert_allclose(c.getForwardKinematics(), forward("ur5e", q1), atol=1e-9)
    finally:
        c.stopScript()
        c.disconnect()


def test_rtde_watchdog_stops_the_program(make_sim):
    sim = make_sim()
    c = rtde_control.RTDEControlInterface(sim.host)
    try:
        assert c.setWatchdog(20.0)  # at least 20 Hz of input packages, or the program stops
        for _ in range(20):
            assert c.kickWatchdog()
            time.sleep(0.01)
        assert c.isProgramRunning()
        time.sleep(0.3)  # silence
        assert not c.isProgramRunning()
        assert any("watchdog" in m[2] for m in sim.state()["log"])
    finally:
        c.disconnect()
