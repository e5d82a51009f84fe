"""The real-time interface (TCP 30003): a 1220-byte state package every control period, read here by a parser written
from UR's documented layout (the byte offsets below, independent of the simulator's field table), with the values
RTDE reports for the same period."""

from __future__ import annotations

import socket
import struct
import time

import numpy as np
import pytest

from planner.kinematics import forward, get_model
from tests import sim_fixtures
from tests.sim_fixtures import RawRTDE

make_sim = sim_fixtures.make_sim  # fixture

# UR's client interface documentation, real-time interface, PolyScope 5.10 and later: byte offsets (the 4-byte size
# included) of the fields read here. The earlier versions' packages end where later fields start: 1044 bytes (3.0-3.1,
# before the digital outputs), 1108 (3.5-3.9 / 5.0-5.3, before the safety status), 1140 (5.9, before the payload).
SIZE = 1220
OFFSETS = {"time": (4, 1), "q_target": (12, 6), "qd_target": (60, 6), "q_actual": (252, 6), "qd_actual": (300, 6),
           "tool_vector_actual": (444, 6), "tcp_speed_actual": (492, 6), "tool_vector_target": (588, 6),
           "motor_temperatures": (692, 6), "robot_mode": (756, 1), "joint_modes": (764, 6), "safety_mode": (812, 1),
           "tool_accelerometer": (868, 3), "speed_scaling": (940, 1), "v_robot": (980, 1), "program_state": (1052, 1),
           "elbow_position": (1060, 3), "safety_status": (1108, 1), "payload_mass": (1140, 1), "payload_cog": (1148, 3),
           "payload_inertia": (1172, 6)}
DIGITAL_INPUTS, DIGITAL_OUTPUTS = 684, 1044  # uint64 bit words


def parse(package: bytes) -> dict:
    """One real-time package as a dict of the fields above (tuples for vectors, ints for the bit words)."""
    assert struct.unpack_from(">i", package)[0] == SIZE == len(package)
    out: dict = {name: struct.unpack_from(f">{n}d", package, at) for name, (at, n) in OFFSETS.items()}
    out = {k: v[0] if len(v) == 1 else v for k, v in out.items()}
    out["digital_inputs"], out["digital_outputs"] = (struct.unpack_from(">Q", package, at)[0]
                                                     for at in (DIGITAL_INPUTS, DIGITAL_OUTPUTS))
    return out


class RealtimeClient:
    """A reader of 30003: whole packages with the wall time they arrived."""

    def __init__(self, host: str) -> None:
        self.sock = socket.create_connection((host, 30003), timeout=2.0)
        self.buf = bytearray()

    def read(self, seconds: float) -> list[tuple[float, bytes]]:
        out = []
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.sock.settimeout(max(end - time.monotonic(), 0.001))
            try:
                chunk = self.sock.recv(1 << 16)
            except TimeoutError:
                break
            if not chunk:
                raise ConnectionError("the controller hung up")
            now = time.monotonic()
            self.buf += chunk
            while len(self.buf) >= 4 and len(self.buf) >= struct.unpack_from(">i", self.buf)[0]:
                n = struct.unpack_from(">i", self.buf)[0]
                assert n == SIZE, n
                out.append((now, bytes(self.buf[:n])))
                del self.buf[:n]
        return out

    def send(self, script: str) -> None:
        self.sock.sendall(script.encode())

    def close(self) -> None:
        self.sock.close()


@pytest.mark.realtime  # rates of wall time: on their own, after the parallel run
def test_one_package_per_control_period_in_the_510_layout(make_sim):
    sim = make_sim()
    rt = RealtimeClient(sim.host)
    try:
        got = rt.read(2.2)
    finally:
        rt.close()
    pkgs = [parse(p) for _, p in got]
    stamps = np.array([p["time"] for p in pkgs])
    steps = np.diff(stamps) / 0.002
    # one package per 2 ms period, none repeated; a package skipped only if this reader fell behind
    assert np.allclose(steps, np.round(steps), atol=1e-6)
    steps = np.round(steps)
    assert steps.min() >= 1 and np.count_nonzero(steps == 1) >= 0.98 * steps.size
    arrived = np.array([t for t, _ in got])
    rate = (len(got) - 1) / (arrived[-1] - arrived[0])
    assert 450 < rate < 550, rate  # 500 Hz of wall time (the first 50 ms are held back)
    p = pkgs[-1]
    assert p["robot_mode"] == 7 and p["safety_mode"] == 1 and p["safety_status"] == 1
    assert p["joint_modes"] == (253.0,) * 6 or p["joint_modes"] == (255.0,) * 6
    assert p["speed_scaling"] == 1.0 and p["v_robot"] == 48.0 and p["motor_temperatures"] == (30.0,) * 6
    assert np.linalg.norm(p["tool_accelerometer"]) == pytest.approx(9.81, abs=1e-9)
    model = get_model("ur5e")
    pose = forward(model, np.array(p["q_actual"]))
    np.testing.assert_allclose(p["tool_vector_actual"][:3], pose[:3], atol=1e-12)


@pytest.mark.realtime  # rates of wall time: on their own, after the parallel run
def test_joints_equal_rtde_period_by_period_during_a_move(make_sim):
    """During a movej, the real-time package of each control period carries the joints, speeds and TCP pose RTDE
    sends for that period (matched by the controller's time stamp), bit for bit; outputs and payload likewise."""
    sim = make_sim()
    rtde = RawRTDE(sim.host)
    names = ["timestamp", "actual_q", "actual_qd", "actual_TCP_pose", "actual_digital_output_bits", "runtime_state",
             "payload", "payload_cog"]
    rtde.send("V", struct.pack(">H", 2))
    assert rtde.recv() == ("V", b"\x01")
    rtde.send("O", struct.pack(">d", 500.0) + ",".join(names).encode())
    assert rtde.recv() == ("O", b"\x01DOUBLE,VECTOR6D,VECTOR6D,VECTOR6D,UINT64,UINT32,DOUBLE,VECTOR3D")
    row = struct.Struct(">B d 6d 6d 6d Q I d 3d")
    rt = RealtimeClient(sim.host)
    rt.read(0.2)
    rt.send("def go():\n  set_standard_digital_out(3, True)\n"
            "  movej([0.4, -1.3, 1.5, -1.7, -1.5, 0.2], a=1.5, v=1.0)\nend\n")
    rtde.send("S")
    rows: dict[float, tuple] = {}
    pkgs: list[dict] = []
    end = time.monotonic() + 2.0
    rtde.sock.settimeout(0.02)
    while time.monotonic() < end:
        pkgs += [parse(p) for _, p in rt.read(0.02)]
        until = time.monotonic() + 0.02
        try:
            while time.monotonic() < until:
                k, p = rtde.recv(skip_data=False)
                if k == "U":
                    r = row.unpack(p)
                    rows[round(r[1], 6)] = r
        except TimeoutError:
            pass
    rt.close()
    rtde.close()
    matched = [(p, rows[round(p["time"], 6)]) for p in pkgs if round(p["time"], 6) in rows]
    assert len(matched) >= 0.9 * len(pkgs) and len(matched) > 500
    moving = 0
    for p, r in matched:
        assert p["q_actual"] == r[2:8] and p["q_target"] == r[2:8]  # the same doubles (targets follow exactly)
        assert p["qd_actual"] == r[8:14] and p["tool_vector_actual"] == r[14:20]
        assert p["digital_outputs"] == r[20] and p["program_state"] == r[21]
        assert p["payload_mass"] == r[22] and p["payload_cog"] == r[23:26]
        moving += max(abs(v) for v in p["qd_actual"]) > 0.1
    assert moving > 100  # seen moving
    assert any(p["digital_outputs"] == 1 << 3 for p, _ in matched)
    assert any(p["program_state"] == 2 for p, _ in matched)  # RTDE's runtime_state PLAYING


@pytest.mark.realtime  # rates of wall time: on their own, after the parallel run
def test_a_client_that_never_reads_is_kept_and_does_not_hold_up_the_others(make_sim):
    """ur_rtde keeps 30003 open to upload its control script and never reads it: its packages are skipped, it is
    not hung up on, a program it sends later still runs, and a reading client meanwhile gets every period."""
    sim = make_sim()
    idle = socket.create_connection((sim.host, 30003))
    idle.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    try:
        time.sleep(3.0)  # ~3.7 MB of packages sent meanwhile: far beyond what the sockets hold
        rt = RealtimeClient(sim.host)
        try:
            got = [parse(p) for _, p in rt.read(1.0)]
            steps = np.round(np.diff([p["time"] for p in got]) / 0.002)
            assert len(got) > 400 and np.count_nonzero(steps == 1) >= 0.98 * steps.size
            idle.sendall(b"set_standard_digital_out(5, True)\n")
            deadline = time.monotonic() + 3.0
            while time.monotonic() < deadline:
                got = rt.read(0.1)
                if got and parse(got[-1][1])["digital_outputs"] >> 5 & 1:
                    break
            else:
                pytest.fail("a program sent on the connection that never read did not run")
        finally:
            rt.close()
    finally:
        idle.close()


@pytest.mark.parametrize("name", ["ur3e", "ur5e", "ur10e", "ur16e", "ur20"])
def test_the_elbow_position_sent_every_period_is_the_link_frames_one(name):
    """The elbow position (real-time and RTDE outputs) in closed form equals the kinematics' link frame 3."""
    from planner.kinematics import link_frames
    from sim.core import _link3_origin

    model = get_model(name)
    for q in np.random.default_rng(7).uniform(-2 * np.pi, 2 * np.pi, (300, 6)):
        np.testing.assert_allclose(_link3_origin(model, q), link_frames(model, q)[3][:3, 3], rtol=0, atol=1e-15)
