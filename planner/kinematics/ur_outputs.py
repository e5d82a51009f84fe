"""The digital outputs of a UR controller: the one table of their kinds, pins, bits, names and setters.

Every part of the project that switches, records, simulates or names a digital output reads this table (the
settings' ``cut_output``, the I/O events of the time law, the trajectory's I/O bits, the URScript exports, the
drivers over RTDE and Modbus, the simulated controller, the reports and plots). It lives in the kinematics package
because the simulated controller may import ``planner.kinematics`` only.

The 18-bit word (the layout of RTDE's ``actual_digital_output_bits`` and ``actual_digital_input_bits``, the
drivers' and the simulator's I/O state): bits 0-7 standard, 8-15 configurable, 16-17 tool.

============  ====  =====  =============================  ===========================  ===============
kind          pins  bits   URScript setter (n, b)         RTDE input field (+ _mask)   Modbus register
============  ====  =====  =============================  ===========================  ===============
standard      8     0-7    set_standard_digital_out       standard_digital_output      1 bits 0-7
configurable  8     8-15   set_configurable_digital_out   configurable_digital_output  31 bits 0-7
tool          2     16-17  set_tool_digital_out           tool_digital_output          1 bits 8-9
============  ====  =====  =============================  ===========================  ===============

The set / clear mask registers of register 1 are 2 / 3, those of register 31 are 32 / 33.

Sources: UR Script Manual (e-Series) for the setters; Universal Robots' RTDE guide for the field names; its
support article "Modbus server" (UR's table "ModBus server data") for the registers, whose bit layout is
``[BBBBBBBBTTxxxxxx]`` (standard 0-7, tool 8-9) for registers 0-3 and ``[BBBBBBBBxxxxxxxx]`` for 30-33; ur_rtde's
``RTDEIOInterface`` for its setter methods.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

from planner.errors import PlannerError

__all__ = [
    "DIGITAL_BITS",
    "DIGITAL_MASK",
    "IO_BIT_OFFSET",
    "OUTPUT_PINS",
    "UR_OUTPUTS",
    "OutputKind",
    "bit_name",
    "from_modbus",
    "from_ur_bits",
    "output_bit",
    "to_modbus",
    "to_ur_bits",
]


@dataclass(frozen=True)
class OutputKind:
    """One kind of digital output of a UR controller.

    Attributes
    ----------
    name : str
        ``"standard"``, ``"configurable"`` or ``"tool"`` (what ``PlanSettings.cut_output`` and I/O events name).
    pins : int
        Number of outputs of the kind, numbered 0 .. pins - 1.
    bit_offset : int
        Bit of pin 0 in the 18-bit word.
    script_setter : str
        The URScript function switching one of them: ``<script_setter>(n, b)``.
    rtde_field : str
        The RTDE input field with their values; ``<rtde_field>_mask`` selects the outputs to change.
    rtde_io_method : str
        ur_rtde's ``RTDEIOInterface`` method switching one of them: ``<rtde_io_method>(n, b)``.
    modbus_register : int
        UR's Modbus server register holding their states (``modbus_shift`` is the bit of pin 0 there).
    modbus_shift : int
    modbus_set_register, modbus_clear_register : int
        Write-only mask registers: the outputs under the bits written go high / low.
    """

    name: str
    pins: int
    bit_offset: int
    script_setter: str
    rtde_field: str
    rtde_io_method: str
    modbus_register: int
    modbus_shift: int
    modbus_set_register: int
    modbus_clear_register: int

    @property
    def pin_mask(self) -> int:
        """The kind's pins as the low bits of an int (0xFF for 8 pins)."""
        return (1 << self.pins) - 1

    @property
    def mask(self) -> int:
        """The kind's bits in the 18-bit word."""
        return self.pin_mask << self.bit_offset

    def bit(self, pin: int) -> int:
        """Bit number (0-17) of output ``pin`` in the 18-bit word (pin checked by :func:`output_bit`)."""
        return self.bit_offset + pin

    def pins_of(self, word: int) -> int:
        """The kind's states in the 18-bit ``word``, pin p as bit p (RTDE's ``actual_configurable_digital_output_bits``
        is ``UR_OUTPUTS["configurable"].pins_of(actual_digital_output_bits)``)."""
        return (word >> self.bit_offset) & self.pin_mask


#: The output kinds, in the order of their bits.
UR_OUTPUTS: Mapping[str, OutputKind] = MappingProxyType({
    k.name: k for k in (
        OutputKind("standard", 8, 0, "set_standard_digital_out", "standard_digital_output", "setStandardDigitalOut",
                   1, 0, 2, 3),
        OutputKind("configurable", 8, 8, "set_configurable_digital_out", "configurable_digital_output",
                   "setConfigurableDigitalOut", 31, 0, 32, 33),
        OutputKind("tool", 2, 16, "set_tool_digital_out", "tool_digital_output", "setToolDigitalOut", 1, 8, 2, 3),
    )
})
#: Number of pins of each kind.
OUTPUT_PINS: Mapping[str, int] = MappingProxyType({k.name: k.pins for k in UR_OUTPUTS.values()})
#: Bit of pin 0 of each kind in the 18-bit word.
IO_BIT_OFFSET: Mapping[str, int] = MappingProxyType({k.name: k.bit_offset for k in UR_OUTPUTS.values()})
#: Bits of the word, and all of them.
DIGITAL_BITS = max(k.bit_offset + k.pins for k in UR_OUTPUTS.values())
DIGITAL_MASK = (1 << DIGITAL_BITS) - 1


def output_bit(kind: str, pin) -> int:
    """Bit number (0-17) of output ``pin`` of ``kind`` ("standard" 0-7, "configurable" 0-7, "tool" 0-1).

    A kind not in the table, or a pin that is no integer of its range, is a :class:`PlannerError` (a ValueError)
    naming it.
    """
    k = UR_OUTPUTS.get(kind) if isinstance(kind, str) else None
    if k is None:
        raise PlannerError(f"output kind must be one of {sorted(UR_OUTPUTS)}, got {kind!r}")
    if not hasattr(pin, "__index__"):
        raise PlannerError(f"{kind} output pin must be an integer, got {pin!r} ({type(pin).__name__})")
    p = pin.__index__()
    if not 0 <= p < k.pins:
        raise PlannerError(f"{kind} output pin must be within 0..{k.pins - 1}, got {p}")
    return k.bit(p)


def bit_name(bit: int) -> str:
    """Readable name of a bit of the 18-bit word: ``standard[3]``, ``configurable[1]``, ``tool[0]``."""
    for k in UR_OUTPUTS.values():
        if k.bit_offset <= bit < k.bit_offset + k.pins:
            return f"{k.name}[{bit - k.bit_offset}]"
    raise PlannerError(f"bit {bit} is no digital I/O bit (0..{DIGITAL_BITS - 1})")


def to_modbus(word: int, register: int) -> int:
    """The bits of the 18-bit ``word`` that UR's Modbus ``register`` holds (1 or 31), in that register's layout."""
    value = 0
    for k in UR_OUTPUTS.values():
        if k.modbus_register == register:
            value |= ((word >> k.bit_offset) & k.pin_mask) << k.modbus_shift
    return value


def from_modbus(register: int, value: int) -> int:
    """The 18-bit word of the bits Modbus ``register`` (1 or 31) holds as ``value``; its undefined bits dropped."""
    word = 0
    for k in UR_OUTPUTS.values():
        if k.modbus_register == register:
            word |= ((value >> k.modbus_shift) & k.pin_mask) << k.bit_offset
    return word


def to_ur_bits(word: int) -> int:
    """18-bit word -> UR's register-1 layout (standard 0-7, tool 8-9); the configurable bits are dropped (they
    live in register 31)."""
    return to_modbus(word, UR_OUTPUTS["standard"].modbus_register)


def from_ur_bits(bits: int, configurable: int = 0) -> int:
    """UR's register-1 layout (and register 31's configurable bits) -> the 18-bit word."""
    return (from_modbus(UR_OUTPUTS["standard"].modbus_register, bits)
            | from_modbus(UR_OUTPUTS["configurable"].modbus_register, configurable))
