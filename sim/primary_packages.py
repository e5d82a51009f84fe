"""Packages of the primary and secondary client interfaces (TCP 30001, 30002) in a PolyScope 5.x controller's layout.

Pure functions from plain values to bytes; :mod:`sim.primary_server` gathers the values and sends the bytes. Every
number is big-endian. A package is ``int32 size`` (the whole package, header included) and ``uint8 type``, then:

* type 16, robot state: sub-packages, each ``uint32 size`` (its header included), ``uint8 sub-type``, payload;
* type 20, robot message: ``uint64 timestamp`` (us), ``int8 source``, ``uint8 message type``, payload.

The payload layouts (`SUB_PACKAGES`, the message functions) and the order of the sub-packages (`STATE_ORDER`) are
those of UR's client interface documentation for e-Series 5.x as Universal Robots' C++ client library parses them
(``src/primary/robot_state/*.cpp``, ``src/primary/robot_message/*.cpp``, ``include/ur_client_library/primary/``),
checked against the first robot state package of a URSim 5.8 UR5e that library's tests hold (1386 bytes: the same
sub-packages, sizes and order). ``sim/PROTOCOLS.md`` lists every field.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

HEADER = struct.Struct(">iB")  # package: size (with this header), type
SUB_HEADER = struct.Struct(">IB")  # robot state sub-package: size (with this header), sub-type
MESSAGE_HEADER = struct.Struct(">QbB")  # robot message after the package header: timestamp us, source, message type

ROBOT_STATE, ROBOT_MESSAGE = 16, 20

# robot state sub-package types
(ROBOT_MODE_DATA, JOINT_DATA, TOOL_DATA, MASTERBOARD_DATA, CARTESIAN_INFO, KINEMATICS_INFO, CONFIGURATION_DATA,
 FORCE_MODE_DATA, ADDITIONAL_INFO, CALIBRATION_DATA, SAFETY_DATA, TOOL_COMM_INFO, TOOL_MODE_INFO) = range(13)

#: Payload layout of each robot state sub-package (after its 5-byte header).
SUB_PACKAGES: dict[int, struct.Struct] = {
    # timestamp us; real robot connected, enabled, power on, emergency stopped, protective stopped, program running,
    # program paused; robot mode, control mode; target speed fraction, speed scaling, target speed fraction limit;
    # reserved
    ROBOT_MODE_DATA: struct.Struct(">Q???????BBdddB"),
    # per joint: q actual, q target, qd actual (double); I actual, V actual, T motor, T micro (float); joint mode
    JOINT_DATA: struct.Struct(">" + "dddffffB" * 6),
    # analog input range 0, 1; analog input 0, 1; tool voltage 48 V (float); tool output voltage (uint8); tool current,
    # tool temperature (float); tool mode
    TOOL_DATA: struct.Struct(">BBddfBffB"),
    # digital input bits, digital output bits; analog input range 0, 1; analog input 0, 1; analog output domain 0, 1;
    # analog output 0, 1; masterboard temperature, robot voltage 48 V, robot current, master I/O current (float);
    # safety mode, in reduced mode, euromap67 installed (0: its four fields absent); reserved (uint32); operational
    # mode selector input, three-position enabling device input, reserved
    MASTERBOARD_DATA: struct.Struct(">IIBBddBBddffffBBBIBBB"),
    # TCP pose x, y, z, rx, ry, rz; TCP offset x, y, z, rx, ry, rz
    CARTESIAN_INFO: struct.Struct(">12d"),
    # calibration checksum per joint (uint32); DH theta, a, d, alpha (6 doubles each); calibration status (uint32)
    KINEMATICS_INFO: struct.Struct(">6I24dI"),
    # per joint min, max position; per joint max speed, max acceleration; v joint, a joint, v tool, a tool defaults,
    # eq radius; DH a, d, alpha, theta (6 doubles each); masterboard version, controller box type, robot type,
    # robot sub-type (int32)
    CONFIGURATION_DATA: struct.Struct(">12d12d5d24d4i"),
    # force Fx, Fy, Fz, Frx, Fry, Frz; robot dexterity
    FORCE_MODE_DATA: struct.Struct(">7d"),
    # teach pendant button state, freedrive button enabled, I/O enabled freedrive, reserved
    ADDITIONAL_INFO: struct.Struct(">B??B"),
    # UR-internal (calibration of the force/torque estimate): 6 doubles
    CALIBRATION_DATA: struct.Struct(">6d"),
    # UR-internal safety data (38 bytes on URSim 5.8): uint32, two uint8, four doubles
    SAFETY_DATA: struct.Struct(">IBB4d"),
    # tool communication enabled; baud rate, parity, stop bits (uint32); rx idle chars, tx idle chars (float)
    TOOL_COMM_INFO: struct.Struct(">?IIIff"),
    # tool output mode, digital output 0 mode, digital output 1 mode
    TOOL_MODE_INFO: struct.Struct(">BBB"),
}
#: Order of the sub-packages in a robot state package, as URSim 5.8 sends them.
STATE_ORDER = (ROBOT_MODE_DATA, JOINT_DATA, CARTESIAN_INFO, KINEMATICS_INFO, CALIBRATION_DATA, MASTERBOARD_DATA,
               TOOL_DATA, CONFIGURATION_DATA, FORCE_MODE_DATA, ADDITIONAL_INFO, SAFETY_DATA, TOOL_COMM_INFO,
               TOOL_MODE_INFO)
#: Size of a whole robot state package (bytes).
STATE_SIZE = HEADER.size + sum(SUB_HEADER.size + SUB_PACKAGES[k].size for k in STATE_ORDER)

# robot message types
TEXT_MESSAGE, VERSION_MESSAGE, SAFETY_MODE_MESSAGE, ERROR_CODE_MESSAGE, KEY_MESSAGE, RUNTIME_EXCEPTION_MESSAGE = (
    0, 3, 5, 6, 7, 10)
# message sources (UR's list; which a controller uses for which message is not documented)
SOURCE_ROBOT_INTERFACE, SOURCE_RTMACHINE, SOURCE_CONTROLLER, SOURCE_SAFETY_PROCESSOR = -2, -3, 7, 20
# report levels of error code messages
DEBUG, INFO, WARNING, VIOLATION, FAULT = 0, 1, 2, 3, 4
#: Error code of a script or command sent to a read-only primary interface (local control), as UR's C++ client
#: library recognizes it (C210).
READ_ONLY_INTERFACE = 210

#: UR's robot type ids (configuration data) of the models the simulator knows.
ROBOT_TYPES = {"ur3e": 3, "ur5e": 1, "ur10e": 2, "ur16e": 4, "ur20": 7}
#: Masterboard version, controller box type, robot sub-type: a URSim 5.8 e-Series controller's.
MASTERBOARD_VERSION, CONTROLLER_BOX_TYPE, ROBOT_SUB_TYPE = 6, 4, 3
#: Default joint speed (rad/s) and acceleration (rad/s^2), tool speed (m/s) and acceleration (m/s^2), equivalent
#: radius (m): the controller's movej / movel defaults.
MOVE_DEFAULTS = (math.radians(60.0), math.radians(80.0), 0.25, 1.2, 0.25)


@dataclass(frozen=True)
class StateSample:
    """The controller as one robot state package reports it (SI units, tuples of 6 per joint).

    ``joint_mode`` is the controller's joint mode (253 running, 255 idle, 239 power off), also the tool's mode;
    ``analog_io_types`` has RTDE's bits (0-1 inputs, 2-3 outputs; 1 = voltage); ``digital_in`` / ``digital_out``
    hold bits 0-7 standard, 8-15 configurable, 16-17 tool."""

    time: float
    robot_mode: int
    safety_mode: int
    powered: bool
    program_running: bool
    program_paused: bool
    speed_fraction: float
    speed_scaling: float
    q: tuple[float, ...]
    q_target: tuple[float, ...]
    qd: tuple[float, ...]
    joint_mode: int
    tcp_pose: tuple[float, ...]
    tcp_offset: tuple[float, ...]
    digital_in: int
    digital_out: int
    analog_in: tuple[float, float]
    analog_out: tuple[float, float]
    analog_io_types: int
    tool_voltage: int


@dataclass(frozen=True)
class ModelData:
    """What the configuration and kinematics packages say of the arm (a :class:`planner.kinematics.URModel`'s
    values): DH parameters, joint position and speed limits, the acceleration limit, UR's robot type id."""

    dh_a: tuple[float, ...]
    dh_d: tuple[float, ...]
    dh_alpha: tuple[float, ...]
    q_min: tuple[float, ...]
    q_max: tuple[float, ...]
    qd_max: tuple[float, ...]
    qdd_max: float
    robot_type: int

    @classmethod
    def of(cls, model, qdd_max: float) -> ModelData:
        """From a ``planner.kinematics.URModel`` and the joint acceleration limit (rad/s^2)."""
        return cls(dh_a=(0.0, model.a2, model.a3, 0.0, 0.0, 0.0),
                   dh_d=(model.d1, 0.0, 0.0, model.d4, model.d5, model.d6),
                   dh_alpha=(math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0),
                   q_min=tuple(model.q_min), q_max=tuple(model.q_max), qd_max=tuple(model.qd_max),
                   qdd_max=float(qdd_max), robot_type=ROBOT_TYPES[model.name])


# values the simulator has no model for, reported as constants (the same as its RTDE outputs)
JOINT_TEMPERATURE, JOINT_VOLTAGE, ROBOT_VOLTAGE = 30.0, 48.0, 48.0
TOOL_TEMPERATURE, MASTERBOARD_TEMPERATURE = 30.0, 30.0


def _sub(kind: int, *values) -> bytes:
    layout = SUB_PACKAGES[kind]
    return SUB_HEADER.pack(SUB_HEADER.size + layout.size, kind) + layout.pack(*values)


def robot_state(s: StateSample, m: ModelData) -> bytes:
    """One robot state package (type 16) of every sub-package in `STATE_ORDER`: `STATE_SIZE` bytes."""
    us = int(round(s.time * 1e6))
    joints = []
    for j in range(6):
        joints += [s.q[j], s.q_target[j], s.qd[j], 0.0, JOINT_VOLTAGE if s.powered else 0.0, JOINT_TEMPERATURE, 0.0,
                   s.joint_mode]
    limits = [x for j in range(6) for x in (m.q_min[j], m.q_max[j])]
    motion = [x for j in range(6) for x in (m.qd_max[j], m.qdd_max)]
    dh_theta = (0.0,) * 6
    parts = {
        ROBOT_MODE_DATA: _sub(ROBOT_MODE_DATA, us, True, True, s.powered, s.safety_mode in (6, 7), s.safety_mode == 3,
                              s.program_running, s.program_paused, s.robot_mode, 0, s.speed_fraction, s.speed_scaling,
                              1.0, 0),
        JOINT_DATA: _sub(JOINT_DATA, *joints),
        CARTESIAN_INFO: _sub(CARTESIAN_INFO, *s.tcp_pose, *s.tcp_offset),
        # the checksums and status of an uncalibrated arm, as URSim reports them
        KINEMATICS_INFO: _sub(KINEMATICS_INFO, *(0xFFFFFFFF,) * 6, *dh_theta, *m.dh_a, *m.dh_d, *m.dh_alpha, 0),
        CALIBRATION_DATA: _sub(CALIBRATION_DATA, *(0.0,) * 6),
        MASTERBOARD_DATA: _sub(MASTERBOARD_DATA, s.digital_in & 0x3FFFF, s.digital_out & 0x3FFFF,
                               s.analog_io_types & 1, s.analog_io_types >> 1 & 1, *s.analog_in,
                               s.analog_io_types >> 2 & 1, s.analog_io_types >> 3 & 1, *s.analog_out,
                               MASTERBOARD_TEMPERATURE, ROBOT_VOLTAGE if s.powered else 0.0, 0.0, 0.0, s.safety_mode,
                               False, 0, 0, 1, 1, 0),
        TOOL_DATA: _sub(TOOL_DATA, 0, 0, 0.0, 0.0, ROBOT_VOLTAGE if s.powered else 0.0, s.tool_voltage, 0.0,
                        TOOL_TEMPERATURE, s.joint_mode),
        CONFIGURATION_DATA: _sub(CONFIGURATION_DATA, *limits, *motion, *MOVE_DEFAULTS, *m.dh_a, *m.dh_d, *m.dh_alpha,
                                 *dh_theta, MASTERBOARD_VERSION, CONTROLLER_BOX_TYPE, m.robot_type, ROBOT_SUB_TYPE),
        FORCE_MODE_DATA: _sub(FORCE_MODE_DATA, *(0.0,) * 7),
        ADDITIONAL_INFO: _sub(ADDITIONAL_INFO, 0, True, False, 1),
        SAFETY_DATA: _sub(SAFETY_DATA, 0, 1, 1, 0.0, 0.0, 0.0, 0.0),
        TOOL_COMM_INFO: _sub(TOOL_COMM_INFO, False, 115200, 0, 1, 1.5, 3.5),
        # tool output mode 0 and both tool digital outputs push-pull off (the RTDE outputs' values)
        TOOL_MODE_INFO: _sub(TOOL_MODE_INFO, 0, 1, 1),
    }
    body = b"".join(parts[k] for k in STATE_ORDER)
    return HEADER.pack(HEADER.size + len(body), ROBOT_STATE) + body


def _message(kind: int, time: float, source: int, payload: bytes) -> bytes:
    body = MESSAGE_HEADER.pack(int(round(time * 1e6)), source, kind) + payload
    return HEADER.pack(HEADER.size + len(body), ROBOT_MESSAGE) + body


def _text(text: str) -> bytes:
    return text.encode("utf-8", "replace")


def version_message(time: float, version: tuple[int, int, int, int], build_date: str,
                    project: str = "URControl") -> bytes:
    """The first package on every primary and secondary connection: int8 name length, name, uint8 major, uint8
    minor, int32 bugfix, int32 build, build date (the rest)."""
    name = _text(project)
    payload = struct.pack(">b", len(name)) + name + struct.pack(">BBii", *version) + _text(build_date)
    return _message(VERSION_MESSAGE, time, SOURCE_ROBOT_INTERFACE, payload)


def text_message(time: float, text: str) -> bytes:
    """A text message (a program's ``textmsg``): the text."""
    return _message(TEXT_MESSAGE, time, SOURCE_RTMACHINE, _text(text))


def key_message(time: float, title: str, text: str, code: int = 0, argument: int = 0) -> bytes:
    """A key message (``PROGRAM_XXX_STARTED`` / ``PROGRAM_XXX_STOPPED`` with the program's name): int32 code,
    int32 argument, uint8 title length, title, text (the rest)."""
    t = _text(title)[:255]
    return _message(KEY_MESSAGE, time, SOURCE_ROBOT_INTERFACE,
                    struct.pack(">iiB", code, argument, len(t)) + t + _text(text))


def error_code_message(time: float, code: int, argument: int, level: int, text: str) -> bytes:
    """An error code message: int32 code, int32 argument, int32 report level, uint32 data type, uint32 data, text."""
    return _message(ERROR_CODE_MESSAGE, time, SOURCE_CONTROLLER,
                    struct.pack(">iiiII", code, argument, level, 0, 0) + _text(text))


def runtime_exception_message(time: float, line: int, column: int, text: str) -> bytes:
    """A program's runtime (or compile) error: uint32 line, uint32 column (1-based; 0 unknown), text."""
    return _message(RUNTIME_EXCEPTION_MESSAGE, time, SOURCE_RTMACHINE,
                    struct.pack(">II", max(line, 0), max(column, 0)) + _text(text))


def safety_mode_message(time: float, mode: int, code: int = 0, argument: int = 0) -> bytes:
    """A change of safety mode: int32 code, int32 argument, uint8 safety mode, uint32 report data type, uint32 data."""
    return _message(SAFETY_MODE_MESSAGE, time, SOURCE_SAFETY_PROCESSOR,
                    struct.pack(">iiBII", code, argument, mode, 0, 0))
