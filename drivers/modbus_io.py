"""Tool I/O through a UR controller's Modbus TCP server (or a Modbus device with UR's map): a pymodbus client.

`ModbusToolIO` sets and reads the robot's digital outputs at the addresses of UR's Modbus server (the map
:mod:`sim.modbus` serves; Universal Robots' support article "Modbus server"):

=========  ==============================================================================================
register   content
=========  ==============================================================================================
0          digital inputs, UR layout ``[BBBBBBBBTTxxxxxx]``: standard 0-7 in bits 0-7, tool 0-1 in bits 8-9
1          digital outputs, same layout
2 / 3      set / clear masks of the outputs of register 1 (write-only): the bits under the mask go high / low
30         configurable inputs (bits 0-7)
31         configurable outputs (bits 0-7)
32 / 33    set / clear masks of the configurable outputs
=========  ==============================================================================================

Outputs are switched through the set / clear mask registers only (never a read-modify-write of register 1 or
31), so a switch never undoes an output that a program or another client changed meanwhile. Words exchanged with
the caller use the driver layer's 18-bit layout (RTDE's ``actual_digital_output_bits``): bits 0-7 standard, 8-15
configurable, 16-17 tool. Kinds, pins, bits and the outputs' registers are the UR output table's
(:mod:`planner.kinematics.ur_outputs`).

Errors are :class:`ModbusIOError` (the device answered with a Modbus exception, or no answer came) and
:class:`ModbusConnectionError` (cannot connect, or the connection dropped; also a
:class:`drivers.base.ConnectionLostError`); both name the host, port, function and register addresses.
A request is never retried silently (``retries=0``): an output switch that failed is reported, not repeated.
"""

from __future__ import annotations

import ipaddress
import math
import operator
import socket
import threading
import warnings

import numpy as np
from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ModbusException

from drivers.base import ConnectionLostError, DriverError
from planner.kinematics.ur_outputs import (
    DIGITAL_MASK,
    UR_OUTPUTS,
    from_ur_bits,
    output_bit,
    to_modbus,
    to_ur_bits,  # noqa: F401  (importable from here, as before)
)

# UR's register addresses: the outputs' from the UR output table, the inputs' beside them
_STANDARD, _CONFIGURABLE = UR_OUTPUTS["standard"], UR_OUTPUTS["configurable"]
REG_OUTPUTS, REG_SET_OUTPUTS, REG_CLEAR_OUTPUTS = (
    _STANDARD.modbus_register, _STANDARD.modbus_set_register, _STANDARD.modbus_clear_register)
REG_CONF_OUTPUTS, REG_SET_CONF, REG_CLEAR_CONF = (
    _CONFIGURABLE.modbus_register, _CONFIGURABLE.modbus_set_register, _CONFIGURABLE.modbus_clear_register)
REG_INPUTS, REG_CONF_INPUTS = REG_OUTPUTS - 1, REG_CONF_OUTPUTS - 1
#: The groups of outputs switched by one request each: (state register, set-mask register, clear-mask register).
_GROUPS = tuple(dict.fromkeys((k.modbus_register, k.modbus_set_register, k.modbus_clear_register)
                              for k in UR_OUTPUTS.values()))



def __getattr__(name: str):
    if name == "OUTPUT_KINDS":  # kind -> (first bit, pins): now columns of the UR output table
        warnings.warn("drivers.modbus_io.OUTPUT_KINDS is deprecated and will be removed in the release after the next "
                      "one: use planner.kinematics.ur_outputs.UR_OUTPUTS (kind -> bit_offset, pins, ...)",
                      DeprecationWarning, stacklevel=2)
        return {k.name: (k.bit_offset, k.pins) for k in UR_OUTPUTS.values()}
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: Modbus exception codes and their names (Modbus application protocol v1.1b3, section 7).
EXCEPTION_NAMES = {
    1: "illegal function", 2: "illegal data address", 3: "illegal data value", 4: "server device failure",
    5: "acknowledge", 6: "server device busy", 8: "memory parity error", 10: "gateway path unavailable",
    11: "gateway target device failed to respond",
}

_REGISTER_NAMES = {
    REG_INPUTS: "digital inputs", REG_OUTPUTS: "digital outputs", REG_SET_OUTPUTS: "set-output mask",
    REG_CLEAR_OUTPUTS: "clear-output mask", REG_CONF_INPUTS: "configurable inputs",
    REG_CONF_OUTPUTS: "configurable outputs", REG_SET_CONF: "configurable set mask",
    REG_CLEAR_CONF: "configurable clear mask",
}


class ModbusIOError(DriverError):
    """The Modbus device refused a request (an exception response) or did not answer it."""

    kind = "tool I/O"


class ModbusConnectionError(ModbusIOError, ConnectionLostError):
    """No connection to the Modbus device (refused, unreachable, timed out) or it dropped."""

    kind = "tool I/O connection"


def _int(value, name: str) -> int:
    if isinstance(value, bool):
        return int(value)
    try:
        return operator.index(value)
    except TypeError:
        raise ValueError(f"{name} must be an integer, got {value!r} ({type(value).__name__})") from None


def _word(value, name: str) -> int:
    v = _int(value, name)
    if not 0 <= v <= DIGITAL_MASK:
        raise ValueError(f"{name} must be within 0..0x{DIGITAL_MASK:X} (18 digital bits: standard 0-7, "
                         f"configurable 8-15, tool 16-17), got {v}")
    return v


def _registers(first: int, n: int) -> str:
    names = ", ".join(_REGISTER_NAMES.get(a, "?") for a in range(first, first + n))
    where = f"register {first}" if n == 1 else f"registers {first}-{first + n - 1}"
    return f"{where} ({names})"


class ModbusToolIO:
    """Digital outputs of a UR robot through its Modbus TCP server (a pymodbus ``ModbusTcpClient``).

    Parameters
    ----------
    host : str
        The controller's (or the Modbus device's) address; the client connects to this host only.
    port : int
        Modbus TCP port (UR: 502).
    unit : int
        Modbus unit (device) id sent with each request, 0..255 (UR's server answers any).
    timeout : float
        Seconds to wait for the connection and for each answer.

    Connects on first use (or :meth:`connect`); use as a context manager or call :meth:`close`. Thread-safe:
    one request at a time.
    """

    def __init__(self, host: str, port: int = 502, *, unit: int = 1, timeout: float = 2.0) -> None:
        if not isinstance(host, str) or not host.strip():
            raise ValueError(f"Modbus host must be a non-empty host name or IP address, got {host!r}")
        self.host = host.strip()
        try:
            self.host = str(ipaddress.ip_address(self.host))
        except ValueError:
            pass  # a host name: resolved when connecting
        p = _int(port, "Modbus port")
        if not 1 <= p <= 65535:
            raise ValueError(f"Modbus port must be within 1..65535, got {p}")
        self.port = p
        u = _int(unit, "Modbus unit id")
        if not 0 <= u <= 255:
            raise ValueError(f"Modbus unit id must be within 0..255, got {u}")
        self.unit = u
        try:
            t = float(timeout)
        except (TypeError, ValueError):
            raise ValueError(f"Modbus timeout must be a number of seconds, got {timeout!r}") from None
        if not (math.isfinite(t) and t > 0):
            raise ValueError(f"Modbus timeout must be > 0 s, got {timeout!r}")
        self.timeout = t
        self._client: ModbusTcpClient | None = None
        self._lock = threading.Lock()

    @property
    def where(self) -> str:
        """``host:port`` of the device, for messages."""
        return f"{self.host}:{self.port}"

    # -- connection ------------------------------------------------------------------------------
    def connect(self) -> None:
        """Open the connection (a no-op when open); :class:`ModbusConnectionError` when it cannot."""
        with self._lock:
            self._connect()

    def _connect(self) -> ModbusTcpClient:
        if self._client is not None and self._client.connected:
            return self._client
        client = ModbusTcpClient(self.host, port=self.port, timeout=self.timeout, retries=0)
        if not client.connect():
            client.close()
            raise ModbusConnectionError(f"cannot connect to the Modbus server at {self.where}: {self._why()}")
        self._client = client
        return client

    def _why(self) -> str:
        """The operating system's reason a connection to the device fails (pymodbus only logs it)."""
        try:
            with socket.create_connection((self.host, self.port), timeout=self.timeout):
                return "the connection failed once, then succeeded (the server is flaky or was starting)"
        except OSError as exc:
            return exc.strerror or str(exc) or type(exc).__name__

    def close(self) -> None:
        """Close the connection (the outputs keep their state)."""
        with self._lock:
            if self._client is not None:
                self._client.close()
                self._client = None

    @property
    def connected(self) -> bool:
        return self._client is not None and self._client.connected

    def __enter__(self) -> ModbusToolIO:
        self.connect()
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"ModbusToolIO({self.host!r}, {self.port}, unit={self.unit})"

    # -- requests --------------------------------------------------------------------------------
    def _request(self, what: str, first: int, n: int, call):
        """Run ``call(client)``; Modbus exception responses and failures become errors naming the registers."""
        with self._lock:
            client = self._connect()
            try:
                response = call(client)
            except ModbusException as exc:
                self._drop()
                text = str(exc)
                cls = ModbusConnectionError if "connect" in text.lower() or not client.connected \
                    else ModbusIOError
                raise cls(f"Modbus {what} {_registers(first, n)} at {self.where} failed: {text}") from exc
            except OSError as exc:
                self._drop()
                raise ModbusConnectionError(f"Modbus {what} {_registers(first, n)} at {self.where}: connection "
                                            f"lost ({exc.strerror or exc})") from exc
        if response.isError():
            code = getattr(response, "exception_code", None)
            name = EXCEPTION_NAMES.get(code, "unknown exception") if code is not None else str(response)
            raise ModbusIOError(f"Modbus {what} {_registers(first, n)} at {self.where} refused: exception "
                                f"{code} ({name})")
        return response

    def _drop(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None

    def _write(self, first: int, values: list[int]) -> None:
        self._request("write of", first, len(values),
                      lambda c: c.write_registers(first, values, device_id=self.unit))

    def _read(self, first: int) -> int:
        r = self._request("read of", first, 1, lambda c: c.read_holding_registers(first, count=1,
                                                                                    device_id=self.unit))
        if len(r.registers) != 1:
            raise ModbusIOError(f"Modbus read of {_registers(first, 1)} at {self.where}: expected 1 register, "
                                f"got {len(r.registers)}")
        return int(r.registers[0])

    # -- outputs ---------------------------------------------------------------------------------
    def set_bits(self, mask: int, value: int) -> None:
        """Set the outputs under ``mask`` to ``value``'s bits (18-bit words: standard 0-7, configurable 8-15,
        tool 16-17); the other outputs keep their state.

        One Modbus request per group touched: registers 2-3 (standard and tool: set mask, then clear mask) and
        registers 32-33 (configurable).
        """
        m = _word(mask, "output mask")
        v = _word(value, "output value")
        on, off = m & v, m & ~v
        for reg, set_reg, _clear_reg in _GROUPS:  # the clear-mask register follows the set-mask register
            if to_modbus(m, reg):
                self._write(set_reg, [to_modbus(on, reg), to_modbus(off, reg)])

    def set_output(self, kind: str, pin: int, value: bool) -> None:
        """Switch output ``pin`` of ``kind`` ("standard" 0-7, "configurable" 0-7, "tool" 0-1) on or off."""
        bit = 1 << output_bit(kind, pin)
        if isinstance(value, bool | np.bool_):
            on = bool(value)
        else:
            try:
                on = operator.index(value)
            except TypeError:
                on = -1
            if on not in (0, 1):
                raise ValueError(f"{kind} output {pin} value must be True/False (or 1/0), got {value!r}")
        self.set_bits(bit, bit if on else 0)

    def read_outputs(self) -> int:
        """All digital outputs as an 18-bit word (standard 0-7, configurable 8-15, tool 16-17)."""
        return from_ur_bits(self._read(REG_OUTPUTS), self._read(REG_CONF_OUTPUTS))

    def read_inputs(self) -> int:
        """All digital inputs as an 18-bit word (standard 0-7, configurable 8-15, tool 16-17)."""
        return from_ur_bits(self._read(REG_INPUTS), self._read(REG_CONF_INPUTS))
