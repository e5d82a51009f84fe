"""The simulated controller's Modbus TCP server: UR's server map on pymodbus's own server.

`ModbusServerThread` serves an `IOState` (and optionally the TCP pose) with pymodbus's
``ModbusTcpServer`` and ``SimDevice``/``SimData`` datastore, in a thread with its own asyncio loop.
Reads come from the IOState (so what RTDE or a program set is seen over Modbus); writes go to it
(so RTDE sees them).

What it follows: Universal Robots' support article "Modbus server" (function codes 1-6, 15, 16; several
clients at once; exception 1 illegal function, 2 illegal data address) and its table "ModBus server
data" (support article 16377), for the addresses below. Bit layout of registers 0-3 is UR's
``[BBBBBBBBTTxxxxxx]``: bits 0-7 the box's standard I/O, bits 8-9 the tool I/O, 10-15 undefined; of
registers 30-33 ``[BBBBBBBBxxxxxxxx]``: bits 0-7 configurable I/O.

Registers (function codes 3, 4, 6, 16; holding and input registers are one table):

=========  ===  ==============================================================================
address    R/W  content
=========  ===  ==============================================================================
0          R    digital inputs (standard 0-7, tool 8-9)
1          R/W  digital outputs (standard 0-7, tool 8-9)
2          W    set-output mask: outputs under the set bits go high
3          W    clear-output mask: outputs under the set bits go low
20         R/W  tool output voltage, V: 0, 12 or 24
21         R    tool digital inputs (bits 0-1)
22         R/W  tool digital outputs (bits 0-1)
30         R    configurable inputs (bits 0-7)
31         R/W  configurable outputs (bits 0-7)
32         W    set mask of the configurable outputs
33         W    clear mask of the configurable outputs
128-255    R/W  general-purpose registers (uint16)
400-405    R    TCP pose in the base frame: x, y, z in 0.1 mm, rx, ry, rz (rotation vector) in mrad,
                as int16 two's complement in the uint16 register; only with ``tcp_pose=``
=========  ===  ==============================================================================

Coils (function codes 1, 5, 15) and discrete inputs (2, the same bit table, read-only): 16-31 the output
bits of register 1 (UR's table as quoted by a public client, libmodbus's ``tests/ur3e.c``: "16-31 Outputs,
bits 0-15 [BBBBBBBBTTxxxxxx]"; coil 16 is digital output 0), 0-15 the input bits of register 0
(read-only; by the same layout, not seen in the public excerpts of UR's table).

Answers, as UR's server gives them: an address outside the table (or a gap in it, or a range running
into one) -> exception 2 (illegal data address); a write to a read-only address -> exception 2; a value
a register cannot hold (an undefined bit set, a tool voltage other than 0/12/24), a quantity outside
1..2000 bits / 1..125 registers, or a coil value other than 0xFF00 / 0x0000 -> exception 3 (illegal data
value); any other function code pymodbus knows -> exception 1 (illegal function; a code pymodbus does
not know at all gets pymodbus's own answer, exception 1 under function code 0x80); a failing
``tcp_pose()`` -> exception 4 (server device failure). A refused request changes nothing (a write of
several registers is checked whole before any is applied), and the server keeps serving. Reading a
write-only mask register (2, 3, 32, 33) returns the mask last written there (so a write's echo is right).

Threads: requests run in the server's thread, holding the IOState's lock while they read or write it
(IOState callbacks therefore run in that thread too); ``tcp_pose()`` is called before that lock is taken.

Not simulated: UR's analog registers (4-19), Euromap67 (24-29), the robot-state registers (256-399,
410-...), and the configurable I/O as coils (UR's public table does not show their bit addresses).
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
import math
import struct
import threading
from collections.abc import Callable, Sequence

from pymodbus.constants import ExcCodes
from pymodbus.datastore import ModbusServerContext
from pymodbus.pdu import ExceptionResponse, ModbusPDU
from pymodbus.pdu.bit_message import ReadCoilsRequest, ReadDiscreteInputsRequest, WriteSingleCoilRequest
from pymodbus.pdu.decoders import DecodePDU
from pymodbus.pdu.register_message import ReadHoldingRegistersRequest, ReadInputRegistersRequest
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from planner.kinematics.ur_outputs import UR_OUTPUTS, from_modbus, from_ur_bits, to_modbus, to_ur_bits

from .io_state import REGISTER_FIRST, REGISTER_LAST, TOOL_VOLTAGES, IOState

log = logging.getLogger(__name__)

#: The function codes UR's server answers; every other one is refused with exception 1.
FUNCTION_CODES = (1, 2, 3, 4, 5, 6, 15, 16)
_COIL_FC = {1, 5, 15}
_WRITE_FC = {5, 6, 15, 16}

# register addresses: the digital outputs' (and their set / clear masks) from the UR output table
_STANDARD, _CONF, _TOOL_KIND = UR_OUTPUTS["standard"], UR_OUTPUTS["configurable"], UR_OUTPUTS["tool"]
REG_OUTPUTS, REG_SET_OUTPUTS, REG_CLEAR_OUTPUTS = (
    _STANDARD.modbus_register, _STANDARD.modbus_set_register, _STANDARD.modbus_clear_register)
REG_CONF_OUTPUTS, REG_SET_CONF, REG_CLEAR_CONF = (
    _CONF.modbus_register, _CONF.modbus_set_register, _CONF.modbus_clear_register)
REG_INPUTS, REG_CONF_INPUTS = REG_OUTPUTS - 1, REG_CONF_OUTPUTS - 1  # the inputs, in the same layouts
REG_TOOL_VOLTAGE, REG_TOOL_INPUTS, REG_TOOL_OUTPUTS = 20, 21, 22
REG_TCP_POSE = 400  # 400..405
#: First coil address of the outputs (coils 0-15 are the inputs).
COIL_OUTPUTS = 16
COIL_COUNT = 32

_READ_ONLY = (REG_INPUTS, REG_TOOL_INPUTS, REG_CONF_INPUTS)
_READ_WRITE = (REG_OUTPUTS, REG_SET_OUTPUTS, REG_CLEAR_OUTPUTS, REG_TOOL_VOLTAGE, REG_TOOL_OUTPUTS,
               REG_CONF_OUTPUTS, REG_SET_CONF, REG_CLEAR_CONF)
_BOX_AND_TOOL = from_modbus(REG_OUTPUTS, 0xFFFF)  # IOState bits of UR's [BBBBBBBBTT] layout (standard and tool)
_CONFIGURABLE = _CONF.mask
_TOOL = _TOOL_KIND.mask
#: Valid bits of each writable bit register (UR's layouts); 10 bits: standard 0-7 and tool 8-9.
_VALID_BITS = {REG_OUTPUTS: to_ur_bits(_BOX_AND_TOOL), REG_SET_OUTPUTS: to_ur_bits(_BOX_AND_TOOL),
               REG_CLEAR_OUTPUTS: to_ur_bits(_BOX_AND_TOOL), REG_TOOL_OUTPUTS: _TOOL_KIND.pin_mask,
               REG_CONF_OUTPUTS: _CONF.pin_mask, REG_SET_CONF: _CONF.pin_mask, REG_CLEAR_CONF: _CONF.pin_mask}


def _pose_registers(pose: Sequence[float]) -> list[int]:
    """TCP pose (6,) in m and rad -> six uint16 registers holding int16 of 0.1 mm and mrad."""
    values = [float(v) for v in pose]
    if len(values) != 6 or not all(math.isfinite(v) for v in values):
        raise ValueError(f"tcp_pose() must return 6 finite numbers (m, rad), got {pose!r}")
    scaled = [v * 1e4 for v in values[:3]] + [v * 1e3 for v in values[3:]]
    return [max(-32768, min(32767, round(v))) & 0xFFFF for v in scaled]


class _URMap:
    """The action behind pymodbus's datastore: refreshes reads from, and applies writes to, the IOState."""

    def __init__(self, io: IOState, tcp_pose: Callable[[], Sequence[float]] | None) -> None:
        self.io = io
        self.tcp_pose = tcp_pose
        self.masks = {REG_SET_OUTPUTS: 0, REG_CLEAR_OUTPUTS: 0, REG_SET_CONF: 0, REG_CLEAR_CONF: 0}
        self.writable = frozenset(_READ_WRITE) | frozenset(range(REGISTER_FIRST, REGISTER_LAST + 1))
        pose = range(REG_TCP_POSE, REG_TCP_POSE + 6) if tcp_pose is not None else ()
        self.readable = self.writable | frozenset(_READ_ONLY) | frozenset(pose)

    def device(self) -> SimDevice:
        """The SimDevice: four separate tables (coils, discrete inputs, holding, input registers)."""
        def registers() -> list[SimData]:
            blocks = [SimData(a, datatype=DataType.REGISTERS, readonly=True) for a in _READ_ONLY]
            blocks += [SimData(a, datatype=DataType.REGISTERS) for a in _READ_WRITE]
            blocks.append(SimData(REGISTER_FIRST, count=REGISTER_LAST - REGISTER_FIRST + 1,
                                  datatype=DataType.REGISTERS))
            if self.tcp_pose is not None:
                blocks.append(SimData(REG_TCP_POSE, count=6, datatype=DataType.REGISTERS, readonly=True))
            return blocks

        def bits() -> list[SimData]:
            return [SimData(0, values=[False] * COIL_COUNT, datatype=DataType.BITS)]

        return SimDevice(0, simdata=(bits(), bits(), registers(), registers()), action=self.action)

    # -- pymodbus's SimDevice action -------------------------------------------------------------
    async def action(self, function_code: int, start_address: int, address: int, count: int,
                     registers: list[int], set_values: list[int] | list[bool] | None) -> ExcCodes | None:
        """Apply a write to the IOState (or refuse it), then refresh the table from the IOState.

        For bit tables pymodbus passes the bit ``address`` and ``count`` in 16-bit registers; for register
        tables the register ``address`` and ``count``. ``registers`` is the table, from ``start_address``.
        """
        if function_code not in FUNCTION_CODES:
            return ExcCodes.ILLEGAL_FUNCTION
        # the whole request is checked here, before anything is applied, whatever checks pymodbus makes
        # around this call (they moved from after it to before it between pymodbus 3.15 and 3.16)
        if function_code in _COIL_FC:
            if set_values is not None and function_code in _WRITE_FC and \
                    not COIL_OUTPUTS <= address <= address + len(set_values) <= COIL_COUNT:
                return ExcCodes.ILLEGAL_ADDRESS
        elif function_code != 2:
            writing = set_values is not None and function_code in _WRITE_FC
            n = len(set_values) if set_values is not None and writing else count
            allowed = self.writable if writing else self.readable
            if not all(a in allowed for a in range(address, address + n)):
                return ExcCodes.ILLEGAL_ADDRESS
        try:
            # the pose first, outside the IOState's lock (tcp_pose may take the motion model's lock, and the
            # motion model may read the IOState under it: never hold both in opposite orders)
            pose = None
            if self.tcp_pose is not None and function_code in (3, 4) and \
                    address <= REG_TCP_POSE + 5 and REG_TCP_POSE < address + count:
                pose = _pose_registers(self.tcp_pose())
            with self.io.locked():
                if function_code in _COIL_FC:
                    if set_values is not None and function_code in _WRITE_FC:
                        if (exc := self._write_coils(address, [bool(v) for v in set_values])) is not None:
                            return exc
                    self._refresh_bits(registers, start_address)
                elif function_code == 2:
                    self._refresh_bits(registers, start_address)
                else:
                    if set_values is not None and function_code in _WRITE_FC:
                        if (exc := self._write_registers(address, [int(v) for v in set_values])) is not None:
                            return exc
                    self._refresh_registers(registers, start_address, address, count, pose)
        except Exception:  # a fault of ours or of tcp_pose(): answer "server device failure", keep serving
            log.exception("Modbus request fc=%d address=%d count=%d failed", function_code, address, count)
            return ExcCodes.DEVICE_FAILURE
        return None

    def _refresh_bits(self, registers: list[int], start: int) -> None:
        registers[0 - start] = to_ur_bits(self.io.digital_in)
        registers[1 - start] = to_ur_bits(self.io.digital_out)

    def _refresh_registers(self, registers: list[int], start: int, address: int, count: int,
                           pose: list[int] | None) -> None:
        end = address + count

        def wanted(first: int, last: int) -> bool:
            return address <= last and first < end

        io = self.io
        simple = {
            REG_INPUTS: lambda: to_ur_bits(io.digital_in),
            REG_OUTPUTS: lambda: to_ur_bits(io.digital_out),
            REG_TOOL_VOLTAGE: lambda: io.tool_voltage,
            REG_TOOL_INPUTS: lambda: _TOOL_KIND.pins_of(io.digital_in),
            REG_TOOL_OUTPUTS: lambda: _TOOL_KIND.pins_of(io.digital_out),
            REG_CONF_INPUTS: lambda: to_modbus(io.digital_in, REG_CONF_OUTPUTS),
            REG_CONF_OUTPUTS: lambda: to_modbus(io.digital_out, REG_CONF_OUTPUTS),
        }
        for reg, get in simple.items():
            if wanted(reg, reg):
                registers[reg - start] = get()
        for reg, mask in self.masks.items():
            if wanted(reg, reg):
                registers[reg - start] = mask
        if wanted(REGISTER_FIRST, REGISTER_LAST):
            n = REGISTER_LAST - REGISTER_FIRST + 1
            registers[REGISTER_FIRST - start : REGISTER_FIRST - start + n] = io.get_registers(REGISTER_FIRST, n)
        if pose is not None:
            registers[REG_TCP_POSE - start : REG_TCP_POSE - start + 6] = pose

    def _write_coils(self, address: int, values: list[bool]) -> ExcCodes | None:
        """Coils ``address`` .. ``address + len(values) - 1`` (pymodbus checked the table's bounds)."""
        mask = value = 0
        for i, bit in enumerate(values):
            ur_bit = address - COIL_OUTPUTS + i
            if not (_VALID_BITS[REG_OUTPUTS] >> ur_bit) & 1:
                if bit:
                    return ExcCodes.ILLEGAL_VALUE  # an undefined output bit
                continue
            mask |= 1 << ur_bit
            value |= int(bool(bit)) << ur_bit
        self.io.set_digital_out(from_ur_bits(mask), from_ur_bits(value))
        return None

    def _write_registers(self, address: int, values: list[int]) -> ExcCodes | None:
        """Registers from ``address``; every value is checked before any is applied."""
        for i, v in enumerate(values):
            reg = address + i
            if reg in _VALID_BITS and v & ~_VALID_BITS[reg]:
                return ExcCodes.ILLEGAL_VALUE
            if reg == REG_TOOL_VOLTAGE and v not in TOOL_VOLTAGES:
                return ExcCodes.ILLEGAL_VALUE
        io = self.io
        for i, v in enumerate(values):
            reg = address + i
            if reg == REG_OUTPUTS:
                io.set_digital_out(_BOX_AND_TOOL, from_ur_bits(v))
            elif reg == REG_SET_OUTPUTS:
                io.set_digital_out(from_ur_bits(v), from_ur_bits(v))
            elif reg == REG_CLEAR_OUTPUTS:
                io.set_digital_out(from_ur_bits(v), 0)
            elif reg == REG_TOOL_VOLTAGE:
                io.set_tool_voltage(v)
            elif reg == REG_TOOL_OUTPUTS:
                io.set_digital_out(_TOOL, v << _TOOL_KIND.bit_offset)
            elif reg == REG_CONF_OUTPUTS:
                io.set_digital_out(_CONFIGURABLE, from_modbus(REG_CONF_OUTPUTS, v))
            elif reg == REG_SET_CONF:
                io.set_digital_out(from_modbus(REG_CONF_OUTPUTS, v), from_modbus(REG_CONF_OUTPUTS, v))
            elif reg == REG_CLEAR_CONF:
                io.set_digital_out(from_modbus(REG_CONF_OUTPUTS, v), 0)
            elif REGISTER_FIRST <= reg <= REGISTER_LAST:
                io.set_register(reg, v)
            if reg in self.masks:
                self.masks[reg] = v
        return None


def _strict_read(base: type[ModbusPDU]) -> type[ModbusPDU]:
    """``base`` (a read request) answering a quantity outside 1..MAX_COUNT with exception 3 (the spec's
    answer; pymodbus's own request class fails to decode it and answers with function code 0x80)."""

    class StrictRead(base):  # type: ignore[valid-type, misc]
        def decode(self, data: bytes) -> None:
            self.address, self.count = struct.unpack(">HH", data[:4])

        async def datastore_update(self, context: ModbusServerContext, device_id: int) -> ModbusPDU:
            if not 1 <= self.count <= self.MAX_COUNT:
                return ExceptionResponse(self.function_code, ExcCodes.ILLEGAL_VALUE)
            return await super().datastore_update(context, device_id)

    StrictRead.__name__ = StrictRead.__qualname__ = f"Strict{base.__name__}"
    return StrictRead


class _StrictWriteCoil(WriteSingleCoilRequest):
    """Write single coil answering a value other than 0xFF00 / 0x0000 with exception 3, as the spec says
    (pymodbus's own class takes any non-zero value as on)."""

    def decode(self, data: bytes) -> None:
        self.address, self.raw_value = struct.unpack(">HH", data[:4])
        self.bits = [self.raw_value == 0xFF00]

    async def datastore_update(self, context: ModbusServerContext, device_id: int) -> ModbusPDU:
        if self.raw_value not in (0xFF00, 0x0000):
            return ExceptionResponse(self.function_code, ExcCodes.ILLEGAL_VALUE)
        return await super().datastore_update(context, device_id)


def _refused_pdu(function_code: int) -> type[ModbusPDU]:
    """A request class for ``function_code`` that UR's server does not offer: answered with exception 1."""

    class Refused(ModbusPDU):
        async def datastore_update(self, context: ModbusServerContext, device_id: int) -> ModbusPDU:
            return ExceptionResponse(self.function_code, ExcCodes.ILLEGAL_FUNCTION)

    Refused.function_code = function_code
    Refused.__name__ = Refused.__qualname__ = f"RefusedFunction{function_code}"
    return Refused


def _check_host(host: str, allow_remote: bool) -> str:
    try:
        ip = ipaddress.ip_address(host)
    except ValueError:
        raise ValueError(f"Modbus host must be an IP address, got {host!r}") from None
    if not ip.is_loopback and not allow_remote:
        raise ValueError(f"Modbus host {host} is not a loopback address (127.0.0.0/8, ::1); "
                         "pass allow_remote=True to serve it anyway")
    return host


class ModbusServerThread:
    """UR's Modbus TCP server for one simulated controller, in a thread with its own asyncio loop.

    ``io``: the controller's IOState. ``host``: the one address to bind (loopback unless ``allow_remote``).
    ``port``: TCP port (0 picks a free one; read `port` after `wait_ready`). ``tcp_pose``: optional callable
    returning the TCP pose (6,) in m and rad (rotation vector) for registers 400-405; it is called from the
    server's thread and must be thread-safe. Use as a context manager, or `start` / `wait_ready` / `stop`.
    """

    def __init__(self, io: IOState, host: str, port: int,
                 tcp_pose: Callable[[], Sequence[float]] | None = None, *, allow_remote: bool = False) -> None:
        if not isinstance(io, IOState):
            raise ValueError(f"io must be an IOState, got {type(io).__name__}")
        self.host = _check_host(host, allow_remote)
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise ValueError(f"Modbus port must be an integer within 0..65535, got {port!r}")
        if tcp_pose is not None and not callable(tcp_pose):
            raise ValueError(f"tcp_pose must be callable or None, got {tcp_pose!r}")
        self.port = port
        self._map = _URMap(io, tcp_pose)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._stop_event = asyncio.Event()
        self._ready = threading.Event()
        self._error: BaseException | None = None

    # -- lifecycle ------------------------------------------------------------------------------
    def start(self) -> None:
        """Start serving in a new thread (returns at once; `wait_ready` waits until it serves)."""
        if self._thread is not None:
            raise RuntimeError("this Modbus server was already started (make a new one to serve again)")
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._run, name=f"modbus-{self.host}:{self.port}", daemon=True)
        self._thread.start()

    def wait_ready(self, timeout: float) -> None:
        """Return once the server listens; raise if it failed to, or is not listening after ``timeout`` s."""
        if self._thread is None:
            raise RuntimeError("the Modbus server was not started")
        if not self._ready.wait(timeout):
            raise TimeoutError(f"Modbus server on {self.host}:{self.port} not serving after {timeout} s")
        if self._error is not None:
            raise RuntimeError(f"Modbus server on {self.host}:{self.port} failed: {self._error}") from self._error

    @property
    def serving(self) -> bool:
        """True while the server listens."""
        return self._ready.is_set() and self._error is None and self._thread is not None \
            and self._thread.is_alive() and not self._stop_event.is_set()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop serving: close the listening socket and every client connection, end the thread."""
        if self._thread is None:
            return
        loop = self._loop
        if loop is not None and self._thread.is_alive():
            try:
                loop.call_soon_threadsafe(self._stop_event.set)
            except RuntimeError:  # the loop already closed (the server failed to start)
                pass
        self._thread.join(timeout)
        if self._thread.is_alive():
            raise RuntimeError(f"Modbus server on {self.host}:{self.port} did not stop within {timeout} s")

    def __enter__(self) -> ModbusServerThread:
        self.start()
        try:
            self.wait_ready(10.0)
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop()

    # -- the server's thread --------------------------------------------------------------------
    def _run(self) -> None:
        loop = self._loop
        assert loop is not None
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(self._serve())
        except BaseException as exc:  # noqa: BLE001 - reported through wait_ready
            self._error = exc
        finally:
            self._ready.set()
            try:
                loop.run_until_complete(loop.shutdown_asyncgens())
            finally:
                loop.close()

    async def _serve(self) -> None:
        server = ModbusTcpServer(self._map.device(), address=(self.host, self.port))
        # UR answers function codes 1-6, 15, 16 only; pymodbus's other ones are answered with exception 1
        for fc in sorted(set(DecodePDU.pdu_table) - set(FUNCTION_CODES)):
            server.decoder.register(_refused_pdu(fc))
        for request in (ReadCoilsRequest, ReadDiscreteInputsRequest, ReadHoldingRegistersRequest,
                        ReadInputRegistersRequest):
            server.decoder.register(_strict_read(request))
        server.decoder.register(_StrictWriteCoil)
        if not await server.listen():
            raise OSError(f"cannot listen on {self.host}:{self.port} (port in use, or not an address of this host)")
        # pymodbus keeps its listener in ``transport`` (typed as a transport): the asyncio.Server that
        # loop.create_server returned
        listener = server.transport
        if not isinstance(listener, asyncio.Server):
            raise OSError(f"Modbus on {self.host}:{self.port}: pymodbus gave no TCP listener ({type(listener)})")
        try:
            self.port = listener.sockets[0].getsockname()[1]
            self._ready.set()
            await self._stop_event.wait()
        finally:
            await server.shutdown()
            listener.close()
            await listener.wait_closed()
