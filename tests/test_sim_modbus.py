"""sim.modbus: UR's Modbus TCP server map, served by pymodbus, driven by the real pymodbus clients and raw
sockets on 127.0.0.x (a kernel-chosen free port per server)."""

from __future__ import annotations

import asyncio
import socket
import struct
import sys
import threading

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymodbus.client import AsyncModbusTcpClient, ModbusTcpClient

from sim.io_state import DIGITAL_MASK, IOState
from sim.modbus import ModbusServerThread

HOST = "127.0.0.61"
OTHER_HOST = "127.0.0.163"  # an address nothing in these tests binds

ILLEGAL_FUNCTION, ILLEGAL_ADDRESS, ILLEGAL_VALUE, DEVICE_FAILURE = 1, 2, 3, 4


def ur_bits(word: int) -> int:
    """IOState's word (standard 0-7, configurable 8-15, tool 16-17) in UR's register-0/1 layout."""
    return (word & 0xFF) | (((word >> 16) & 3) << 8)


def client(port: int, host: str = HOST) -> ModbusTcpClient:
    c = ModbusTcpClient(host, port=port, timeout=3, retries=0)
    assert c.connect(), f"cannot connect to the Modbus server on {host}:{port}"
    return c


def exception_code(response) -> int:
    assert response.isError(), f"expected an exception response, got {response}"
    return response.exception_code


def raw_request(sock: socket.socket, tid: int, pdu: bytes) -> bytes:
    """Send one Modbus TCP request (unit 1) and return the response PDU."""
    sock.sendall(struct.pack(">HHHB", tid, 0, len(pdu) + 1, 1) + pdu)
    header = recv_exact(sock, 7)
    rtid, proto, length, _unit = struct.unpack(">HHHB", header)
    assert (rtid, proto) == (tid, 0)
    return recv_exact(sock, length - 1)


def recv_exact(sock: socket.socket, n: int) -> bytes:
    data = b""
    while len(data) < n:
        chunk = sock.recv(n - len(data))
        assert chunk, "the server closed the connection"
        data += chunk
    return data


@pytest.fixture
def served():
    io = IOState()
    with ModbusServerThread(io, HOST, 0) as srv:
        yield io, srv


@pytest.fixture(scope="module")
def shared():
    io = IOState()
    with ModbusServerThread(io, HOST, 0) as srv:
        c = client(srv.port)
        yield io, c
        c.close()


# -- the register map, both directions ----------------------------------------------------------------

@settings(max_examples=60, deadline=None)
@given(outputs=st.integers(0, DIGITAL_MASK), inputs=st.integers(0, DIGITAL_MASK))
def test_state_set_through_iostate_is_read_over_modbus(shared, outputs, inputs):
    io, c = shared
    io.set_digital_out(DIGITAL_MASK, outputs)
    io.set_digital_in(DIGITAL_MASK, inputs)
    regs = c.read_holding_registers(0, count=2).registers
    assert regs == [ur_bits(inputs), ur_bits(outputs)]
    assert c.read_input_registers(0, count=2).registers == regs  # one table for FC 3 and FC 4
    assert c.read_holding_registers(21, count=2).registers == [inputs >> 16, outputs >> 16]
    assert c.read_input_registers(30, count=2).registers == [(inputs >> 8) & 0xFF, (outputs >> 8) & 0xFF]
    bits = c.read_coils(0, count=32).bits
    expected = [bool(ur_bits(inputs) >> i & 1) for i in range(16)] + [bool(ur_bits(outputs) >> i & 1) for i in range(16)]
    assert bits[:32] == expected
    assert c.read_discrete_inputs(0, count=32).bits[:32] == expected


@settings(max_examples=60, deadline=None)
@given(start=st.integers(0, DIGITAL_MASK), set_mask=st.integers(0, 0x3FF), clear_mask=st.integers(0, 0x3FF),
       conf_set=st.integers(0, 0xFF), conf_clear=st.integers(0, 0xFF))
def test_set_and_clear_masks(shared, start, set_mask, clear_mask, conf_set, conf_clear):
    io, c = shared
    io.set_digital_out(DIGITAL_MASK, start)
    assert not c.write_register(2, set_mask).isError()
    after_set = ur_bits(io.digital_out)
    assert after_set == ur_bits(start) | set_mask
    assert not c.write_register(3, clear_mask).isError()
    assert ur_bits(io.digital_out) == after_set & ~clear_mask
    assert io.digital_out & 0xFF00 == start & 0xFF00  # configurable outputs untouched by registers 2/3
    before_conf = io.digital_out
    assert not c.write_registers(32, [conf_set, conf_clear]).isError()  # set, then clear
    conf = ((((start >> 8) & 0xFF) | conf_set) & ~conf_clear) & 0xFF
    assert io.digital_out == (before_conf & ~0xFF00) | (conf << 8)
    assert c.read_holding_registers(2, count=2).registers == [set_mask, clear_mask]  # last masks written


def test_output_writes_reach_iostate(served):
    io, srv = served
    c = client(srv.port)
    io.set_digital_out(0xFF00, 0xA500)  # configurable outputs must survive register-1 writes
    assert not c.write_register(1, 0b10_0101_0110).isError()  # tool output 1, standard 1, 2, 4, 6
    assert io.digital_out == 0xA500 | 0b0101_0110 | (1 << 17)
    assert not c.write_coil(16 + 8, True).isError()  # tool output 0
    assert not c.write_coil(16 + 1, False).isError()
    assert io.digital_out == 0xA500 | 0b0101_0100 | (3 << 16)
    assert not c.write_coils(16, [True] * 8 + [False, False]).isError()
    assert io.digital_out == 0xA500 | 0xFF
    assert not c.write_register(22, 0b10).isError()
    assert io.digital_out >> 16 == 0b10
    assert not c.write_register(31, 0x3C).isError()
    assert (io.digital_out >> 8) & 0xFF == 0x3C
    assert not c.write_register(20, 12).isError()
    assert io.tool_voltage == 12
    assert c.read_holding_registers(20).registers == [12]
    io.set_tool_voltage(24)
    assert c.read_input_registers(20).registers == [24]
    c.close()


def test_general_purpose_registers_both_ways(served):
    io, srv = served
    c = client(srv.port)
    values = [(a * 2654435761) & 0xFFFF for a in range(128, 256)]
    assert not c.write_registers(128, values[:100]).isError()
    assert not c.write_registers(228, values[100:]).isError()
    assert io.get_registers(128, 128) == tuple(values)
    assert c.read_holding_registers(128, count=125).registers == values[:125]
    assert c.read_input_registers(253, count=3).registers == values[125:]
    io.set_register(200, 4242)
    io.set_register(255, 65535)
    assert c.read_holding_registers(200).registers == [4242]
    assert c.read_input_registers(255).registers == [65535]
    assert not c.write_register(131, 7).isError()
    assert io.get_register(131) == 7
    c.close()


def test_modbus_writes_notify_subscribers(served):
    io, srv = served
    events = []
    io.subscribe(lambda name, value: events.append((name, value)))
    c = client(srv.port)
    c.write_register(140, 99)
    c.write_coil(16, True)
    c.write_register(140, 99)  # same value: no event
    assert events == [("register", (140, 99)), ("digital_out", 1)]
    c.close()


def test_tcp_pose_registers():
    pose = [0.41235, -0.12345, 3.5, 0.0014, -3.14159, 40.0]  # m, rad; z and rz beyond the int16 range
    calls = []

    def tcp_pose():
        calls.append(1)
        return pose

    with ModbusServerThread(IOState(), HOST, 0, tcp_pose=tcp_pose) as srv:
        c = client(srv.port)
        regs = c.read_holding_registers(400, count=6).registers
        signed = [r - 65536 if r >= 32768 else r for r in regs]
        assert signed == [4124, -1234, 32767, 1, -3142, 32767]  # 0.1 mm and mrad, saturated at int16
        assert c.read_input_registers(403).registers == [regs[3]]
        assert exception_code(c.write_register(400, 1)) == ILLEGAL_ADDRESS  # read-only
        n = len(calls)
        c.read_holding_registers(128, count=4)
        assert len(calls) == n  # the pose is computed only when asked for
        pose[0] = float("nan")
        assert exception_code(c.read_holding_registers(400, count=6)) == DEVICE_FAILURE
        assert c.read_holding_registers(128).registers == [0]  # still serving
        c.close()


# -- refused requests ----------------------------------------------------------------------------------

@pytest.mark.parametrize(
    ("request_", "code"),
    [
        (lambda c: c.read_holding_registers(256), ILLEGAL_ADDRESS),  # past the GP registers
        (lambda c: c.read_holding_registers(255, count=2), ILLEGAL_ADDRESS),  # running out of them
        (lambda c: c.read_holding_registers(34), ILLEGAL_ADDRESS),  # a gap in UR's map
        (lambda c: c.read_input_registers(0, count=5), ILLEGAL_ADDRESS),  # into the gap after 3
        (lambda c: c.read_holding_registers(400), ILLEGAL_ADDRESS),  # no tcp_pose given
        (lambda c: c.read_holding_registers(65535), ILLEGAL_ADDRESS),
        (lambda c: c.read_coils(32), ILLEGAL_ADDRESS),
        (lambda c: c.read_discrete_inputs(30, count=4), ILLEGAL_ADDRESS),
        (lambda c: c.write_register(0, 1), ILLEGAL_ADDRESS),  # inputs are read-only
        (lambda c: c.write_register(21, 1), ILLEGAL_ADDRESS),
        (lambda c: c.write_register(30, 1), ILLEGAL_ADDRESS),
        (lambda c: c.write_register(256, 1), ILLEGAL_ADDRESS),
        (lambda c: c.write_coil(3, True), ILLEGAL_ADDRESS),  # input coils are read-only
        (lambda c: c.write_coils(14, [False] * 4), ILLEGAL_ADDRESS),
        (lambda c: c.write_coil(40, True), ILLEGAL_ADDRESS),
        (lambda c: c.write_registers(127, [1, 2]), ILLEGAL_ADDRESS),
        (lambda c: c.write_register(1, 1 << 10), ILLEGAL_VALUE),  # undefined bit
        (lambda c: c.write_register(22, 4), ILLEGAL_VALUE),
        (lambda c: c.write_register(31, 0x100), ILLEGAL_VALUE),
        (lambda c: c.write_register(20, 5), ILLEGAL_VALUE),  # tool voltage is 0, 12 or 24
        (lambda c: c.write_coil(16 + 12, True), ILLEGAL_VALUE),  # undefined output bit
        (lambda c: c.write_registers(1, [1, 1 << 12]), ILLEGAL_VALUE),  # second value bad: none applied
        (lambda c: c.mask_write_register(address=130, and_mask=0, or_mask=1), ILLEGAL_FUNCTION),  # FC 22
        (lambda c: c.readwrite_registers(read_address=128, read_count=1, write_address=129, values=[1]),
         ILLEGAL_FUNCTION),  # FC 23
        (lambda c: c.diag_read_diagnostic_register(), ILLEGAL_FUNCTION),  # FC 8
        (lambda c: c.report_device_id(), ILLEGAL_FUNCTION),  # FC 17
    ],
)
def test_refused_requests_change_nothing_and_the_server_keeps_serving(served, request_, code):
    io, srv = served
    io.set_register(130, 5)
    io.set_register(129, 6)
    io.set_register(128, 7)
    c = client(srv.port)
    before = io.snapshot()
    assert exception_code(request_(c)) == code
    assert io.snapshot() == before
    assert c.read_holding_registers(128, count=3).registers == [7, 6, 5]  # same connection still served
    other = client(srv.port)
    assert other.read_input_registers(130).registers == [5]  # and a new one
    other.close()
    c.close()


def test_malformed_quantities_and_coil_values(served):
    """Quantities outside the spec's limits and a coil value other than 0xFF00/0x0000 -> exception 3
    under the request's own function code (pymodbus's client refuses to send these: raw socket)."""
    io, srv = served
    with socket.create_connection((HOST, srv.port), timeout=3) as s:
        assert raw_request(s, 1, struct.pack(">BHH", 3, 128, 0)) == bytes([0x83, ILLEGAL_VALUE])
        assert raw_request(s, 2, struct.pack(">BHH", 4, 128, 126)) == bytes([0x84, ILLEGAL_VALUE])
        assert raw_request(s, 3, struct.pack(">BHH", 1, 0, 0)) == bytes([0x81, ILLEGAL_VALUE])
        assert raw_request(s, 4, struct.pack(">BHH", 2, 0, 2001)) == bytes([0x82, ILLEGAL_VALUE])
        assert raw_request(s, 5, struct.pack(">BHH", 5, 16, 0x1234)) == bytes([0x85, ILLEGAL_VALUE])
        assert io.digital_out == 0
        assert raw_request(s, 6, struct.pack(">BHH", 5, 16, 0xFF00)) == struct.pack(">BHH", 5, 16, 0xFF00)
        assert io.digital_out == 1
        assert raw_request(s, 7, struct.pack(">BHH", 3, 0, 2)) == bytes([3, 4, 0, 0, 0, 1])


# -- connections ---------------------------------------------------------------------------------------

def test_clients_vanishing_mid_request(served):
    io, srv = served
    io.set_register(150, 1234)
    steady = client(srv.port)
    frame = struct.pack(">HHHBBHH", 9, 0, 6, 1, 3, 150, 1)
    # half a frame, then gone
    with socket.create_connection((HOST, srv.port), timeout=3) as s:
        s.sendall(frame[:5])
    # a whole request, gone before the answer (reset, not a clean close)
    s = socket.create_connection((HOST, srv.port), timeout=3)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    s.sendall(frame + frame[:9])
    s.close()
    # garbage, then gone
    with socket.create_connection((HOST, srv.port), timeout=3) as s:
        s.sendall(b"\xff" * 300)
    assert steady.read_holding_registers(150).registers == [1234]
    fresh = client(srv.port)
    assert fresh.read_holding_registers(150).registers == [1234]
    with socket.create_connection((HOST, srv.port), timeout=3) as s:
        assert raw_request(s, 77, struct.pack(">BHH", 3, 150, 1)) == bytes([3, 2]) + struct.pack(">H", 1234)
    fresh.close()
    steady.close()


def test_two_clients_at_once(served):
    io, srv = served

    both_connected: asyncio.Barrier

    async def worker(offset: int, rounds: int) -> list[int]:
        c = AsyncModbusTcpClient(HOST, port=srv.port, timeout=3, retries=0)
        assert await c.connect()
        await both_connected.wait()
        seen = []
        for i in range(rounds):
            w = await c.write_registers(128 + offset * 64, [i, i + 1, i + 2, i + 3])
            assert not w.isError()
            r = await c.read_holding_registers(128 + (1 - offset) * 64, count=4)  # the other's block
            assert not r.isError()
            assert r.registers[1:] == [r.registers[0] + k for k in (1, 2, 3)] or r.registers == [0, 0, 0, 0]
            seen.append(r.registers[0])
            assert not (await c.write_coil(16 + offset, bool(i & 1))).isError()
        c.close()
        return seen

    async def both():
        nonlocal both_connected
        both_connected = asyncio.Barrier(2)
        return await asyncio.gather(worker(0, 150), worker(1, 150))

    seen0, seen1 = asyncio.run(both())
    assert io.get_registers(128, 4) == (149, 150, 151, 152)
    assert io.get_registers(192, 4) == (149, 150, 151, 152)
    assert io.digital_out & 0b11 == 0b11
    # each saw the other's writes happen, in order (a multi-register write is never seen half done)
    assert seen0 == sorted(seen0) and seen1 == sorted(seen1)
    assert max(seen0) > 0 and max(seen1) > 0


# -- lifecycle -----------------------------------------------------------------------------------------

def test_stop_closes_connections_and_releases_the_port():
    io = IOState()
    srv = ModbusServerThread(io, HOST, 0)
    srv.start()
    srv.wait_ready(10)
    port = srv.port
    assert port > 0 and srv.serving
    s = socket.create_connection((HOST, port), timeout=3)
    assert raw_request(s, 1, struct.pack(">BHH", 3, 128, 1)) == bytes([3, 2, 0, 0])
    srv.stop()
    assert not srv.serving
    assert s.recv(16) == b""  # the server closed our connection
    s.close()
    with pytest.raises(ConnectionRefusedError):
        socket.create_connection((HOST, port), timeout=3)
    again = ModbusServerThread(io, HOST, port)  # the same port serves again
    with again:
        c = client(port)
        assert c.read_holding_registers(128).registers == [0]
        c.close()
    srv.stop()  # a second stop is harmless


def test_binds_only_its_host(served):
    _io, srv = served
    with pytest.raises(ConnectionRefusedError):
        socket.create_connection((OTHER_HOST, srv.port), timeout=3)


def test_port_in_use_is_reported(served):
    _io, srv = served
    clash = ModbusServerThread(IOState(), HOST, srv.port)
    clash.start()
    with pytest.raises(RuntimeError, match=f"cannot listen on {HOST}:{srv.port}"):
        clash.wait_ready(10)
    clash.stop()
    c = client(srv.port)  # the first server is unharmed
    assert not c.read_holding_registers(128).isError()
    c.close()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"host": "10.1.2.3", "port": 5020}, "not a loopback address"),
        ({"host": "localhost", "port": 5020}, "must be an IP address"),
        ({"host": HOST, "port": 70000}, "0..65535"),
        ({"host": HOST, "port": "502"}, "0..65535"),
        ({"host": HOST, "port": 5020, "tcp_pose": 3}, "tcp_pose must be callable"),
    ],
)
def test_bad_arguments(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ModbusServerThread(IOState(), **kwargs)


def test_lifecycle_misuse():
    srv = ModbusServerThread(IOState(), HOST, 0)
    with pytest.raises(RuntimeError, match="not started"):
        srv.wait_ready(1)
    srv.stop()  # never started: nothing to do
    with srv:
        with pytest.raises(RuntimeError, match="already started"):
            srv.start()


def test_pose_reads_never_deadlock_with_a_motion_thread():
    """tcp_pose takes the motion model's lock; a motion thread writes the IOState while holding it. The server
    must not hold the IOState's lock while asking for the pose (the opposite order would deadlock)."""
    io = IOState()
    motion_lock = threading.Lock()
    stop = threading.Event()

    def tcp_pose():
        with motion_lock:
            return [0.1, 0.2, 0.3, 0.0, 0.0, 0.0]

    def motion():
        i = 0
        while not stop.is_set():
            with motion_lock:
                io.set_register(200, i & 0xFFFF)
                i += 1

    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    try:
        with ModbusServerThread(io, HOST, 0, tcp_pose=tcp_pose) as srv:
            t = threading.Thread(target=motion)
            t.start()
            try:
                c = client(srv.port)
                for _ in range(300):
                    r = c.read_input_registers(400, count=6)
                    assert not r.isError()
                    assert r.registers[:3] == [1000, 2000, 3000]
                    assert not c.read_holding_registers(200).isError()
                c.close()
            finally:
                stop.set()
                t.join(5)
    finally:
        sys.setswitchinterval(interval)
