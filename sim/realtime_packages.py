"""The real-time interface's state package (TCP 30003, 500 Hz) in the layout of PolyScope 5.10 and later: 1220 bytes;
a controller of an earlier release sends the prefix that release has (`SIZES`).

A package is ``int32 size`` (1220, the whole package) then 152 big-endian 8-byte values, all doubles but the digital
input and output words, which are the bits as an unsigned 64-bit integer (UR's documentation lists them as doubles
"encoded as int64_t"; the parsers below read them so). The field list, in order, is `FIELDS`: UR's client interface
documentation for the real-time interface (``ClientInterfaces_Realtime``, the 5.10 columns) as recorded by the public
clients that parse it: JHU's sawUniversalRobot (``mtsUniversalRobotScriptRT.cpp``: the packet structs per version,
1220 bytes for 5.10), ROS-Industrial's ur_modern_driver (``ur/rt_state.h``: the fields up to 5.4, ``uint64_t``
digital words) and python-urx (``urrtmon.py``: the 5.9 layout as doubles). ``sim/PROTOCOLS.md`` lists them.

Every value comes from an RTDE output of the same name's meaning (:data:`sim.rtde_fields.OUTPUTS`), read from one
:class:`sim.rtde_fields.Snapshot`: a client of both interfaces reads the same numbers. Fields UR reserves for its own
software are zeros.
"""

from __future__ import annotations

import struct

from sim.rtde_fields import Snapshot, compile_packer

#: Header: the package's size in bytes (this header included).
HEADER = struct.Struct(">i")

#: The package's fields in order: (name in UR's documentation, number of values, struct code of one value,
#: the RTDE output it carries or None for a field reserved for UR's software, sent as zeros).
FIELDS: tuple[tuple[str, int, str, str | None], ...] = (
    ("Time", 1, "d", "timestamp"),
    ("q target", 6, "d", "target_q"),
    ("qd target", 6, "d", "target_qd"),
    ("qdd target", 6, "d", "target_qdd"),
    ("I target", 6, "d", "target_current"),
    ("M target", 6, "d", "target_moment"),
    ("q actual", 6, "d", "actual_q"),
    ("qd actual", 6, "d", "actual_qd"),
    ("I actual", 6, "d", "actual_current"),
    ("I control", 6, "d", "joint_control_output"),
    ("Tool vector actual", 6, "d", "actual_TCP_pose"),
    ("TCP speed actual", 6, "d", "actual_TCP_speed"),
    ("TCP force", 6, "d", "actual_TCP_force"),
    ("Tool vector target", 6, "d", "target_TCP_pose"),
    ("TCP speed target", 6, "d", "target_TCP_speed"),
    ("Digital input bits", 1, "Q", "actual_digital_input_bits"),
    ("Motor temperatures", 6, "d", "joint_temperatures"),
    ("Controller Timer", 1, "d", "actual_execution_time"),
    ("Test value", 1, "d", None),
    ("Robot Mode", 1, "d", "robot_mode"),
    ("Joint Modes", 6, "d", "joint_mode"),
    ("Safety Mode", 1, "d", "safety_mode"),
    ("reserved", 6, "d", None),
    ("Tool Accelerometer values", 3, "d", "actual_tool_accelerometer"),
    ("reserved", 6, "d", None),
    ("Speed scaling", 1, "d", "speed_scaling"),
    ("Linear momentum norm", 1, "d", "actual_momentum"),
    ("reserved", 1, "d", None),
    ("reserved", 1, "d", None),
    ("V main", 1, "d", "actual_main_voltage"),
    ("V robot", 1, "d", "actual_robot_voltage"),
    ("I robot", 1, "d", "actual_robot_current"),
    ("V actual", 6, "d", "actual_joint_voltage"),
    ("Digital outputs", 1, "Q", "actual_digital_output_bits"),
    ("Program state", 1, "d", "runtime_state"),
    ("Elbow position", 3, "d", "elbow_position"),
    ("Elbow velocity", 3, "d", "elbow_velocity"),
    ("Safety Status", 1, "d", "safety_status"),
    ("reserved", 3, "d", None),
    ("Payload Mass", 1, "d", "payload"),
    ("Payload CoG", 3, "d", "payload_cog"),
    ("Payload Inertia", 6, "d", "payload_inertia"),
)

#: The whole package after its header.
BODY = struct.Struct(">" + "".join(code * n for _, n, code, _ in FIELDS))
#: Bytes of one package: 1220.
PACKAGE_SIZE = HEADER.size + BODY.size
#: The package's length from each release on (earlier releases send a prefix of the 5.10 package, the fields they
#: have): 1108 bytes 5.0-5.3, 1116 5.4-5.8 (Safety Status added), 1140 5.9, 1220 from 5.10 (sawUniversalRobot's
#: packet structs per version, sim/PROTOCOLS.md).
SIZES: tuple[tuple[tuple[int, int, int], int], ...] = (((5, 0, 0), 1108), ((5, 4, 0), 1116), ((5, 9, 0), 1140),
                                                        ((5, 10, 0), PACKAGE_SIZE))


def package_size(version) -> int:
    """Bytes of one package (header included) sent by a controller of ``version`` (a
    :class:`sim.versions.SoftwareVersion`)."""
    return [size for since, size in SIZES if version.at_least(since)][-1]



def _packer(size: int):
    """The packer (:func:`sim.rtde_fields.compile_packer`) of a ``size``-byte package: the header, then the fields that
    fit, each from its RTDE output, the reserved ones zeros."""
    codes, sources, at = "", [], HEADER.size
    for _, n, code, src in FIELDS:
        if at >= size:
            break
        codes += code * n
        at += 8 * n
        sources.append((0.0,) * n if src is None else src)
    return compile_packer(struct.Struct(HEADER.format + codes), (size,), sources)


#: The packer of each package size (`SIZES`).
_PACKERS = {size: _packer(size) for _, size in SIZES}


def offsets() -> dict[str, int]:
    """Byte offset of each named field in a package (the header included), for parsers and documentation."""
    out: dict[str, int] = {}
    at = HEADER.size
    for name, n, _, _ in FIELDS:
        out.setdefault(name, at)
        at += 8 * n
    return out


def realtime_state(snap: Snapshot, size: int = PACKAGE_SIZE) -> bytes:
    """One real-time state package of the controller as ``snap`` sees it: ``size`` bytes (one of `SIZES`: the
    package of that release, a prefix of the 5.10 one)."""
    return _PACKERS[size](snap)
