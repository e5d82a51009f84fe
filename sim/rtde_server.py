"""RTDE server (TCP 30004): protocol negotiation, recipes, start/pause, data packages, text messages.

Behaviour as ur_rtde 1.6.5 needs it (src/rtde.cpp): every setup request gets exactly one reply
package; output recipes answer ``NOT_FOUND`` for unknown names, input recipes ``IN_USE`` for fields
another connection owns (recipe id 0 then); recipe ids count 1, 2, 3 ... per connection; data
packages ('U') are accepted before 'S' (RTDEIOInterface never starts). Output packages go out at the
recipe's frequency, on the controller's absolute 500 Hz schedule, only while the connection is started.

The controller's version (:attr:`sim.core.Core.version`) is what ``get_urcontrol_version`` answers, and it decides
which fields exist: a field newer than it answers ``NOT_FOUND`` in an output or input recipe (recipe id 0), as an
unknown name does (:func:`sim.rtde_fields.output_type`, :func:`sim.rtde_fields.input_type`).

Protocol versions (the RTDE guide's, as UR's C++ client library speaks them): a connection speaks version 1
until the client asks for version 2 ('V'); a version other than 1 or 2, or a change of version once a recipe is set
up or the synchronization started, is refused (0) and the connection keeps its version. In version 1 an output
setup carries no frequency (outputs every control period, 500 Hz) and its answer no recipe id, the connection has
one output recipe (a new setup replaces it), output data packages carry no recipe id, text messages are ``uint8
level`` + text, and a text message from the client is answered with an error (version 1's go to the client only).

Malformed input, answered as a controller does without disturbing other clients: a package shorter
than its header or larger than its stream allows closes that connection; an unknown package type, a
data package for an unknown recipe or one shorter than its recipe gets an error text message ('M')
and is ignored; a data package longer than its recipe is applied (its recipe's fields) with a warning.
"""

from __future__ import annotations

import collections
import math
import os
import socket
import struct
import threading
import time
from collections.abc import Callable

from planner._deprecated import module_getattr
from planner.kinematics.ur_outputs import UR_OUTPUTS
from sim import rtde_protocol as rp
from sim.hosts import set_realtime_priority
from sim.rtde_fields import INPUTS, Snapshot, compile_packer, input_type, output_type
from sim.streams import OutputStream

MAX_FREQUENCY = 500.0


class Connection(OutputStream):
    """One RTDE client connection: its recipes, its started flag, its buffered output."""

    def __init__(self, server: RTDEServer, sock: socket.socket, addr) -> None:
        super().__init__(sock)
        self.server = server
        self.addr = addr
        # recipe, its data package's packer (header and recipe id byte included, :func:`data_packer`), phase
        self.outputs: list[tuple[rp.Recipe, Callable[[Snapshot], bytes], float]] = []
        self.inputs: dict[int, rp.Recipe] = {}
        self.next_output_id = 1
        self.next_input_id = 1
        self.started = False
        self.protocol = 1  # RTDE protocol version; 2 once the client asked for it

    def text(self, message: str, level: int = rp.ERROR, source: str = "RTDE") -> None:
        """Send a text message in the connection's protocol version."""
        self.write(rp.text_message(message, source, level, self.protocol))

    # ---- input -------------------------------------------------------------------------------
    def serve(self) -> None:
        """Read packages until the client leaves (runs in its own thread)."""
        if os.sched_getscheduler(0) == os.SCHED_FIFO:
            set_realtime_priority(8)  # below the control loop, above the rest: inputs arrive on time
        buf = bytearray()
        try:
            while not self.closed:
                try:
                    chunk = self.sock.recv(65536)
                except OSError:
                    break
                if not chunk:
                    break
                buf += chunk
                while len(buf) >= rp.HEADER_SIZE:
                    size, kind = rp.HEADER.unpack_from(buf)
                    if size < rp.HEADER_SIZE:
                        self.text(f"malformed package: size {size} < header size 3", level=rp.EXCEPTION)
                        return
                    if len(buf) < size:
                        break
                    payload = bytes(buf[rp.HEADER_SIZE : size])
                    del buf[:size]
                    self.handle(kind, payload)
        finally:
            self.server.drop(self)

    def handle(self, kind: int, payload: bytes) -> None:
        """Answer one package."""
        if kind == rp.REQUEST_PROTOCOL_VERSION:
            version = struct.unpack(">H", payload)[0] if len(payload) == 2 else 0
            # a recipe's layout depends on the version: no change once one is set up or the synchronization started
            ok = version in rp.PROTOCOL_VERSIONS and (version == self.protocol or not (
                self.outputs or self.inputs or self.started))
            if ok:
                self.protocol = version
            self.write(rp.package(kind, bytes([1 if ok else 0])))
        elif kind == rp.GET_URCONTROL_VERSION:
            self.write(rp.package(kind, struct.pack(">IIII", *self.server.core.version.words)))
        elif kind == rp.SETUP_OUTPUTS:
            self._setup_outputs(payload)
        elif kind == rp.SETUP_INPUTS:
            self._setup_inputs(payload)
        elif kind == rp.START:
            self.started = bool(self.outputs)
            self.write(rp.package(kind, bytes([1 if self.started else 0])))
        elif kind == rp.PAUSE:
            self.started = False
            self.write(rp.package(kind, bytes([1])))
        elif kind == rp.DATA_PACKAGE:
            self._data(payload)
        elif kind == rp.TEXT_MESSAGE:
            if self.protocol == 1:  # version 1's text messages go from the controller to the client only
                self.text("a text message from the client needs RTDE protocol version 2")
            # version 2: clients may log to the controller
        else:
            self.text(f"unknown package type {kind}")

    @staticmethod
    def _names(text: bytes) -> tuple[str, ...]:
        return tuple(n.strip() for n in text.decode("ascii", "replace").split(",") if n.strip())

    def _setup_outputs(self, payload: bytes) -> None:
        if self.protocol == 1:  # names only; outputs every control period; one recipe, answered without its id
            freq, names = MAX_FREQUENCY, self._names(payload)
        elif len(payload) < 8:
            self.write(rp.package(rp.SETUP_OUTPUTS, bytes([0])))
            return
        else:
            (freq,) = struct.unpack_from(">d", payload)
            names = self._names(payload[8:])
        types = tuple(output_type(n, self.server.core.version) for n in names)
        ok = bool(names) and all(t != "NOT_FOUND" for t in types) and 0.0 < freq
        rid = self.next_output_id if ok else 0
        if ok:
            self.next_output_id += 1
            recipe = rp.Recipe(rid, names, types, min(freq, MAX_FREQUENCY))
            packer = data_packer(recipe, self.protocol)
            if self.protocol == 1:
                with self.server.core.lock:  # not while the control loop sends this connection's packages
                    self.outputs[:] = [(recipe, packer, 0.0)]
            else:
                self.outputs.append((recipe, packer, 0.0))
        answer = ",".join(types).encode()
        self.write(rp.package(rp.SETUP_OUTPUTS, answer if self.protocol == 1 else bytes([rid]) + answer))

    def _setup_inputs(self, payload: bytes) -> None:
        names = self._names(payload)
        with self.server.owner_lock:
            types = []
            for n in names:
                t = input_type(n, self.server.core.version)
                owner = self.server.owners.get(n)
                if t != "NOT_FOUND" and owner is not None and owner is not self:
                    t = "IN_USE"
                types.append(t)
            ok = bool(names) and all(t in rp.TYPE_CODES for t in types)
            rid = self.next_input_id if ok else 0
            if ok:
                self.next_input_id += 1
                for n in names:
                    self.server.owners[n] = self
                self.inputs[rid] = rp.Recipe(rid, names, tuple(types))
        self.write(rp.package(rp.SETUP_INPUTS, bytes([rid]) + ",".join(types).encode()))

    def _data(self, payload: bytes) -> None:
        if not payload:
            self.text("data package without recipe id")
            return
        rid = payload[0]
        recipe = self.inputs.get(rid)
        if recipe is None:
            self.text(f"data package for unknown input recipe id {rid}")
            return
        layout = recipe.struct
        body = payload[1:]
        if len(body) < layout.size:
            self.text(f"data package for input recipe {rid} has {len(body)} bytes, the recipe needs {layout.size}")
            return
        if len(body) > layout.size:
            self.text(f"data package for input recipe {rid} has {len(body)} bytes, the recipe needs {layout.size}; "
                      "extra bytes ignored", level=rp.WARNING)
        values = rp.unflatten(recipe.types, layout.unpack_from(body))
        self.server.receive_inputs(dict(zip(recipe.names, values, strict=True)))


def data_packer(recipe: rp.Recipe, protocol: int) -> Callable[[Snapshot], bytes]:
    """The function of a :class:`sim.rtde_fields.Snapshot` giving output ``recipe``'s whole data package ('U') in
    RTDE protocol version ``protocol`` (version 2: the recipe id after the header)."""
    head = (recipe.recipe_id,) if protocol == 2 else ()
    layout = struct.Struct(rp.HEADER.format + "B" * len(head) + recipe.struct.format[1:])
    return compile_packer(layout, (layout.size, rp.DATA_PACKAGE, *head), recipe.names)


class RTDEServer:
    """The RTDE listener of one simulated controller.

    Parameters
    ----------
    core : sim.core.Core
    host : str
        Address to bind (port 30004).
    """

    def __init__(self, core, host: str, port: int = 30004) -> None:
        self.core = core
        self.sock = socket.create_server((host, port), reuse_port=False)
        self.conns: list[Connection] = []
        self.owners: dict[str, Connection] = {}
        self.owner_lock = threading.Lock()
        self.ticks = 0
        # data packages received and not yet applied: (perf_counter on arrival, fields), applied by the control
        # loop before the period they arrived in (:meth:`apply_received`)
        self._received: collections.deque[tuple[float, dict]] = collections.deque()
        self._thread = threading.Thread(target=self._accept, name="rtde-accept", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def _accept(self) -> None:
        while True:
            try:
                sock, addr = self.sock.accept()
            except OSError:
                return
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            conn = Connection(self, sock, addr)
            with self.owner_lock:
                self.conns.append(conn)
            threading.Thread(target=conn.serve, name=f"rtde-{addr[1]}", daemon=True).start()

    def drop(self, conn: Connection) -> None:
        """A connection ended: release its inputs."""
        conn.close()
        with self.owner_lock:
            if conn in self.conns:
                self.conns.remove(conn)
            for name in [n for n, c in self.owners.items() if c is conn]:
                del self.owners[name]

    def close(self) -> None:
        self.sock.close()
        for c in list(self.conns):
            c.close()

    # ---- inputs ------------------------------------------------------------------------------
    def receive_inputs(self, fields: dict) -> None:
        """One data package's fields, stamped with their arrival: the control loop applies them in their period.

        A controller that never stalls applies each package in the period it arrives in. When this process is
        held up (a shared machine stalls it for tens of ms now and then), the loop integrates the missed periods
        afterwards; stamping the packages lets each of those periods see the inputs that had arrived by its time,
        instead of all of them seeing the newest (a servo stream's targets would jump by the whole stall)."""
        self._received.append((time.perf_counter(), fields))

    def apply_received(self, until: float = math.inf) -> int:
        """Apply the data packages received by ``until`` (perf_counter s) in arrival order (the control loop,
        holding ``core.lock``, before each period's ticks); returns how many."""
        received = self._received
        n = 0
        while received and received[0][0] <= until:
            self.apply_inputs(received.popleft()[1])
            n += 1
        return n

    def apply_inputs(self, fields: dict) -> None:
        """One data package's fields into the controller (registers and I/O), atomically."""
        core = self.core
        regs = core.registers
        io = core.io
        with core.lock:
            for name, value in fields.items():
                core.input_time[name] = core.time
                if name.startswith("input_int_register_"):
                    regs.in_int[int(name[19:])] = value
                elif name.startswith("input_double_register_"):
                    regs.in_double[int(name[22:])] = value
                elif name.startswith("input_bit_register_"):
                    i = int(name[19:])
                    regs.in_bits = (regs.in_bits & ~(1 << i)) | (int(bool(value)) << i)
                elif name == "input_bit_registers0_to_31":
                    regs.in_bits = (regs.in_bits & ~0xFFFFFFFF) | value
                elif name == "input_bit_registers32_to_63":
                    regs.in_bits = (regs.in_bits & ~(0xFFFFFFFF << 32)) | (value << 32)
            try:
                self._apply_io(fields, io)
            except ValueError as exc:
                core.message(f"RTDE input rejected: {exc}", source="RTDE", level=1)

    @staticmethod
    def _apply_io(f: dict, io) -> None:
        for kind in UR_OUTPUTS.values():  # <field>_mask selects the outputs <field> sets (the UR output table)
            if f"{kind.rtde_field}_mask" in f:
                io.set_digital_out((f[f"{kind.rtde_field}_mask"] & kind.pin_mask) << kind.bit_offset,
                                   (f.get(kind.rtde_field, 0) & kind.pin_mask) << kind.bit_offset)
        if f.get("speed_slider_mask", 0) & 1:
            io.set_speed_slider(min(max(f.get("speed_slider_fraction", 1.0), 0.0), 1.0))
        mask = f.get("standard_analog_output_mask", 0)
        for i in (0, 1):
            if mask >> i & 1:
                voltage = bool(f.get("standard_analog_output_type", 0) >> i & 1)
                io.set_analog_domain(True, i, voltage)
                ratio = min(max(f.get(f"standard_analog_output_{i}", 0.0), 0.0), 1.0)
                io.set_analog_out(i, 10.0 * ratio if voltage else 0.004 + 0.016 * ratio)

    # ---- outputs (tick thread) ---------------------------------------------------------------
    def publish(self, ticks: int = 1, snap: Snapshot | None = None) -> int:
        """Send the data packages due after ``ticks`` more 500 Hz wall-clock ticks, of the controller as ``snap`` sees
        it (None: as it is now); returns how many."""
        self.ticks += ticks
        core = self.core
        conns = self.conns
        msgs = core.outbox
        if msgs:
            core.outbox = []
        sent = 0
        for conn in list(conns):
            if not conn.started or conn.closed:
                continue
            # what is due for this connection goes out in one write: its text messages, then its data packages
            out = [rp.text_message(text, source, level, conn.protocol) for text, source, level in msgs]
            outputs = conn.outputs
            for k, (recipe, packer, phase) in enumerate(outputs):
                phase += ticks * recipe.frequency / MAX_FREQUENCY
                if phase >= 1.0 - 1e-9:
                    phase = min(phase - 1.0, 1.0)
                    if snap is None:
                        snap = Snapshot(core)
                    out.append(packer(snap))
                    sent += 1
                outputs[k] = (recipe, packer, phase)
            if out:
                conn.write(out[0] if len(out) == 1 else b"".join(out))
        return sent


__all__ = ["RTDEServer", "Connection", "INPUTS"]


# the names of 0.1.0 this module no longer defines (planner._deprecated)
__getattr__ = module_getattr(__name__)
