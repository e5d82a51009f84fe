"""The primary (30001) and secondary (30002) client interfaces, read with a decoder written here from UR's
documented e-Series 5.x layout (not the simulator's tables): the version message first, robot state packages at
10 Hz with every sub-package at its documented size, values that agree with RTDE's, the robot messages (program
started / stopped, runtime and compile errors, protective stops) and the primary commands UR's clients send."""

from __future__ import annotations

import math
import socket
import struct
import time

import numpy as np
import pytest

from planner.kinematics import get_model
from tests import sim_fixtures
from tests.sim_fixtures import RawRTDE, eventually

make_sim = sim_fixtures.make_sim  # fixture

# UR's client interface, e-Series 5.x: payload layouts of the robot state sub-packages (after size + type)
STATE_LAYOUT = {
    0: ">Q???????BBdddB",  # robot mode data
    1: ">" + "dddffffB" * 6,  # joint data, per joint
    2: ">BBddfBffB",  # tool data
    3: ">iiBBddBBddffffBBBIBBB",  # masterboard data (no euromap67)
    4: ">12d",  # cartesian info
    5: ">6I24dI",  # kinematics info
    6: ">12d12d5d24d4i",  # configuration data
    7: ">7d",  # force mode data
    8: ">B??B",  # additional info
    9: ">6d",  # calibration data
    10: ">IBB4d",  # safety data
    11: ">?IIIff",  # tool communication info
    12: ">BBB",  # tool mode info
}
# sizes of the sub-packages (headers included) in a URSim 5.8 robot state package, and its order
DOCUMENTED_SIZES = {0: 47, 1: 251, 4: 101, 5: 225, 9: 53, 3: 75, 2: 37, 6: 445, 7: 61, 8: 9, 10: 43, 11: 26, 12: 8}


def _packages(sock: socket.socket, seconds: float, buf: bytearray | None = None) -> list[tuple[float, int, bytes]]:
    """(arrival time, type, whole package) of every package received within ``seconds``."""
    buf = bytearray() if buf is None else buf
    out = []
    end = time.monotonic() + seconds
    sock.settimeout(0.05)
    while time.monotonic() < end:
        try:
            chunk = sock.recv(65536)
        except TimeoutError:
            continue
        if not chunk:
            raise ConnectionError("the controller hung up")
        now = time.monotonic()
        buf += chunk
        while len(buf) >= 5:
            size, kind = struct.unpack_from(">iB", buf)
            assert size >= 5, size
            if len(buf) < size:
                break
            out.append((now, kind, bytes(buf[:size])))
            del buf[:size]
    return out


def _decode_state(pkg: bytes) -> tuple[list[int], dict[int, tuple]]:
    """Sub-package types in order, and each one's fields."""
    size, kind = struct.unpack_from(">iB", pkg)
    assert kind == 16 and size == len(pkg)
    order, fields = [], {}
    off = 5
    while off < size:
        sub, t = struct.unpack_from(">IB", pkg, off)
        layout = struct.Struct(STATE_LAYOUT[t])
        assert sub == 5 + layout.size, (t, sub, layout.size)
        fields[t] = layout.unpack_from(pkg, off + 5)
        order.append(t)
        off += sub
    assert off == size
    return order, fields


def _message(pkg: bytes) -> tuple[int, int, int, bytes]:
    """A robot message's timestamp (us), source, type and payload."""
    size, kind = struct.unpack_from(">iB", pkg)
    assert kind == 20 and size == len(pkg)
    ts, source, mtype = struct.unpack_from(">QbB", pkg, 5)
    return ts, source, mtype, pkg[15:]


def _connect(host: str, port: int) -> socket.socket:
    return socket.create_connection((host, port), timeout=3)


def _messages(pkgs, mtype: int) -> list[bytes]:
    return [_message(p)[3] for _, k, p in pkgs if k == 20 and _message(p)[2] == mtype]


def test_version_message_then_robot_state_at_10_hz(make_sim):
    sim = make_sim()
    for port in (30001, 30002):
        with _connect(sim.host, port) as s:
            pkgs = _packages(s, 3.6)
        # the version message comes first: URControl 5.11.6.108949 and its build date
        first = pkgs[0]
        assert first[1] == 20
        _, _, mtype, payload = _message(first[2])
        assert mtype == 3
        n = payload[0]
        assert payload[1 : 1 + n] == b"URControl"
        major, minor, bugfix, build = struct.unpack_from(">BBii", payload, 1 + n)
        assert (major, minor, bugfix, build) == (5, 11, 6, 108949)
        assert payload[1 + n + 10 :].decode() == "27-07-2021, 12:00:00"
        states = [(t, p) for t, k, p in pkgs if k == 16]
        # 10 Hz: 30 packages in 3 s (a loaded machine may delay one, never add one)
        t0 = states[0][0]
        window = [t for t, _ in states if 0.25 <= t - t0 < 3.25]
        assert 28 <= len(window) <= 31, len(window)
        # robot state packages: 1386 bytes of 13 sub-packages at their documented sizes, in URSim's order
        for _, p in states:
            order, fields = _decode_state(p)
            assert len(p) == 1386
            assert order == list(DOCUMENTED_SIZES)
        stamps = np.array([_decode_state(p)[1][0][0] for _, p in states]) * 1e-6
        assert np.median(np.diff(stamps)) == pytest.approx(0.1, abs=0.004)


def test_joint_and_cartesian_values_are_the_ones_rtde_reports(make_sim):
    sim = make_sim(model="ur10e")
    model = get_model("ur10e")
    rtde = RawRTDE(sim.host)
    names = ["timestamp", "actual_q", "actual_qd", "actual_TCP_pose", "robot_mode", "safety_mode", "runtime_state"]
    rtde.send("V", struct.pack(">H", 2))
    assert rtde.recv() == ("V", b"\x01")
    rtde.send("O", struct.pack(">d", 500.0) + ",".join(names).encode())
    kind, payload = rtde.recv()
    assert payload[1:].decode() == "DOUBLE,VECTOR6D,VECTOR6D,VECTOR6D,INT32,INT32,UINT32"
    row = struct.Struct(">B d 6d 6d 6d i i I")
    with _connect(sim.host, 30001) as s:
        _packages(s, 0.3)
        s.sendall(b"def go():\n  set_tcp(p[0, 0, 0.1, 0, 0, 0])\n"
                  b"  movej([0.5, -1.2, 1.4, -1.6, -1.5, 0.3], a=1.0, v=0.8)\nend\n")
        rtde.send("S")
        rtde_rows = {}
        primary = []
        end = time.monotonic() + 2.5
        while time.monotonic() < end:
            primary += _packages(s, 0.05)
            rtde.sock.settimeout(0.05)
            until = time.monotonic() + 0.05
            try:
                while time.monotonic() < until:
                    k, p = rtde.recv(skip_data=False)
                    if k == "U":
                        r = row.unpack(p)
                        rtde_rows[round(r[1], 6)] = r
            except TimeoutError:
                pass
    rtde.close()
    states = [_decode_state(p)[1] for _, k, p in primary if k == 16]
    matched = 0
    for f in states:
        t = round(f[0][0] * 1e-6, 6)
        if t not in rtde_rows:
            continue
        matched += 1
        r = rtde_rows[t]
        joints = f[1]
        q = [joints[8 * j] for j in range(6)]
        qd = [joints[8 * j + 2] for j in range(6)]
        np.testing.assert_array_equal(q, r[2:8])  # the same doubles, bit for bit
        np.testing.assert_array_equal(qd, r[8:14])
        np.testing.assert_array_equal(f[4][:6], r[14:20])
        np.testing.assert_allclose(f[4][6:], [0, 0, 0.1, 0, 0, 0], atol=1e-15)  # the TCP offset set_tcp set
        assert f[0][8] == r[20] == 7  # robot mode RUNNING
        assert f[3][14] == r[21] == 1  # masterboard safety mode NORMAL
        assert f[0][6] == (r[22] == 2)  # program running
        assert all(joints[8 * j + 7] == 253 for j in range(6))  # joint mode RUNNING
    assert matched >= 15
    assert any(f[0][6] for f in states) and any(abs(f[1][2]) > 0.1 for f in states)  # seen moving, program running
    # kinematics and configuration: the model's DH parameters and limits, UR's robot type id of a UR10
    kin, conf = states[-1][5], states[-1][6]
    assert kin[6:12] == (0.0,) * 6
    np.testing.assert_allclose(kin[12:18], [0, model.a2, model.a3, 0, 0, 0])
    np.testing.assert_allclose(kin[18:24], [model.d1, 0, 0, model.d4, model.d5, model.d6])
    np.testing.assert_allclose(kin[24:30], [math.pi / 2, 0, 0, math.pi / 2, -math.pi / 2, 0])
    np.testing.assert_allclose(conf[0:12:2], model.q_min)
    np.testing.assert_allclose(conf[1:12:2], model.q_max)
    np.testing.assert_allclose(conf[12:24:2], model.qd_max)
    np.testing.assert_allclose(conf[29:35], kin[12:18])
    assert conf[-2] == 2  # robot type UR10


def test_program_messages_and_io_on_the_primary_interface_only(make_sim):
    sim = make_sim()
    with _connect(sim.host, 30001) as p, _connect(sim.host, 30002) as sec:
        _packages(p, 0.2)
        _packages(sec, 0.2)
        p.sendall(b'def blink():\n  set_standard_digital_out(2, True)\n  textmsg("lit")\nend\n')
        got = _packages(p, 0.4)
        # a second program replaces the first; this one does not compile
        p.sendall(b"def broken():\n  movej([0, 0, 0, 0, 0, 0], a=1, v=1)\n  no_such_call(1)\nend\n")
        got += _packages(p, 0.4)
        got_sec = _packages(sec, 0.6)
    keys = []
    for payload in _messages(got, 7):
        code, arg, n = struct.unpack_from(">iiB", payload)
        keys.append((payload[9 : 9 + n].decode(), payload[9 + n :].decode()))
    assert keys == [("PROGRAM_XXX_STARTED", "blink"), ("PROGRAM_XXX_STOPPED", "blink")]
    assert b"lit" in _messages(got, 0)
    (exc,) = _messages(got, 10)
    line, column = struct.unpack_from(">II", exc)
    assert line == 3 and b"no_such_call" in exc[8:]
    # the secondary interface: robot state only
    assert {k for _, k, _ in got_sec} == {16}
    out_bits = _decode_state([q for _, k, q in got if k == 16][-1])[1][3][1]
    assert out_bits == 1 << 2


def test_primary_commands_power_brakes_and_protective_stop(make_sim):
    sim = make_sim(speed=5.0)  # the protective stop's 5 s unlock delay in 1 s
    with _connect(sim.host, 30001) as s:
        def robot_mode_data():
            return _decode_state([q for _, k, q in _packages(s, 0.25) if k == 16][-1])[1][0]

        s.sendall(b"power off\n")
        assert eventually(lambda: robot_mode_data()[8] == 3)  # POWER_OFF
        assert robot_mode_data()[3] is False  # power off
        s.sendall(b"power on\n")
        assert eventually(lambda: robot_mode_data()[8] == 5)  # IDLE
        s.sendall(b"set robotmode run\n")
        assert eventually(lambda: robot_mode_data()[8] == 7)  # RUNNING
        # a joint target beyond its limit: a protective stop, announced by a safety mode and an error code message
        s.sendall(b"def far():\n  movej([0, -1.57, 1.57, -1.57, -1.57, 7.0], a=1, v=1)\nend\n")
        got = _packages(s, 0.5)
        assert robot_mode_data()[5] is True  # protective stopped
        modes = [struct.unpack_from(">iiB", m)[2] for m in _messages(got, 5)]
        assert modes == [3]
        (err,) = _messages(got, 6)
        code, arg, level = struct.unpack_from(">iii", err)
        assert level == 3 and b"Protective stop" in err[20:]
        time.sleep(1.2)
        s.sendall(b"set unlock protective stop\n")
        assert eventually(lambda: robot_mode_data()[5] is False)
        assert sim.state()["safety_mode"] == "NORMAL"


def test_local_control_makes_the_primary_interface_read_only(make_sim):
    sim = make_sim(remote_control=False)
    with _connect(sim.host, 30001) as s:
        _packages(s, 0.2)
        s.sendall(b"power off\n")
        s.sendall(b"def go():\n  textmsg(1)\nend\n")
        got = _packages(s, 0.6)
    codes = [struct.unpack_from(">iii", m) for m in _messages(got, 6)]
    assert [c for c, _, _ in codes] == [210, 210]
    assert sim.state()["robot_mode"] == "RUNNING" and sim.state()["program"] is None


def test_clients_that_vanish_leave_the_stream_to_the_others(make_sim):
    """Clients that hang up at once, mid-package or mid-program do not disturb a client that stays."""
    sim = make_sim()
    with _connect(sim.host, 30002) as stay:
        _packages(stay, 0.2)
        for i in range(20):
            c = _connect(sim.host, 30001 if i % 2 else 30002)
            if i % 3 == 0:
                c.sendall(b"def half():\n  textmsg(")  # a program cut off by the hang-up: never runs
            if i % 4 == 0:
                c.recv(7)
            c.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))  # reset, not FIN
            c.close()
        _packages(stay, 0.3)  # what queued up meanwhile
        got = _packages(stay, 1.05)
    assert 9 <= sum(1 for _, k, _ in got if k == 16) <= 11
    assert sim.state()["program"] is None
    assert all(t != "half" for _, _, t in sim.state()["log"])


def test_one_line_programs_as_python_urx_sends_them(make_sim):
    """python-urx sends every command as one URScript line (``movej([...], a=.., v=..)``) on 30002."""
    sim = make_sim()
    target = [0.1, -1.5, 1.4, -1.5, -1.5, 0.2]
    with _connect(sim.host, 30002) as s:
        s.sendall(f"movej({target}, a=1.0, v=1.0)\n".encode())
        assert eventually(lambda: np.allclose(sim.state()["q"], target, atol=1e-12), timeout=5.0)
    with _connect(sim.host, 30001) as p:
        _packages(p, 0.2)
        p.sendall(b"no_such_function(1)\n")
        got = _packages(p, 0.4)
    (exc,) = _messages(got, 10)
    assert struct.unpack_from(">II", exc) == (1, 0) and b"no_such_function" in exc[8:]


def test_a_program_sent_by_a_client_that_hangs_up_at_once_runs(make_sim):
    """A client that connects, sends a long program and closes without reading (this project's UR driver does) must
    not lose the program's end: closing with the version message unread would reset the connection."""
    sim = make_sim()
    body = "".join(f"  x{k} = {k}\n" for k in range(13000))  # about 190 kB (within the 250 kB a program may have)
    for i in range(3):
        with _connect(sim.host, 30002) as s:
            s.sendall(f'def long_{i}():\n{body}  textmsg("done {i}")\nend\n'.encode())
        assert eventually(lambda i=i: any(m[2] == f"done {i}" for m in sim.state()["log"]), timeout=5.0)
