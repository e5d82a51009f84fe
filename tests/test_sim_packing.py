"""The 500 Hz packages are built from cached kinematics by compiled packers: byte for byte what a plain encoding of
the same period's state gives.

In-process, period by period through a program that moves the arm, changes the TCP offset, rests, and sets I/O and
registers: every RTDE data package (protocol versions 1 and 2, ur_rtde's receive recipe and every output of the
release, as a real connection on a socket pair receives them) and every real-time package (each release's size)
equals the field-by-field ``struct`` encoding written here, and the TCP pose, speed, acceleration and tool gravity
they carry equal the kinematics computed afresh from the joint history (the batch forward kinematics over the last
three periods, as the speed was computed before it was cached), bit for bit.
"""

from __future__ import annotations

import socket
import struct

import numpy as np
import pytest

from planner.kinematics import forward, forward_matrix
from sim import realtime_packages as rtp
from sim import rtde_protocol as rp
from sim.core import Core
from sim.io_state import IOState
from sim.motion import DT, GRAVITY
from sim.rtde_fields import OUTPUTS, Snapshot, available
from sim.rtde_server import Connection, RTDEServer
from sim.versions import parse_polyscope

# ur_rtde 1.6.5's RTDEReceiveInterface recipe (what it asks for on a 5.11 controller)
UR_RTDE_RECIPE = (
    "timestamp target_q target_qd target_qdd target_current target_moment actual_q actual_qd actual_current "
    "joint_control_output actual_TCP_pose actual_TCP_speed actual_TCP_force target_TCP_pose target_TCP_speed "
    "actual_digital_input_bits joint_temperatures actual_execution_time robot_mode joint_mode safety_mode "
    "actual_tool_accelerometer speed_scaling target_speed_fraction actual_momentum actual_main_voltage "
    "actual_robot_voltage actual_robot_current actual_joint_voltage actual_digital_output_bits runtime_state "
    "standard_analog_input0 standard_analog_input1 standard_analog_output0 standard_analog_output1 robot_status_bits "
    "safety_status_bits ft_raw_wrench payload payload_cog payload_inertia output_int_register_2 "
    "output_double_register_12 output_double_register_19").split()
EXTRA = ["actual_TCP_acceleration", "tcp_offset", "elbow_position", "actual_configurable_digital_output_bits",
         "output_bit_register_70", "tool_output_mode", "target_gravity"]

PROGRAM = """def moves():
  movej([0.1, -1.4, 1.2, -1.3, -1.5, 0.3], a=1.4, v=1.05)
  set_tcp(p[0.01, 0.02, 0.15, 0.1, 0.0, 0.2])
  movel(p[-0.45, -0.1, 0.35, 2.6, 1.7, 0.0], a=1.2, v=0.25)
  set_standard_digital_out(2, True)
  sleep(0.2)
  movej([0.0, -1.57, 1.57, -1.57, -1.57, 0.0], a=1.4, v=1.05)
end
"""
CODES = {"BOOL": "?", "UINT8": "B", "UINT32": "I", "UINT64": "Q", "INT32": "i", "DOUBLE": "d", "VECTOR3D": "3d",
         "VECTOR6D": "6d", "VECTOR6INT32": "6i"}


def plain_rtde(names, snap, recipe_id: int | None) -> bytes:
    """A data package encoded field by field from the outputs' getters."""
    body = b"" if recipe_id is None else bytes([recipe_id])
    for name in names:
        rtde_type, getter = OUTPUTS[name]
        value = getter(snap)
        body += struct.pack(">" + CODES[rtde_type], *(value if rtde_type.startswith("VECTOR") else (value,)))
    return struct.pack(">HB", 3 + len(body), rp.DATA_PACKAGE) + body


def plain_realtime(snap, size: int) -> bytes:
    """A real-time package encoded field by field from UR's field table, cut to ``size``."""
    body = b""
    for _, n, code, src in rtp.FIELDS:
        value = (0.0,) * n if src is None else OUTPUTS[src][1](snap)
        body += struct.pack(f">{n}{code}", *(value if n > 1 or src is None else (value,)))
    return struct.pack(">i", size) + body[: size - 4]


def fresh_kinematics(core: Core) -> dict:
    """Pose, speed, acceleration and tool gravity from the joint history, computed without the core's caches."""
    m = core.motion
    tcp = m.tcp if np.any(m.tcp) else None
    T = forward_matrix(m.model, np.vstack([core.q_history(k) for k in (2, 1, 0)]), tcp)
    v = (T[1:, :3, 3] - T[:-1, :3, 3]) / DT
    W = (T[1:, :3, :3] - T[:-1, :3, :3]) @ T[1:, :3, :3].transpose(0, 2, 1) / DT
    speeds = np.column_stack([v, W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]])
    return {"pose": forward(m.model, m.q, tcp), "speed": speeds[-1], "accel": (speeds[-1] - speeds[-2]) / DT,
            "gravity": forward_matrix(m.model, m.q, tcp)[:3, :3].T @ GRAVITY}


def read_all(sock: socket.socket) -> bytes:
    out = b""
    while True:
        try:
            out += sock.recv(1 << 20, socket.MSG_DONTWAIT)
        except BlockingIOError:
            return out


@pytest.mark.parametrize("polyscope", ["5.11.6", "5.4.0"])
def test_packages_equal_a_plain_encoding_of_the_periods_state(polyscope):
    version = parse_polyscope(polyscope)
    core = Core("ur5e", IOState(), version=version)
    server = RTDEServer(core, "127.0.0.1", port=0)
    every = [n for n in OUTPUTS if available(n, version)]
    recipes = {2: [[n for n in names if available(n, version)] for names in (UR_RTDE_RECIPE, EXTRA, every)],
               1: [[n for n in UR_RTDE_RECIPE if available(n, version)]]}
    ends = []
    try:
        for protocol, lists in recipes.items():
            ours, theirs = socket.socketpair()
            conn = Connection(server, ours, ("socketpair", protocol))
            server.conns.append(conn)
            ends.append((theirs, conn, lists))
            if protocol == 2:
                conn.handle(rp.REQUEST_PROTOCOL_VERSION, struct.pack(">H", 2))
            for names in lists:
                conn.handle(rp.SETUP_OUTPUTS, (struct.pack(">d", 500.0) if protocol == 2 else b"") + ",".join(
                    names).encode())
            conn.handle(rp.START, b"")
            read_all(theirs)  # the setup answers
        sizes = [size for _, size in rtp.SIZES if size <= rtp.package_size(version)]
        moved = rested = 0
        for k in range(3000):
            if k == 20:
                assert core.load_program(PROGRAM), list(core.log)
            if k == 2000:
                core.io.set_digital_in(0xFF, 0x5A)
                core.registers.out_int[2], core.registers.out_double[19] = 77, -2.5
                core.registers.out_bits |= 1 << 70
                core.message("a text message amid the data packages", "Test", 3)
            q_before = core.motion.q
            core.tick()
            moved += core.motion.q is not q_before
            rested += core.motion.q is q_before
            snap = Snapshot(core)
            messages = list(core.outbox)
            assert server.publish(1, snap) == 4
            for theirs, conn, lists in ends:
                got = read_all(theirs)
                # the period's text messages first, in the connection's protocol, then its data packages
                text = b"".join(rp.text_message(t, source, level, conn.protocol) for t, source, level in messages)
                assert got.startswith(text), f"period {k}"
                got = got[len(text):]
                want = b"".join(plain_rtde(names, Snapshot(core), len(lists) > 1 and i + 1 or None)
                                for i, names in enumerate(lists))
                assert got == want, f"period {k}, protocol {conn.protocol}"
            for size in sizes if k % 10 == 0 else sizes[-1:]:  # every period the release's own size
                assert rtp.realtime_state(snap, size) == plain_realtime(Snapshot(core), size), f"period {k}, {size}"
            if k >= 2:
                fresh = fresh_kinematics(core)
                assert np.array_equal(core.tcp_pose(), fresh["pose"]), k
                assert np.array_equal(core.tcp_speed(), fresh["speed"]), k
                assert np.array_equal(core.tcp_acceleration(), fresh["accel"]), k
                assert np.array_equal(core.tool_gravity(), fresh["gravity"]), k
        # the run covered a moving arm (after and before the TCP change) and an arm at rest
        assert moved > 1000 and rested > 300 and np.any(core.motion.tcp)
        assert core.safety_mode == 1, list(core.log)
    finally:
        server.close()
        for theirs, _, _ in ends:
            theirs.close()
