"""The simulated controller's I/O: digital and analog I/O, tool I/O, speed slider, Modbus registers.

One `IOState` per simulated controller, shared by every entry point (RTDE, script programs, Modbus)
so that what one of them sets the others see. All methods are thread-safe (one internal re-entrant
lock); reads return immutable values (ints, floats, tuples).

Digital bit layout (the layout of RTDE's ``actual_digital_output_bits`` / ``actual_digital_input_bits``, the UR
output table's, :mod:`planner.kinematics.ur_outputs`): bits 0-7 standard I/O, bits 8-15 configurable I/O, bits
16-17 tool I/O (`DIGITAL_BITS` = 18 bits).

Analog values are in the output's unit, as RTDE's ``standard_analog_output0`` / ``standard_analog_input0``
report them: volts in the voltage domain (0..10 V), amperes in the current domain (0.004..0.020 A).
The domain of each channel is in `analog_io_types` (RTDE's ``analog_io_types`` bits: bit 0/1 standard
analog input 0/1, bit 2/3 standard analog output 0/1; 0 = current, 1 = voltage).

Modbus general-purpose registers are UR's addresses 128..255, unsigned 16-bit.

Change notification: `subscribe(callback)` calls ``callback(name, value)`` after every change, in the
writer's thread and while the state lock is held (so callbacks see changes in the order they happened,
and may read this IOState, but must not block). Names and values:

=====================  ==========================================================
``digital_out``        int, all 18 output bits after the change
``digital_in``         int, all 18 input bits after the change
``analog_out``         tuple (2,) of float
``analog_in``          tuple (2,) of float
``analog_io_types``    int (4 bits)
``speed_slider``       float, 0..1
``tool_voltage``       int, volts (0, 12 or 24)
``register``           tuple (address, value) of one general-purpose register
=====================  ==========================================================

Callbacks fire only when a value really changes (writing the same value again is silent).
"""

from __future__ import annotations

import math
import operator
import threading
from collections.abc import Callable
from typing import Any

from planner.kinematics.ur_outputs import DIGITAL_BITS, DIGITAL_MASK, UR_OUTPUTS  # noqa: F401  (DIGITAL_BITS: as before)

#: Bits of the standard, configurable and tool I/O inside the 18-bit word (DIGITAL_BITS of them, all: DIGITAL_MASK).
STANDARD_MASK = UR_OUTPUTS["standard"].mask
CONFIGURABLE_MASK = UR_OUTPUTS["configurable"].mask
TOOL_MASK = UR_OUTPUTS["tool"].mask
#: First and last Modbus general-purpose register address (inclusive).
REGISTER_FIRST = 128
REGISTER_LAST = 255
#: Tool output voltages the controller offers, V.
TOOL_VOLTAGES = (0, 12, 24)
#: Analog ranges per domain: voltage 0..10 V, current 4..20 mA (in A).
ANALOG_VOLTAGE_RANGE = (0.0, 10.0)
ANALOG_CURRENT_RANGE = (0.004, 0.020)

Callback = Callable[[str, Any], None]


def _as_int(value: Any, name: str) -> int:
    """``value`` as a Python int (numpy integers accepted), or a ValueError naming ``name``."""
    if isinstance(value, bool):
        return int(value)
    try:
        return operator.index(value)
    except TypeError:
        raise ValueError(f"{name} must be an integer, got {value!r} ({type(value).__name__})") from None


def _bits(value: Any, name: str) -> int:
    """An 18-bit digital word, validated."""
    v = _as_int(value, name)
    if not 0 <= v <= DIGITAL_MASK:
        raise ValueError(f"{name} must be within 0..0x{DIGITAL_MASK:X} (18 digital bits), got {v}")
    return v


def _finite(value: Any, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {v}")
    return v


def _index2(index: Any, name: str) -> int:
    i = _as_int(index, name)
    if i not in (0, 1):
        raise ValueError(f"{name} must be 0 or 1, got {i}")
    return i


def check_register_address(address: Any) -> int:
    """A general-purpose register address (128..255) as int, or a ValueError naming it."""
    a = _as_int(address, "register address")
    if not REGISTER_FIRST <= a <= REGISTER_LAST:
        raise ValueError(f"register address must be within {REGISTER_FIRST}..{REGISTER_LAST}, got {a}")
    return a


class IOState:
    """Thread-safe I/O of one simulated controller (see the module docstring for layout and units)."""

    def __init__(self) -> None:
        self._lock = threading.RLock()
        self._digital_out = 0
        self._digital_in = 0
        self._analog_out = (0.0, 0.0)
        self._analog_in = (0.0, 0.0)
        self._analog_io_types = 0b1111  # every channel in the voltage domain
        self._speed_slider = 1.0
        self._tool_voltage = 0
        self._registers = [0] * (REGISTER_LAST - REGISTER_FIRST + 1)
        self._callbacks: list[Callback] = []

    def locked(self) -> threading.RLock:
        """The state lock, for a group of changes others must see at once: ``with io.locked(): ...``."""
        return self._lock

    # -- change notification -------------------------------------------------------------------
    def subscribe(self, callback: Callback) -> None:
        """Call ``callback(name, value)`` after every change (names in the module docstring)."""
        if not callable(callback):
            raise ValueError(f"callback must be callable, got {callback!r}")
        with self._lock:
            self._callbacks.append(callback)

    def unsubscribe(self, callback: Callback) -> None:
        """Stop calling ``callback``; a ValueError if it was not subscribed."""
        with self._lock:
            try:
                self._callbacks.remove(callback)
            except ValueError:
                raise ValueError(f"callback {callback!r} is not subscribed") from None

    def _notify(self, name: str, value: Any) -> None:
        for cb in list(self._callbacks):
            cb(name, value)

    # -- digital I/O ---------------------------------------------------------------------------
    @property
    def digital_out(self) -> int:
        """All 18 digital output bits (0-7 standard, 8-15 configurable, 16-17 tool)."""
        with self._lock:
            return self._digital_out

    @property
    def digital_in(self) -> int:
        """All 18 digital input bits (0-7 standard, 8-15 configurable, 16-17 tool)."""
        with self._lock:
            return self._digital_in

    def set_digital_out(self, mask: int, value: int) -> None:
        """Set the output bits under ``mask`` to ``value``'s bits; the others keep their state."""
        m = _bits(mask, "digital output mask")
        v = _bits(value, "digital output value")
        with self._lock:
            new = (self._digital_out & ~m) | (v & m)
            if new != self._digital_out:
                self._digital_out = new
                self._notify("digital_out", new)

    def set_digital_in(self, mask: int, value: int) -> None:
        """Set the input bits under ``mask`` to ``value``'s bits (the simulated wiring's side)."""
        m = _bits(mask, "digital input mask")
        v = _bits(value, "digital input value")
        with self._lock:
            new = (self._digital_in & ~m) | (v & m)
            if new != self._digital_in:
                self._digital_in = new
                self._notify("digital_in", new)

    # -- analog I/O ----------------------------------------------------------------------------
    @property
    def analog_out(self) -> tuple[float, float]:
        """Standard analog outputs 0 and 1 (V or A by domain)."""
        with self._lock:
            return self._analog_out

    @property
    def analog_in(self) -> tuple[float, float]:
        """Standard analog inputs 0 and 1 (V or A by domain)."""
        with self._lock:
            return self._analog_in

    @property
    def analog_io_types(self) -> int:
        """RTDE's analog_io_types: bit 0/1 analog input 0/1, bit 2/3 analog output 0/1; 1 = voltage."""
        with self._lock:
            return self._analog_io_types

    def _analog_value(self, value: Any, name: str, voltage: bool) -> float:
        v = _finite(value, name)
        lo, hi = ANALOG_VOLTAGE_RANGE if voltage else ANALOG_CURRENT_RANGE
        unit = "V (voltage domain)" if voltage else "A (current domain)"
        if not lo <= v <= hi:
            raise ValueError(f"{name} must be within {lo}..{hi} {unit}, got {v}")
        return v

    def set_analog_out(self, index: int, value: float) -> None:
        """Set standard analog output ``index`` (0 or 1) to ``value`` in its domain's unit."""
        i = _index2(index, "analog output index")
        with self._lock:
            v = self._analog_value(value, f"analog output {i}", bool(self._analog_io_types >> (2 + i) & 1))
            if v != self._analog_out[i]:
                out = list(self._analog_out)
                out[i] = v
                self._analog_out = (out[0], out[1])
                self._notify("analog_out", self._analog_out)

    def set_analog_in(self, index: int, value: float) -> None:
        """Set standard analog input ``index`` (0 or 1) to ``value`` in its domain's unit."""
        i = _index2(index, "analog input index")
        with self._lock:
            v = self._analog_value(value, f"analog input {i}", bool(self._analog_io_types >> i & 1))
            if v != self._analog_in[i]:
                vals = list(self._analog_in)
                vals[i] = v
                self._analog_in = (vals[0], vals[1])
                self._notify("analog_in", self._analog_in)

    def set_analog_domain(self, output: bool, index: int, voltage: bool) -> None:
        """Put analog output (``output``) or input ``index`` in the voltage (True) or current domain.

        The channel's value is reset to the bottom of the new domain's range.
        """
        i = _index2(index, "analog channel index")
        bit = 1 << (i + (2 if output else 0))
        with self._lock:
            new = (self._analog_io_types | bit) if voltage else (self._analog_io_types & ~bit)
            if new == self._analog_io_types:
                return
            self._analog_io_types = new
            self._notify("analog_io_types", new)
            bottom = ANALOG_VOLTAGE_RANGE[0] if voltage else ANALOG_CURRENT_RANGE[0]
            (self.set_analog_out if output else self.set_analog_in)(i, bottom)

    # -- speed slider, tool voltage ------------------------------------------------------------
    @property
    def speed_slider(self) -> float:
        """The speed slider fraction, 0..1."""
        with self._lock:
            return self._speed_slider

    def set_speed_slider(self, fraction: float) -> None:
        """Set the speed slider to ``fraction`` (0..1)."""
        f = _finite(fraction, "speed slider fraction")
        if not 0.0 <= f <= 1.0:
            raise ValueError(f"speed slider fraction must be within 0..1, got {f}")
        with self._lock:
            if f != self._speed_slider:
                self._speed_slider = f
                self._notify("speed_slider", f)

    @property
    def tool_voltage(self) -> int:
        """Tool output voltage, V (0, 12 or 24)."""
        with self._lock:
            return self._tool_voltage

    def set_tool_voltage(self, volts: int) -> None:
        """Set the tool output voltage to 0, 12 or 24 V."""
        v = _as_int(volts, "tool voltage")
        if v not in TOOL_VOLTAGES:
            raise ValueError(f"tool voltage must be one of {TOOL_VOLTAGES} V, got {v}")
        with self._lock:
            if v != self._tool_voltage:
                self._tool_voltage = v
                self._notify("tool_voltage", v)

    # -- general-purpose registers -------------------------------------------------------------
    def get_register(self, address: int) -> int:
        """Modbus general-purpose register ``address`` (128..255), uint16."""
        a = check_register_address(address)
        with self._lock:
            return self._registers[a - REGISTER_FIRST]

    def get_registers(self, address: int, count: int) -> tuple[int, ...]:
        """``count`` consecutive general-purpose registers from ``address`` (all within 128..255)."""
        a = check_register_address(address)
        n = _as_int(count, "register count")
        if n < 0 or a + n - 1 > REGISTER_LAST:
            raise ValueError(f"register count {n} from address {a} leaves {REGISTER_FIRST}..{REGISTER_LAST}")
        with self._lock:
            return tuple(self._registers[a - REGISTER_FIRST : a - REGISTER_FIRST + n])

    def set_register(self, address: int, value: int) -> None:
        """Set general-purpose register ``address`` (128..255) to ``value`` (0..65535)."""
        a = check_register_address(address)
        v = _as_int(value, f"register {a} value")
        if not 0 <= v <= 0xFFFF:
            raise ValueError(f"register {a} value must be within 0..65535 (uint16), got {v}")
        with self._lock:
            if v != self._registers[a - REGISTER_FIRST]:
                self._registers[a - REGISTER_FIRST] = v
                self._notify("register", (a, v))

    # -- recorder ------------------------------------------------------------------------------
    def snapshot(self) -> dict[str, Any]:
        """Everything above, consistent at one instant.

        Keys: digital_out, digital_in (int), analog_out, analog_in (tuple of 2 floats), analog_io_types
        (int), speed_slider (float), tool_voltage (int, V), registers (tuple of 128 ints, addresses
        128..255 in order).
        """
        with self._lock:
            return {
                "digital_out": self._digital_out,
                "digital_in": self._digital_in,
                "analog_out": self._analog_out,
                "analog_in": self._analog_in,
                "analog_io_types": self._analog_io_types,
                "speed_slider": self._speed_slider,
                "tool_voltage": self._tool_voltage,
                "registers": tuple(self._registers),
            }
