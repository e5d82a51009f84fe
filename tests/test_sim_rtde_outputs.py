"""Every RTDE output and input of UR's RTDE guide, as UR's own clients ask for them, on raw sockets.

The name and type table below is the RTDE guide's (as Universal Robots' C++ client library lists it in
``src/rtde/data_package.cpp``): a recipe holding any of them must be accepted with these types by a controller of a
release that has them (`GUIDE_SINCE`), refused with ``NOT_FOUND`` by an older one, and the values must be the
controller's where the simulator has them. UR's RTDE Python client (``record.py``) is not published on
the package registries, so its handshake and recording are checked here at the byte level: protocol version 2,
controller version, an output recipe at the asked frequency, start, data packages, pause.
"""

from __future__ import annotations

import socket
import struct
import time

import numpy as np
import pytest

from tests import sim_fixtures
from tests.sim_fixtures import RawRTDE, eventually

make_sim = sim_fixtures.make_sim  # fixture

# the RTDE guide's outputs (registers below), name:TYPE
GUIDE_OUTPUTS = dict(item.split(":") for item in """
timestamp:DOUBLE target_q:VECTOR6D target_qd:VECTOR6D target_qdd:VECTOR6D target_current:VECTOR6D
target_moment:VECTOR6D actual_q:VECTOR6D actual_qd:VECTOR6D actual_current:VECTOR6D actual_current_window:VECTOR6D
actual_current_as_torque:VECTOR6D joint_control_output:VECTOR6D actual_TCP_pose:VECTOR6D actual_TCP_speed:VECTOR6D
actual_TCP_force:VECTOR6D target_TCP_pose:VECTOR6D target_TCP_speed:VECTOR6D tcp_offset:VECTOR6D
actual_TCP_acceleration:VECTOR6D target_TCP_acceleration:VECTOR6D actual_digital_input_bits:UINT64
actual_configurable_digital_input_bits:UINT64 joint_temperatures:VECTOR6D actual_execution_time:DOUBLE
target_execution_time:DOUBLE robot_mode:INT32 joint_mode:VECTOR6INT32 safety_mode:INT32 safety_status:INT32
actual_tool_accelerometer:VECTOR3D speed_scaling:DOUBLE target_speed_fraction:DOUBLE actual_momentum:DOUBLE
actual_main_voltage:DOUBLE actual_robot_voltage:DOUBLE actual_robot_current:DOUBLE actual_joint_voltage:VECTOR6D
actual_digital_output_bits:UINT64 actual_configurable_digital_output_bits:UINT64 runtime_state:UINT32
elbow_position:VECTOR3D elbow_velocity:VECTOR3D robot_status_bits:UINT32 safety_status_bits:UINT32
analog_io_types:UINT32 standard_analog_input0:DOUBLE standard_analog_input1:DOUBLE standard_analog_output0:DOUBLE
standard_analog_output1:DOUBLE io_current:DOUBLE actual_robot_energy_consumed:DOUBLE
actual_robot_braking_energy_dissipated:DOUBLE encoder0_raw:INT32 encoder1_raw:INT32 euromap67_input_bits:UINT32
euromap67_output_bits:UINT32 euromap67_24V_voltage:DOUBLE euromap67_24V_current:DOUBLE tool_mode:UINT32
tool_analog_input_types:UINT32 tool_analog_input0:DOUBLE tool_analog_input1:DOUBLE tool_output_voltage:INT32
tool_output_current:DOUBLE tool_temperature:DOUBLE tool_output_mode:UINT8 tool_digital_output0_mode:UINT8
tool_digital_output1_mode:UINT8 tcp_force_scalar:DOUBLE joint_position_deviation_ratio:DOUBLE
collision_detection_ratio:DOUBLE ft_raw_wrench:VECTOR6D wrench_calc_from_currents:VECTOR6D payload:DOUBLE
payload_cog:VECTOR3D payload_inertia:VECTOR6D script_control_line:UINT32 time_scale_source:INT32
target_gravity:VECTOR3D target_base_acceleration:VECTOR6D control_step:UINT64 target_base_wrench:VECTOR6D
""".split())
GUIDE_INPUTS = dict(item.split(":") for item in """
speed_slider_mask:UINT32 speed_slider_fraction:DOUBLE standard_digital_output_mask:UINT8
standard_digital_output:UINT8 configurable_digital_output_mask:UINT8 configurable_digital_output:UINT8
tool_digital_output_mask:UINT8 tool_digital_output:UINT8 standard_analog_output_mask:UINT8
standard_analog_output_type:UINT8 standard_analog_output_0:DOUBLE standard_analog_output_1:DOUBLE
external_force_torque:VECTOR6D input_bit_registers0_to_31:UINT32 input_bit_registers32_to_63:UINT32
""".split())
for _i in range(48):
    for _io in ("input", "output"):
        GUIDE_OUTPUTS[f"{_io}_int_register_{_i}"] = "INT32"
        GUIDE_OUTPUTS[f"{_io}_double_register_{_i}"] = "DOUBLE"
    GUIDE_INPUTS[f"input_int_register_{_i}"] = "INT32"
    GUIDE_INPUTS[f"input_double_register_{_i}"] = "DOUBLE"
for _i in range(64, 128):
    GUIDE_OUTPUTS[f"input_bit_register_{_i}"] = GUIDE_OUTPUTS[f"output_bit_register_{_i}"] = "BOOL"
    GUIDE_INPUTS[f"input_bit_register_{_i}"] = "BOOL"
for _w in ("0_to_31", "32_to_63"):
    GUIDE_OUTPUTS[f"input_bit_registers{_w}"] = GUIDE_OUTPUTS[f"output_bit_registers{_w}"] = "UINT32"

# the PolyScope 5 release that introduced each field newer than 5.0.0 (UR's RTDE guide's "introduced in" column as
# UR's C++ client library's tests and the commits adding fields record it; ur_rtde 1.6.5's version checks)
GUIDE_SINCE = {"safety_status": (5, 4, 0), "payload": (5, 5, 1), "payload_cog": (5, 5, 1), "tcp_offset": (5, 5, 1),
               "ft_raw_wrench": (5, 9, 0), "payload_inertia": (5, 11, 0), "collision_detection_ratio": (5, 15, 0),
               "time_scale_source": (5, 17, 0), "actual_current_as_torque": (5, 23, 0),
               "target_gravity": (5, 26, 0), "target_base_acceleration": (5, 26, 0), "control_step": (5, 26, 0),
               "target_base_wrench": (5, 26, 0)}
for _i in range(24, 48):
    for _io in ("input", "output"):
        GUIDE_SINCE[f"{_io}_int_register_{_i}"] = GUIDE_SINCE[f"{_io}_double_register_{_i}"] = (5, 3, 0)
for _i in range(64, 128):
    GUIDE_SINCE[f"input_bit_register_{_i}"] = GUIDE_SINCE[f"output_bit_register_{_i}"] = (5, 3, 0)
#: The release that has every field.
NEWEST = "5.26.0"


def _newer(names, release: tuple[int, int, int]) -> list[str]:
    """The names of ``names`` a controller of ``release`` does not have yet."""
    return [n for n in names if GUIDE_SINCE.get(n, (5, 0, 0)) > release]

# the guide's binary layout of each type (big-endian)
LAYOUT = {"BOOL": "?", "UINT8": "B", "UINT32": "I", "UINT64": "Q", "INT32": "i", "DOUBLE": "d", "VECTOR3D": "3d",
          "VECTOR6D": "6d", "VECTOR6INT32": "6i", "VECTOR6UINT32": "6I"}
WIDTH = {"VECTOR3D": 3, "VECTOR6D": 6, "VECTOR6INT32": 6, "VECTOR6UINT32": 6}


def _chunks(names: list[str], limit: int = 2000) -> list[list[str]]:
    """Name lists of at most ``limit`` bytes each (the guide caps a recipe's name list at 2048 bytes)."""
    out: list[list[str]] = [[]]
    for n in names:
        if len(",".join(out[-1] + [n])) > limit:
            out.append([])
        out[-1].append(n)
    return out


def _handshake(raw: RawRTDE) -> tuple[int, ...]:
    raw.send("V", struct.pack(">H", 2))
    kind, payload = raw.recv()
    assert kind == "V" and payload == b"\x01"
    raw.send("v")
    kind, payload = raw.recv()
    assert kind == "v" and len(payload) == 16
    return struct.unpack(">IIII", payload)


def _setup_outputs(raw: RawRTDE, names: list[str], frequency: float) -> tuple[int, list[str]]:
    raw.send("O", struct.pack(">d", frequency) + ",".join(names).encode())
    kind, payload = raw.recv()
    assert kind == "O"
    return payload[0], payload[1:].decode().split(",")


def _decode(types: list[str], body: bytes) -> list:
    """A data package's fields (after the recipe id) by the guide's layout; vectors as tuples."""
    layout = struct.Struct(">" + "".join(LAYOUT[t] for t in types))
    assert len(body) == layout.size, (len(body), layout.size)
    flat = layout.unpack(body)
    out, i = [], 0
    for t in types:
        w = WIDTH.get(t, 1)
        out.append(flat[i] if w == 1 else tuple(flat[i : i + w]))
        i += w
    return out


def _packages(raw: RawRTDE, n: int) -> list[tuple[int, bytes]]:
    """The next ``n`` data packages (recipe id, body), skipping text messages."""
    out = []
    while len(out) < n:
        kind, payload = raw.recv(skip_data=False)
        if kind == "U":
            out.append((payload[0], payload[1:]))
    return out


@pytest.mark.parametrize("polyscope", [NEWEST, "5.11.6", "5.4.0", "5.0.0"])
def test_every_output_and_input_of_the_guide_is_served_with_its_type_from_its_release(make_sim, polyscope):
    """A controller of each release serves the guide's fields of that release with their types; a recipe naming a
    newer one is refused (recipe id 0) with NOT_FOUND at exactly those names, as for an unknown name."""
    release = tuple(int(x) for x in polyscope.split("."))
    sim = make_sim(polyscope=polyscope)
    raw = RawRTDE(sim.host)
    try:
        assert _handshake(raw)[:3] == release
        newer_out, newer_in = _newer(GUIDE_OUTPUTS, release), _newer(GUIDE_INPUTS, release)
        if polyscope == NEWEST:
            assert newer_out == newer_in == []
        if polyscope == "5.11.6":  # the default: these seven came after 5.11
            assert sorted(newer_out) == ["actual_current_as_torque", "collision_detection_ratio", "control_step",
                                         "target_base_acceleration", "target_base_wrench", "target_gravity",
                                         "time_scale_source"]
        if polyscope == "5.0.0":  # the upper registers (5.3) too
            assert "output_double_register_47" in newer_out and "input_bit_register_64" in newer_in
        for chunk in _chunks(newer_out, 1900) if newer_out else []:
            rid, types = _setup_outputs(raw, ["timestamp", *chunk, "actual_q"], 125.0)
            assert rid == 0
            assert types == ["DOUBLE"] + ["NOT_FOUND"] * len(chunk) + ["VECTOR6D"]
        for chunk in _chunks(newer_in, 1900) if newer_in else []:
            raw.send("I", ",".join(["speed_slider_mask", *chunk]).encode())
            kind, payload = raw.recv()
            assert kind == "I" and payload[0] == 0
            assert payload[1:].decode().split(",") == ["UINT32"] + ["NOT_FOUND"] * len(chunk)
        served_out = {n: t for n, t in GUIDE_OUTPUTS.items() if n not in newer_out}
        served_in = {n: t for n, t in GUIDE_INPUTS.items() if n not in newer_in}
        names = sorted(served_out)
        recipes = []
        for chunk in _chunks(names):
            rid, types = _setup_outputs(raw, chunk, 125.0)
            assert "NOT_FOUND" not in types, [n for n, t in zip(chunk, types, strict=True) if t == "NOT_FOUND"]
            assert types == [GUIDE_OUTPUTS[n] for n in chunk]
            assert rid == len(recipes) + 1  # a refused recipe takes no id
            recipes.append((rid, chunk, types))
        for chunk in _chunks(sorted(served_in)):
            raw.send("I", ",".join(chunk).encode())
            kind, payload = raw.recv()
            assert kind == "I" and payload[0] > 0
            assert payload[1:].decode().split(",") == [GUIDE_INPUTS[n] for n in chunk]
        raw.send("S")
        assert raw.recv() == ("S", b"\x01")
        # one package of every recipe, each exactly as long as the guide's layout of its types
        seen = {}
        for rid, body in _packages(raw, 3 * len(recipes)):
            _, chunk, types = recipes[rid - 1]
            seen[rid] = dict(zip(chunk, _decode(types, body), strict=True))
        values = {k: v for d in seen.values() for k, v in d.items()}
        assert set(values) == set(served_out)
        for name, t in served_out.items():  # finite numbers everywhere
            v = values[name]
            assert np.isfinite(np.asarray(v, dtype=float)).all(), (name, t, v)
    finally:
        raw.close()


def _send_program(host: str, text: str) -> None:
    with socket.create_connection((host, 30002)) as s:
        s.sendall(text.encode())


NEW_OUTPUTS = ["timestamp", "control_step", "tcp_offset", "actual_configurable_digital_input_bits",
               "actual_configurable_digital_output_bits", "actual_digital_output_bits", "target_gravity",
               "encoder0_raw", "encoder1_raw", "target_execution_time", "actual_current_as_torque",
               "actual_robot_energy_consumed", "wrench_calc_from_currents", "target_base_wrench", "actual_TCP_pose",
               "actual_TCP_speed", "actual_TCP_acceleration", "target_TCP_acceleration", "runtime_state"]


def test_the_outputs_new_to_the_simulator_carry_the_controllers_values(make_sim):
    sim = make_sim(polyscope=NEWEST)
    tcp = [0.01, -0.02, 0.15, 0.0, 0.0, 0.3]
    pose = ", ".join(map(str, tcp))
    _send_program(sim.host, f"def tool():\n  set_tcp(p[{pose}])\n  set_configurable_digital_out(3, True)\nend\n")
    assert eventually(lambda: sim.state()["digital_out"] == 1 << 11)
    sim.set_digital_in(0xFF00, 0xA500)
    raw = RawRTDE(sim.host)
    try:
        _handshake(raw)
        rid, types = _setup_outputs(raw, NEW_OUTPUTS, 500.0)
        raw.send("S")
        assert raw.recv() == ("S", b"\x01")
        rows = [dict(zip(NEW_OUTPUTS, _decode(types, body), strict=True)) for _, body in _packages(raw, 50)]
    finally:
        raw.close()
    steps = np.array([r["control_step"] for r in rows])
    stamps = np.array([r["timestamp"] for r in rows])
    # control_step counts the 2 ms periods: one per package at 500 Hz, and the timestamp is steps * 2 ms
    assert np.all(np.diff(steps) >= 1) and np.median(np.diff(steps)) == 1
    np.testing.assert_allclose(stamps, steps * 0.002, atol=1e-9)
    last = rows[-1]
    np.testing.assert_allclose(last["tcp_offset"], tcp, atol=1e-12)
    assert last["actual_configurable_digital_input_bits"] == 0xA5
    assert last["actual_configurable_digital_output_bits"] == 1 << 3
    assert last["actual_digital_output_bits"] == 1 << 11
    assert last["target_gravity"] == pytest.approx((0.0, 0.0, -9.81))
    assert last["encoder0_raw"] == last["encoder1_raw"] == 0
    assert last["target_execution_time"] == pytest.approx(2.0)
    for name in ("actual_current_as_torque", "wrench_calc_from_currents", "target_base_wrench"):
        assert last[name] == (0.0,) * 6
    assert last["actual_robot_energy_consumed"] == 0.0


def test_tcp_acceleration_is_the_change_of_the_tcp_speed(make_sim):
    sim = make_sim(polyscope=NEWEST)
    raw = RawRTDE(sim.host)
    try:
        _handshake(raw)
        rid, types = _setup_outputs(raw, NEW_OUTPUTS, 500.0)
        raw.send("S")
        assert raw.recv() == ("S", b"\x01")
        _packages(raw, 5)
        _send_program(sim.host, "def go():\n  movel(p[-0.4, -0.3, 0.4, 0, 3.1416, 0], a=1.2, v=0.25)\nend\n")
        rows = [dict(zip(NEW_OUTPUTS, _decode(types, body), strict=True)) for _, body in _packages(raw, 1500)]
    finally:
        raw.close()
    stamps = np.array([r["timestamp"] for r in rows])
    speed = np.array([r["actual_TCP_speed"] for r in rows])
    acc = np.array([r["actual_TCP_acceleration"] for r in rows])
    assert np.array_equal(acc, np.array([r["target_TCP_acceleration"] for r in rows]))
    # consecutive packages one period apart: the acceleration is the difference of the speeds over 2 ms
    k = np.flatnonzero(np.isclose(np.diff(stamps), 0.002))
    assert len(k) > 1000
    np.testing.assert_allclose(acc[k + 1], (speed[k + 1] - speed[k]) / 0.002, atol=1e-6)
    # the move accelerates at the programmed 1.2 m/s^2 (the time law's linear acceleration)
    lin = np.linalg.norm(acc[:, :3], axis=1)
    assert 1.1 < np.percentile(lin, 99) < 1.3
    assert np.linalg.norm(speed[:, :3], axis=1).max() == pytest.approx(0.25, rel=1e-3)


def test_record_py_handshake_records_n_samples_at_the_rate_asked(make_sim):
    """UR's RTDE client's record.py: protocol 2, controller version, its default recipe (record_configuration.xml)
    at --frequency 125, start, N samples, pause: N packages, 8 ms apart on the controller's clock."""
    sim = make_sim()
    recipe = ("timestamp target_q target_qd target_qdd target_current target_moment actual_q actual_qd actual_current "
              "joint_control_output actual_TCP_pose actual_TCP_speed actual_TCP_force target_TCP_pose target_TCP_speed "
              "actual_digital_input_bits joint_temperatures actual_execution_time robot_mode joint_mode safety_status "
              "actual_tool_accelerometer speed_scaling target_speed_fraction actual_momentum actual_main_voltage "
              "actual_robot_voltage actual_robot_current actual_joint_voltage actual_digital_output_bits runtime_state "
              "joint_position_deviation_ratio").split()
    raw = RawRTDE(sim.host)
    try:
        major, minor, bugfix, build = _handshake(raw)
        assert (major, minor) == (5, 11) and build > 19171
        rid, types = _setup_outputs(raw, recipe, 125.0)
        assert rid == 1 and types == [GUIDE_OUTPUTS[n] for n in recipe]
        raw.send("S")
        assert raw.recv() == ("S", b"\x01")
        t0 = time.monotonic()
        rows = [_decode(types, body) for _, body in _packages(raw, 250)]
        wall = time.monotonic() - t0
        raw.send("P")
        kind, payload = raw.recv()
        assert (kind, payload) == ("P", b"\x01")
        # paused: no data package follows
        raw.sock.settimeout(0.3)
        with pytest.raises(TimeoutError):
            while True:
                raw.recv(skip_data=False)
    finally:
        raw.close()
    stamps = np.array([r[0] for r in rows])
    assert np.median(np.diff(stamps)) == pytest.approx(0.008)
    assert np.diff(stamps).min() >= 0.008 - 1e-9
    assert wall < 250 * 0.008 * 3  # 2 s of recording (a loaded machine delays packages, never drops them)
