"""RTDE variable names the simulated controller serves: their types and where their values come from.

Names and types follow Universal Robots' RTDE guide (the table in Universal Robots' C++ client library,
``src/rtde/data_package.cpp``, and ur_rtde 1.6.5's ``src/robot_state.cpp``): every output and input name
that table knows is served, from the PolyScope release that introduced it (`INTRODUCED`): a field newer than the
controller's version answers ``NOT_FOUND``, as an unknown name does. Variables the simulator has no physics for
(currents, torques, forces, energy, encoders, temperatures) are served with constant values, listed in
`CONSTANT_OUTPUTS`: zeros for what it models nothing of, plausible constants for supply voltages and temperatures.

Outputs read a :class:`Snapshot` of the controller taken once per data package; inputs are applied by
the RTDE server (``sim.rtde_server``) through the controller's register file and I/O state.
"""

from __future__ import annotations

import struct
from collections.abc import Callable

import numpy as np

from planner.kinematics.ur_outputs import UR_OUTPUTS
from sim.motion import DT, GRAVITY
from sim.rtde_protocol import TYPE_WIDTH

N_REGISTERS = 48  # int and double registers 0..47 (24..47 from PolyScope 5.3: `INTRODUCED`)
BIT_REGISTERS = range(64, 128)  # general-purpose bit registers (the guide's X in [64..127])
_CONFIGURABLE = UR_OUTPUTS["configurable"]

ZERO6 = (0.0,) * 6

#: Outputs without a physics model here: constant values.
CONSTANT_OUTPUTS: dict[str, tuple[str, object]] = {
    "target_current": ("VECTOR6D", ZERO6),
    "target_moment": ("VECTOR6D", ZERO6),
    "actual_current": ("VECTOR6D", ZERO6),
    "actual_current_window": ("VECTOR6D", ZERO6),
    "joint_control_output": ("VECTOR6D", ZERO6),
    "actual_TCP_force": ("VECTOR6D", ZERO6),
    "joint_temperatures": ("VECTOR6D", (30.0,) * 6),
    "actual_momentum": ("DOUBLE", 0.0),
    "actual_main_voltage": ("DOUBLE", 48.0),
    "actual_robot_voltage": ("DOUBLE", 48.0),
    "actual_robot_current": ("DOUBLE", 0.0),
    "actual_joint_voltage": ("VECTOR6D", (48.0,) * 6),
    "io_current": ("DOUBLE", 0.0),
    "euromap67_input_bits": ("UINT32", 0),
    "euromap67_output_bits": ("UINT32", 0),
    "euromap67_24V_voltage": ("DOUBLE", 0.0),
    "euromap67_24V_current": ("DOUBLE", 0.0),
    "tool_mode": ("UINT32", 0),
    "tool_analog_input_types": ("UINT32", 0),
    "tool_analog_input0": ("DOUBLE", 0.0),
    "tool_analog_input1": ("DOUBLE", 0.0),
    "tool_output_current": ("DOUBLE", 0.0),
    "tool_temperature": ("DOUBLE", 30.0),
    "tcp_force_scalar": ("DOUBLE", 0.0),
    "tool_output_mode": ("UINT8", 0),
    "tool_digital_output0_mode": ("UINT8", 1),
    "tool_digital_output1_mode": ("UINT8", 1),
    "script_control_line": ("UINT32", 0),
    "ft_raw_wrench": ("VECTOR6D", ZERO6),
    "joint_position_deviation_ratio": ("DOUBLE", 0.0),
    "collision_detection_ratio": ("DOUBLE", 0.0),
    "time_scale_source": ("INT32", 0),
    "actual_current_as_torque": ("VECTOR6D", ZERO6),
    "wrench_calc_from_currents": ("VECTOR6D", ZERO6),
    "actual_robot_energy_consumed": ("DOUBLE", 0.0),
    "actual_robot_braking_energy_dissipated": ("DOUBLE", 0.0),
    "encoder0_raw": ("INT32", 0),
    "encoder1_raw": ("INT32", 0),
    "target_base_acceleration": ("VECTOR6D", ZERO6),
    "target_base_wrench": ("VECTOR6D", ZERO6),
    # the controller's budget for one control period, ms (actual_execution_time is what a period took)
    "target_execution_time": ("DOUBLE", DT * 1e3),
    "target_gravity": ("VECTOR3D", tuple(GRAVITY.tolist())),
}


def _vec(a) -> list:
    return a.tolist() if isinstance(a, np.ndarray) else [float(x) for x in a]


#: Outputs computed from the controller state: name -> (type, getter(snapshot)).
STATE_OUTPUTS: dict[str, tuple[str, Callable]] = {
    "timestamp": ("DOUBLE", lambda s: s.core.time),
    "target_q": ("VECTOR6D", lambda s: _vec(s.motion.target_q)),
    "target_qd": ("VECTOR6D", lambda s: _vec(s.motion.target_qd)),
    "target_qdd": ("VECTOR6D", lambda s: _vec(s.motion.target_qdd)),
    "actual_q": ("VECTOR6D", lambda s: _vec(s.motion.q)),
    "actual_qd": ("VECTOR6D", lambda s: _vec(s.motion.qd)),
    "actual_TCP_pose": ("VECTOR6D", lambda s: _vec(s.actual_tcp_pose)),
    "actual_TCP_speed": ("VECTOR6D", lambda s: _vec(s.actual_tcp_speed)),
    "target_TCP_pose": ("VECTOR6D", lambda s: _vec(s.target_tcp_pose)),
    "target_TCP_speed": ("VECTOR6D", lambda s: _vec(s.actual_tcp_speed)),
    "actual_TCP_acceleration": ("VECTOR6D", lambda s: _vec(s.core.tcp_acceleration())),
    "target_TCP_acceleration": ("VECTOR6D", lambda s: _vec(s.core.tcp_acceleration())),
    "tcp_offset": ("VECTOR6D", lambda s: _vec(s.motion.tcp)),
    "control_step": ("UINT64", lambda s: s.core.steps),
    "actual_digital_input_bits": ("UINT64", lambda s: s.io["digital_in"]),
    "actual_digital_output_bits": ("UINT64", lambda s: s.io["digital_out"]),
    # configurable inputs / outputs 0-7 (bits 8-15 of the digital words: the UR output table's)
    "actual_configurable_digital_input_bits": ("UINT64", lambda s: _CONFIGURABLE.pins_of(s.io["digital_in"])),
    "actual_configurable_digital_output_bits": ("UINT64", lambda s: _CONFIGURABLE.pins_of(s.io["digital_out"])),
    "actual_execution_time": ("DOUBLE", lambda s: s.core.execution_time_ms),
    "robot_mode": ("INT32", lambda s: s.core.robot_mode),
    "joint_mode": ("VECTOR6INT32", lambda s: (s.core.joint_mode,) * 6),
    "safety_mode": ("INT32", lambda s: s.core.safety_mode),
    "safety_status": ("INT32", lambda s: s.core.safety_mode),
    "actual_tool_accelerometer": ("VECTOR3D", lambda s: _vec(s.tool_gravity)),
    "speed_scaling": ("DOUBLE", lambda s: s.core.speed_scaling),
    "target_speed_fraction": ("DOUBLE", lambda s: s.io["speed_slider"]),
    "runtime_state": ("UINT32", lambda s: s.core.runtime_state),
    "elbow_position": ("VECTOR3D", lambda s: _vec(s.elbow_position)),
    "elbow_velocity": ("VECTOR3D", lambda s: (0.0, 0.0, 0.0)),
    "robot_status_bits": ("UINT32", lambda s: s.core.robot_status_bits),
    "safety_status_bits": ("UINT32", lambda s: s.core.safety_status_bits),
    "analog_io_types": ("UINT32", lambda s: s.io["analog_io_types"]),
    "standard_analog_input0": ("DOUBLE", lambda s: s.io["analog_in"][0]),
    "standard_analog_input1": ("DOUBLE", lambda s: s.io["analog_in"][1]),
    "standard_analog_output0": ("DOUBLE", lambda s: s.io["analog_out"][0]),
    "standard_analog_output1": ("DOUBLE", lambda s: s.io["analog_out"][1]),
    "tool_output_voltage": ("INT32", lambda s: s.io["tool_voltage"]),
    "payload": ("DOUBLE", lambda s: s.core.payload_mass),
    "payload_cog": ("VECTOR3D", lambda s: _vec(s.core.payload_cog)),
    "payload_inertia": ("VECTOR6D", lambda s: _vec(s.core.payload_inertia)),
    "output_bit_registers0_to_31": ("UINT32", lambda s: s.registers.out_bits & 0xFFFFFFFF),
    "output_bit_registers32_to_63": ("UINT32", lambda s: (s.registers.out_bits >> 32) & 0xFFFFFFFF),
    "input_bit_registers0_to_31": ("UINT32", lambda s: s.registers.in_bits & 0xFFFFFFFF),
    "input_bit_registers32_to_63": ("UINT32", lambda s: (s.registers.in_bits >> 32) & 0xFFFFFFFF),
}


def _register_getters() -> dict[str, tuple[str, Callable]]:
    out: dict[str, tuple[str, Callable]] = {}
    for i in range(N_REGISTERS):
        out[f"output_int_register_{i}"] = ("INT32", lambda s, i=i: s.registers.out_int[i])
        out[f"output_double_register_{i}"] = ("DOUBLE", lambda s, i=i: s.registers.out_double[i])
        out[f"input_int_register_{i}"] = ("INT32", lambda s, i=i: s.registers.in_int[i])
        out[f"input_double_register_{i}"] = ("DOUBLE", lambda s, i=i: s.registers.in_double[i])
    for i in BIT_REGISTERS:
        out[f"output_bit_register_{i}"] = ("BOOL", lambda s, i=i: bool(s.registers.out_bits >> i & 1))
        out[f"input_bit_register_{i}"] = ("BOOL", lambda s, i=i: bool(s.registers.in_bits >> i & 1))
    return out


OUTPUTS: dict[str, tuple[str, Callable]] = {
    **{name: (t, (lambda s, v=v: v)) for name, (t, v) in CONSTANT_OUTPUTS.items()},
    **STATE_OUTPUTS,
    **_register_getters(),
}


def _input_fields() -> dict[str, str]:
    out = {
        "speed_slider_mask": "UINT32",
        "speed_slider_fraction": "DOUBLE",
        **{name: "UINT8" for k in UR_OUTPUTS.values() for name in (f"{k.rtde_field}_mask", k.rtde_field)},
        "standard_analog_output_mask": "UINT8",
        "standard_analog_output_type": "UINT8",
        "standard_analog_output_0": "DOUBLE",
        "standard_analog_output_1": "DOUBLE",
        "input_bit_registers0_to_31": "UINT32",
        "input_bit_registers32_to_63": "UINT32",
        "external_force_torque": "VECTOR6D",
    }
    for i in range(N_REGISTERS):
        out[f"input_int_register_{i}"] = "INT32"
        out[f"input_double_register_{i}"] = "DOUBLE"
    for i in BIT_REGISTERS:
        out[f"input_bit_register_{i}"] = "BOOL"
    return out


#: Fields a client may write: name -> RTDE type.
INPUTS: dict[str, str] = _input_fields()


#: The PolyScope 5 release that introduced a field (outputs and inputs alike); a field not listed is in every 5.x.
#: Sources (sim/PROTOCOLS.md): UR's RTDE guide's "introduced in" column as Universal Robots' C++ client library's tests
#: held it (the e-Series column of ``EXHAUSTIVE_OUTPUTS_WITH_COMPATIBILITY``, commit 9443dd13 of 2024, "based on" the
#: guide) and its later commits adding fields; ur_rtde 1.6.5's version checks (``rtde_receive_interface.cpp``).
INTRODUCED: dict[str, tuple[int, int, int]] = {
    "safety_status": (5, 4, 0),  # client library tests
    "payload": (5, 5, 1),  # client library tests; ur_rtde (5.5.1)
    "payload_cog": (5, 5, 1),
    "tcp_offset": (5, 5, 1),  # client library pull request 110 and its compatibility table
    "ft_raw_wrench": (5, 9, 0),  # client library tests; ur_rtde
    "payload_inertia": (5, 11, 0),  # ur_rtde (the guide gives none)
    "collision_detection_ratio": (5, 15, 0),  # client library tests
    "time_scale_source": (5, 17, 0),  # client library tests
    "actual_current_as_torque": (5, 23, 0),  # ur_rtde
    "target_gravity": (5, 26, 0),  # client library pull request 420
    "target_base_acceleration": (5, 26, 0),
    "control_step": (5, 26, 0),  # client library pull request 529
    "target_base_wrench": (5, 26, 0),  # client library pull request 539
    # the upper registers (int and double 24..47, bits 64..127): client library tests; ur_rtde (5.3)
    **{f"{d}_{k}_register_{i}": (5, 3, 0) for d in ("input", "output") for k in ("int", "double")
       for i in range(24, N_REGISTERS)},
    **{f"{d}_bit_register_{i}": (5, 3, 0) for d in ("input", "output") for i in BIT_REGISTERS},
}


def available(name: str, version=None) -> bool:
    """Whether a controller of ``version`` (a :class:`sim.versions.SoftwareVersion`; None: any) has field ``name``
    (``name`` must be a known field: `OUTPUTS` or `INPUTS`)."""
    return version is None or version.at_least(INTRODUCED.get(name, (5, 0, 0)))


def output_type(name: str, version=None) -> str:
    """The RTDE type of output ``name`` on a controller of ``version`` (None: the newest), or ``NOT_FOUND``."""
    entry = OUTPUTS.get(name)
    return entry[0] if entry and available(name, version) else "NOT_FOUND"


def input_type(name: str, version=None) -> str:
    """The RTDE type of input ``name`` on a controller of ``version`` (None: the newest), or ``NOT_FOUND``."""
    t = INPUTS.get(name)
    return t if t is not None and available(name, version) else "NOT_FOUND"


class Registers:
    """The controller's RTDE register file (general-purpose int, double and bit registers).

    ``out_*`` are written by programs (``write_output_*_register``), ``in_*`` by RTDE clients.
    Plain lists: the controller's tick thread and the RTDE readers each write whole values (atomic in
    CPython), so no lock is needed for single registers.
    """

    def __init__(self) -> None:
        self.out_int = [0] * N_REGISTERS
        self.out_double = [0.0] * N_REGISTERS
        self.in_int = [0] * N_REGISTERS
        self.in_double = [0.0] * N_REGISTERS
        self.out_bits = 0
        self.in_bits = 0


def compile_packer(layout: struct.Struct, head: tuple, sources) -> Callable[[Snapshot], bytes]:
    """A function of a :class:`Snapshot` giving one package of ``layout``: the values ``head`` (the package header's),
    then the value of each output named in ``sources`` in order, a vector's scalars one by one (a source that is a
    tuple is sent as it is: reserved fields' zeros).

    The package is packed by one ``layout.pack`` call written out for these fields (no per-field loop, no
    intermediate lists: the 500 Hz streams build one every control period); the source text holds no name, only
    positions, so any names may be given."""
    env: dict = {"pack": layout.pack}
    args = [f"h{i}" for i in range(len(head))]
    env.update((f"h{i}", v) for i, v in enumerate(head))
    for i, src in enumerate(sources):
        if isinstance(src, tuple):
            env[f"c{i}"] = src
            args.append(f"*c{i}")
        elif src in CONSTANT_OUTPUTS:
            rtde_type, value = CONSTANT_OUTPUTS[src]
            env[f"c{i}"] = value if rtde_type in TYPE_WIDTH else (value,)  # a vector's value is a tuple
            args.append(f"*c{i}")
        else:
            rtde_type, env[f"g{i}"] = OUTPUTS[src]
            args.append(f"*g{i}(s)" if rtde_type in TYPE_WIDTH else f"g{i}(s)")
    exec(f"def packer(s):\n    return pack({', '.join(args)})\n", env)
    return env["packer"]


class Snapshot:
    """The controller as the packages of one control period see it (every interface's: RTDE, real-time); derived
    values computed on first use.

    Parameters
    ----------
    core : sim.core.Core
        The controller (time, modes, motion, TCP offset, payload, register file, I/O).
    """

    def __init__(self, core) -> None:
        self.core = core
        self.motion = core.motion
        self.registers = core.registers
        self._io: dict | None = None

    @property
    def io(self) -> dict:
        """The I/O state (:meth:`sim.io_state.IOState.snapshot`), taken on first use."""
        if self._io is None:
            self._io = self.core.io.snapshot()
        return self._io


    @property
    def actual_tcp_pose(self) -> np.ndarray:
        return self.core.tcp_pose()

    @property
    def target_tcp_pose(self) -> np.ndarray:
        return self.core.tcp_pose()  # the motion model's joints follow their targets exactly

    @property
    def actual_tcp_speed(self) -> np.ndarray:
        return self.core.tcp_speed()

    @property
    def tool_gravity(self) -> np.ndarray:
        return self.core.tool_gravity()

    @property
    def elbow_position(self) -> np.ndarray:
        return self.core.elbow_position()
