"""drivers.modbus_io.ModbusToolIO: the real pymodbus client against the simulated controller's Modbus server
(in a SimController child process, and sim.modbus's server thread on an IOState), and against raw socket
servers on 127.0.0.x that refuse, stay silent or are absent."""

from __future__ import annotations

import socket
import struct
import threading
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.base import ConnectionLostError
from drivers.modbus_io import ModbusConnectionError, ModbusIOError, ModbusToolIO
from sim.io_state import DIGITAL_MASK, IOState
from sim.modbus import ModbusServerThread
from tests import sim_fixtures

make_sim = sim_fixtures.make_sim  # fixture

HOST = "127.0.0.62"


@pytest.fixture(scope="module")
def served():
    io = IOState()
    with ModbusServerThread(io, HOST, 0) as srv, ModbusToolIO(HOST, srv.port) as tio:
        yield io, tio


@settings(max_examples=80, deadline=None)
@given(start=st.integers(0, DIGITAL_MASK), mask=st.integers(0, DIGITAL_MASK), value=st.integers(0, DIGITAL_MASK))
def test_set_bits_switches_exactly_the_masked_outputs(served, start, mask, value):
    io, tio = served
    io.set_digital_out(DIGITAL_MASK, start)
    tio.set_bits(mask, value)
    assert io.digital_out == (start & ~mask) | (value & mask)
    assert tio.read_outputs() == io.digital_out


@settings(max_examples=40, deadline=None)
@given(inputs=st.integers(0, DIGITAL_MASK), outputs=st.integers(0, DIGITAL_MASK))
def test_read_words_in_the_driver_layout(served, inputs, outputs):
    io, tio = served
    io.set_digital_in(DIGITAL_MASK, inputs)
    io.set_digital_out(DIGITAL_MASK, outputs)
    assert tio.read_inputs() == inputs
    assert tio.read_outputs() == outputs


@pytest.mark.parametrize("kind,pin,bit", [("standard", 0, 0), ("standard", 7, 7), ("configurable", 0, 8),
                                          ("configurable", 7, 15), ("tool", 0, 16), ("tool", 1, 17)])
def test_set_output_each_kind(served, kind, pin, bit):
    io, tio = served
    io.set_digital_out(DIGITAL_MASK, 0x15555)  # other outputs must keep their state
    before = io.digital_out
    tio.set_output(kind, pin, True)
    assert io.digital_out == before | (1 << bit)
    tio.set_output(kind, pin, False)
    assert io.digital_out == before & ~(1 << bit)
    tio.set_output(kind, pin, 1)
    assert tio.read_outputs() >> bit & 1


def test_against_the_simulated_controller(make_sim):
    """The controller's own Modbus server (child process): outputs set over Modbus are the controller's outputs,
    and outputs a URScript program sets are read back over Modbus (one map on both sides)."""
    sim = make_sim(modbus_port=5020)
    port = sim.ports["modbus"]
    assert port == 5020
    with ModbusToolIO(sim.host, port) as tio:
        tio.set_output("standard", 2, True)
        tio.set_output("configurable", 5, True)
        tio.set_output("tool", 1, True)
        expected = (1 << 2) | (1 << 13) | (1 << 17)
        assert sim.state()["digital_out"] == expected
        assert tio.read_outputs() == expected
        program = "def io_check():\n  set_standard_digital_out(6, True)\n  set_tool_digital_out(1, False)\nend\n"
        with socket.create_connection((sim.host, 30002), timeout=3) as s:
            s.sendall(program.encode())
        deadline = time.monotonic() + 5
        want = (expected | (1 << 6)) & ~(1 << 17)
        while tio.read_outputs() != want and time.monotonic() < deadline:
            time.sleep(0.01)
        assert tio.read_outputs() == want
        sim.set_digital_in(0x3FFFF, 0x10381)
        assert tio.read_inputs() == 0x10381


# -- failures ---------------------------------------------------------------------------------------

class RawDevice:
    """A Modbus TCP device on a real socket that answers every request with ``exception`` (or never answers,
    ``exception=None``), counting the requests it received."""

    def __init__(self, exception: int | None) -> None:
        self.exception = exception
        self.requests: list[bytes] = []
        self.sock = socket.create_server((HOST, 0))
        self.port = self.sock.getsockname()[1]
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        try:
            conn, _ = self.sock.accept()
        except OSError:
            return
        with conn:
            while True:
                try:
                    head = conn.recv(7)
                    if len(head) < 7:
                        return
                    tid, _proto, length, unit = struct.unpack(">HHHB", head)
                    pdu = conn.recv(length - 1)
                except OSError:
                    return
                self.requests.append(pdu)
                if self.exception is not None:
                    conn.sendall(struct.pack(">HHHBBB", tid, 0, 3, unit, pdu[0] | 0x80, self.exception))

    def close(self) -> None:
        self.sock.close()


def test_exception_response_names_the_registers_and_is_not_retried():
    dev = RawDevice(exception=2)
    try:
        with ModbusToolIO(HOST, dev.port) as tio:
            with pytest.raises(ModbusIOError) as err:
                tio.set_output("configurable", 3, True)
            msg = str(err.value)
            assert "registers 32-33" in msg and "configurable set mask" in msg
            assert "exception 2 (illegal data address)" in msg and f"{HOST}:{dev.port}" in msg
            assert not isinstance(err.value, ConnectionLostError)
            with pytest.raises(ModbusIOError, match=r"register 1 \(digital outputs\).*exception 2"):
                tio.read_outputs()
        assert len(dev.requests) == 2  # one request each, never repeated
        assert dev.requests[0][0] == 16 and struct.unpack(">HH", dev.requests[0][1:5]) == (32, 2)
    finally:
        dev.close()


def test_silent_device_times_out_without_retry():
    dev = RawDevice(exception=None)
    try:
        tio = ModbusToolIO(HOST, dev.port, timeout=0.5)
        t0 = time.monotonic()
        with pytest.raises(ModbusIOError, match=r"registers 2-3 .* failed"):
            tio.set_output("standard", 1, True)
        assert time.monotonic() - t0 < 3.0
        assert len(dev.requests) == 1
        tio.close()
    finally:
        dev.close()


def test_connection_refused_names_the_address():
    with socket.socket() as s:
        s.bind((HOST, 0))
        port = s.getsockname()[1]  # nothing listens on it once closed
    tio = ModbusToolIO(HOST, port, timeout=1.0)
    with pytest.raises(ModbusConnectionError, match=rf"cannot connect .* {HOST}:{port}: Connection refused") as err:
        tio.read_outputs()
    assert isinstance(err.value, ConnectionLostError)


def test_server_gone_mid_session_is_a_lost_connection():
    io = IOState()
    srv = ModbusServerThread(io, HOST, 0)
    with srv:
        tio = ModbusToolIO(HOST, srv.port, timeout=1.0)
        tio.set_output("standard", 4, True)
        assert io.digital_out == 1 << 4
    with pytest.raises(ModbusConnectionError, match=r"registers 2-3"):
        tio.set_output("standard", 4, False)
    tio.close()


@pytest.mark.parametrize("call,match", [
    (lambda t: t.set_output("analog", 0, True), "output kind must be one of"),
    (lambda t: t.set_output("standard", 8, True), r"standard output pin must be within 0\.\.7, got 8"),
    (lambda t: t.set_output("tool", 2, True), r"tool output pin must be within 0\.\.1, got 2"),
    (lambda t: t.set_output("tool", 0, 2), r"tool output 0 value must be True/False"),
    (lambda t: t.set_output("standard", 1.5, True), "standard output pin must be an integer"),
    (lambda t: t.set_bits(1 << 18, 0), r"output mask must be within 0\.\.0x3FFFF"),
    (lambda t: t.set_bits(1, -1), r"output value must be within"),
])
def test_bad_input_is_refused_before_anything_is_sent(call, match):
    tio = ModbusToolIO(HOST, 1)  # nothing listens there: a request would fail with a connection error
    with pytest.raises(ValueError, match=match):
        call(tio)


@pytest.mark.parametrize("kwargs,match", [
    ({"host": ""}, "Modbus host must be"), ({"host": None}, "Modbus host must be"),
    ({"host": HOST, "port": 0}, r"port must be within 1\.\.65535"),
    ({"host": HOST, "unit": 256}, r"unit id must be within 0\.\.255"),
    ({"host": HOST, "timeout": 0}, "timeout must be > 0"),
])
def test_bad_construction(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ModbusToolIO(**kwargs)
