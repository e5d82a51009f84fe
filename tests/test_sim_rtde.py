"""The simulated controller's RTDE server and process model, through the real ur_rtde receive client
and raw sockets (malformed packages, unknown names, inputs claimed twice, clients vanishing)."""

from __future__ import annotations

import os
import signal
import socket
import struct
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
import rtde_control
import rtde_io
import rtde_receive

from planner.kinematics import forward
from sim import SimController
from sim.motion import HOME
from tests import sim_fixtures
from tests.sim_fixtures import RawRTDE, next_host

make_sim, shared_sim = sim_fixtures.make_sim, sim_fixtures.shared_sim  # fixtures


def test_receive_interface_reads_the_controller_state(shared_sim):
    r = rtde_receive.RTDEReceiveInterface(shared_sim.host)
    try:
        assert r.isConnected()
        np.testing.assert_allclose(r.getActualQ(), HOME, atol=1e-12)
        np.testing.assert_allclose(r.getActualTCPPose(), forward("ur5e", HOME), atol=1e-12)
        assert r.getRobotMode() == 7 and r.getSafetyMode() == 1 and r.getRuntimeState() == 1
        assert r.getSafetyStatusBits() == 1 and r.getRobotStatus() & 1
        assert not r.isProtectiveStopped() and not r.isEmergencyStopped()
        assert r.getSpeedScaling() == 1.0 and r.getTargetSpeedFraction() == 1.0
        assert r.getPayloadCog() == [0.0, 0.0, 0.0] and len(r.getPayloadInertia()) == 6
        # 500 Hz on the simulated clock: timestamps advance with wall time in 2 ms steps
        t0, w0 = r.getTimestamp(), time.monotonic()
        time.sleep(0.5)
        t1, w1 = r.getTimestamp(), time.monotonic()
        assert abs((t1 - t0) - (w1 - w0)) < 0.02
        assert abs(t1 / 0.002 - round(t1 / 0.002)) < 1e-6
    finally:
        r.disconnect()


def test_custom_recipe_frequency_and_unknown_names(shared_sim):
    r = rtde_receive.RTDEReceiveInterface(shared_sim.host, 125.0, ["timestamp", "actual_q"])
    try:
        seen = set()
        end = time.monotonic() + 0.3
        while time.monotonic() < end:
            seen.add(round(r.getTimestamp(), 6))
            time.sleep(0.0005)
        steps = np.diff(sorted(seen))
        # 125 Hz: every package 8 ms of simulated time after the previous (a late tick on a loaded
        # machine may add one 2 ms period, never take one away)
        assert np.median(steps) == pytest.approx(0.008) and steps.min() >= 0.008 - 1e-9, steps
    finally:
        r.disconnect()
    with pytest.raises(RuntimeError, match="not found by the controller.*no_such_variable"):
        rtde_receive.RTDEReceiveInterface(shared_sim.host, 500.0, ["timestamp", "no_such_variable"])


def test_two_clients_claiming_one_input_the_second_is_refused(make_sim):
    sim = make_sim()
    c1 = rtde_control.RTDEControlInterface(sim.host)
    try:
        with pytest.raises(RuntimeError, match="already in use"):
            rtde_control.RTDEControlInterface(sim.host)
        # the first client still drives the arm
        q = (HOME + 0.05).tolist()
        assert c1.moveJ(q, 1.0, 4.0)
        np.testing.assert_allclose(sim.state()["q"], q, atol=1e-9)
        # an IO client uses other registers: no conflict
        io = rtde_io.RTDEIOInterface(sim.host)
        assert io.setStandardDigitalOut(1, True)
        io.disconnect()
    finally:
        c1.stopScript()
        c1.disconnect()


def test_raw_protocol_answers_and_malformed_packages(shared_sim):
    host = shared_sim.host
    watcher = rtde_receive.RTDEReceiveInterface(host)
    raw = RawRTDE(host)
    try:
        raw.send("V", struct.pack(">H", 2))
        assert raw.recv() == ("V", b"\x01")
        raw.send("V", struct.pack(">H", 7))  # unsupported protocol version
        assert raw.recv() == ("V", b"\x00")
        raw.send("v")
        kind, payload = raw.recv()
        assert kind == "v" and struct.unpack(">IIII", payload)[:2] == (5, 11)
        raw.send("O", struct.pack(">d", 500.0) + b"timestamp,bogus_name,actual_q,")
        kind, payload = raw.recv()
        assert kind == "O" and payload[0] == 0 and payload[1:] == b"DOUBLE,NOT_FOUND,VECTOR6D"
        raw.send("I", b"input_int_register_40,no_such_input,")
        kind, payload = raw.recv()
        assert kind == "I" and payload[0] == 0 and payload[1:] == b"INT32,NOT_FOUND"
        raw.send("I", b"input_int_register_40,input_double_register_40,")
        kind, payload = raw.recv()
        assert kind == "I" and payload == b"\x01INT32,DOUBLE"
        # unknown package type, unknown recipe, short and long data packages: a text message each
        raw.send("X", b"abc")
        kind, payload = raw.recv()
        assert kind == "M" and "unknown package type 88" in raw.text(payload)
        raw.send("U", b"\x09" + b"\x00" * 12)
        kind, payload = raw.recv()
        assert kind == "M" and "unknown input recipe id 9" in raw.text(payload)
        raw.send("U", b"\x01" + struct.pack(">i", 5))
        kind, payload = raw.recv()
        assert kind == "M" and "has 4 bytes, the recipe needs 12" in raw.text(payload)
        raw.send("U", b"\x01" + struct.pack(">id", 7, 2.5) + b"\x00\x00")
        kind, payload = raw.recv()
        assert kind == "M" and "extra bytes ignored" in raw.text(payload)
        state = shared_sim.state()
        assert state["in_int"][40] == 7 and state["in_double"][40] == 2.5
        # a header whose size is below the header's own: the controller closes this connection
        raw.send("U", b"", size=2)
        kind, payload = raw.recv()
        assert kind == "M" and "malformed" in raw.text(payload)
        with pytest.raises((ConnectionError, OSError)):
            for _ in range(10):
                raw.recv()
        # other clients were served throughout
        t0 = watcher.getTimestamp()
        time.sleep(0.1)
        assert watcher.isConnected() and watcher.getTimestamp() > t0
    finally:
        raw.close()
        watcher.disconnect()


def test_protocol_version_1_until_the_client_asks_for_2(shared_sim):
    """RTDE's protocol versions as the guide and UR's C++ client library lay them out: a connection that asks for no
    version speaks version 1 (an output setup without frequency, answered and sent without recipe id, at the control
    rate; text messages of level + text; a client's text message refused), and the version cannot change once a
    recipe is set up."""
    raw = RawRTDE(shared_sim.host)
    try:
        raw.send("v")
        kind, payload = raw.recv()
        assert kind == "v" and struct.unpack(">IIII", payload)[:2] == (5, 11)  # in both versions
        raw.send("O", b"timestamp,actual_q")
        assert raw.recv() == ("O", b"DOUBLE,VECTOR6D")  # no recipe id
        raw.send("I", b"input_int_register_30")
        assert raw.recv() == ("I", b"\x01INT32")  # inputs keep their id in version 1
        raw.send("V", struct.pack(">H", 2))
        assert raw.recv() == ("V", b"\x00")  # a recipe is set up: no change of version
        raw.send("O", b"timestamp,actual_q,bogus")  # a second setup replaces the one output recipe
        assert raw.recv() == ("O", b"DOUBLE,VECTOR6D,NOT_FOUND")
        raw.send("O", b"actual_q,timestamp")
        assert raw.recv() == ("O", b"VECTOR6D,DOUBLE")
        raw.send("S")
        assert raw.recv() == ("S", b"\x01")
        stamps = []
        while len(stamps) < 200:
            kind, payload = raw.recv(skip_data=False)
            if kind == "U":
                assert len(payload) == 56  # 6 + 1 doubles, no recipe id
                q = struct.unpack_from(">6d", payload)
                np.testing.assert_allclose(q, HOME, atol=1e-12)
                stamps.append(struct.unpack_from(">d", payload, 48)[0])
        steps = np.round(np.diff(stamps) / 0.002)
        assert (steps >= 1).all() and np.count_nonzero(steps == 1) >= 0.95 * steps.size  # every control period
        raw.send("U", b"\x01" + struct.pack(">i", 41))  # input data packages carry their recipe id
        assert sim_fixtures.eventually(lambda: shared_sim.state()["in_int"][30] == 41)
        raw.send("M", b"\x05hello\x04test\x03")
        kind, payload = raw.recv()
        assert kind == "M" and payload[0] == 1  # version 1: level ERROR, then the text
        assert payload[1:].decode() == "a text message from the client needs RTDE protocol version 2"
        raw.send("P")
        while (kind := raw.recv()[0]) != "P":
            pass
    finally:
        raw.close()
    # version 2 asked before any setup: the recipe id in the answers and the data packages, text messages with source
    raw = RawRTDE(shared_sim.host)
    try:
        for version, answer in ((3, b"\x00"), (0, b"\x00"), (1, b"\x01"), (2, b"\x01")):
            raw.send("V", struct.pack(">H", version))
            assert raw.recv() == ("V", answer)
        raw.send("V", b"\x02")  # a short request: refused
        assert raw.recv() == ("V", b"\x00")
        raw.send("O", struct.pack(">d", 100.0) + b"timestamp")
        assert raw.recv() == ("O", b"\x01DOUBLE")
        raw.send("V", struct.pack(">H", 1))
        assert raw.recv() == ("V", b"\x00")
        raw.send("V", struct.pack(">H", 2))  # the version it speaks: accepted
        assert raw.recv() == ("V", b"\x01")
        raw.send("M", b"\x05hello\x04test\x03")  # taken silently
        raw.send("X")
        kind, payload = raw.recv()
        assert kind == "M" and raw.text(payload) == "unknown package type 88"
        assert payload[-1] == 1 and payload[1 + payload[0] :][1:-1] == b"RTDE"
        raw.send("S")
        assert raw.recv() == ("S", b"\x01")
        kind, payload = raw.recv(skip_data=False)
        assert kind == "U" and len(payload) == 9 and payload[0] == 1
    finally:
        raw.close()


def test_data_before_start_and_pause(shared_sim):
    raw = RawRTDE(shared_sim.host)
    try:
        raw.send("V", struct.pack(">H", 2))
        assert raw.recv() == ("V", b"\x01")
        raw.send("I", b"input_double_register_41,")
        assert raw.recv() == ("I", b"\x01DOUBLE")
        raw.send("U", b"\x01" + struct.pack(">d", 1.25))  # no 'S' (as RTDEIOInterface)
        raw.send("O", struct.pack(">d", 250.0) + b"timestamp,input_double_register_41,")
        assert raw.recv() == ("O", b"\x01DOUBLE,DOUBLE")
        raw.send("S")
        assert raw.recv() == ("S", b"\x01")
        kind, payload = raw.recv(skip_data=False)
        assert kind == "U" and payload[0] == 1 and struct.unpack(">dd", payload[1:])[1] == 1.25
        raw.send("P")
        while True:
            kind, payload = raw.recv(skip_data=True)
            if kind == "P":
                break
        assert payload == b"\x01"
    finally:
        raw.close()


@pytest.mark.parametrize("speed", [1.0, 10.0])
def test_a_controller_held_up_by_the_machine_sends_every_package_late(make_sim, speed):
    """The whole simulator process stopped for 0.1 s (a machine stall, SIGSTOP): afterwards the packages of the
    stall arrive, in a burst, in order. At 1x the simulated clock has followed the wall clock and every 2 ms
    package is there; in fast-forward (a package per wall-clock period, ``speed`` control periods apart) none is
    further apart than that (the catch-up is bounded, so simulated time may fall behind, never skip)."""
    sim = make_sim(speed=speed)
    raw = RawRTDE(sim.host)
    try:
        raw.send("V", struct.pack(">H", 2))
        assert raw.recv() == ("V", b"\x01")
        raw.send("O", struct.pack(">d", 500.0) + b"timestamp")
        assert raw.recv() == ("O", b"\x01DOUBLE")
        raw.send("S")
        assert raw.recv() == ("S", b"\x01")
        stamps = []
        while len(stamps) < 1000:  # 2 s
            kind, payload = raw.recv(skip_data=False)
            if kind == "U":
                stamps.append(struct.unpack(">d", payload[1:9])[0])
            if len(stamps) == 200:
                os.kill(sim.proc.pid, signal.SIGSTOP)
                time.sleep(0.1)
                os.kill(sim.proc.pid, signal.SIGCONT)
    finally:
        raw.close()
    steps = np.round(np.diff(stamps) / 0.002).astype(int)
    if speed == 1.0:
        assert (steps == 1).all(), np.unique(steps, return_counts=True)
        assert stamps[-1] - stamps[0] == pytest.approx(0.002 * 999, abs=1e-9)
    else:
        assert steps.min() >= 0 and steps.max() <= speed, np.unique(steps, return_counts=True)
        assert np.count_nonzero(steps == speed) > 0.8 * steps.size  # a package every 10 periods but for the stall


def test_client_vanishing_mid_stream_leaves_the_controller_serving(make_sim):
    sim = make_sim()
    # a raw client that subscribes at 500 Hz and never reads, then one killed mid servo stream
    raw = RawRTDE(sim.host)
    raw.send("V", struct.pack(">H", 2))
    assert raw.recv() == ("V", b"\x01")
    raw.send("O", struct.pack(">d", 500.0) + b"timestamp,actual_q,actual_TCP_pose,target_q,")
    assert raw.recv()[1][:1] == b"\x01"
    raw.send("S")
    script = textwrap.dedent(f"""
        import math, rtde_control
        c = rtde_control.RTDEControlInterface("{sim.host}")
        q0 = {HOME.tolist()}
        print("ready", flush=True)
        k = 0
        while True:
            t = c.initPeriod()
            q = list(q0); q[0] += 0.1 * math.sin(k * 0.002)
            c.servoJ(q, 0.5, 0.5, 0.002, 0.1, 300)
            c.waitPeriod(t)
            k += 1
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(1.0)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(5)
        raw.sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        raw.close()  # reset, mid-stream
        time.sleep(0.3)
        r = rtde_receive.RTDEReceiveInterface(sim.host)
        t0 = r.getTimestamp()
        time.sleep(0.2)
        assert r.getTimestamp() > t0
        r.disconnect()
        # the vanished client's inputs are free again: a new control client takes over
        c = rtde_control.RTDEControlInterface(sim.host)
        assert c.isProgramRunning()
        assert c.moveJ(HOME.tolist(), 1.0, 4.0)
        c.stopScript()
        c.disconnect()
    finally:
        if proc.poll() is None:
            proc.kill()


def test_hosts_are_loopback_only_and_several_controllers_run_at_once(make_sim):
    with pytest.raises(ValueError, match="not a loopback address"):
        SimController("10.1.2.3")
    with pytest.raises(ValueError, match="IPv4 address"):
        SimController("localhost:30004")
    a, b = make_sim(), make_sim()
    ra, rb = rtde_receive.RTDEReceiveInterface(a.host), rtde_receive.RTDEReceiveInterface(b.host)
    try:
        assert ra.getRobotMode() == 7 and rb.getRobotMode() == 7
    finally:
        ra.disconnect()
        rb.disconnect()
    # nothing answers on an address no controller was given
    with pytest.raises(OSError):
        socket.create_connection((next_host(), 30004), timeout=1.0)


def test_no_orphan_process_when_the_parent_is_killed():
    host = next_host()
    code = f"from sim import SimController\nimport time\ns = SimController('{host}', modbus_port=None).start()\n" \
           "print(s.proc.pid, flush=True)\ntime.sleep(60)\n"
    parent = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True,
                              cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    child = int(parent.stdout.readline())
    os.kill(parent.pid, signal.SIGKILL)
    parent.wait(5)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        try:
            os.kill(child, 0)
        except ProcessLookupError:
            break
        time.sleep(0.1)
    else:
        os.kill(child, signal.SIGKILL)
        pytest.fail("the simulator outlived its parent")
