"""The simulated controller's Modbus server kept in step with RTDE: pymodbus and ur_rtde on one controller."""

from __future__ import annotations

import time

import numpy as np
import rtde_io
import rtde_receive
from pymodbus.client import ModbusTcpClient

from tests import sim_fixtures

make_sim = sim_fixtures.make_sim  # fixture


def _wait(cond, timeout=1.0):
    end = time.monotonic() + timeout
    while not cond() and time.monotonic() < end:
        time.sleep(0.005)
    return cond()


def test_modbus_and_rtde_see_the_same_io(make_sim):
    sim = make_sim(modbus_port=0)
    port = sim.ports["modbus"]
    assert port and port > 0
    mb = ModbusTcpClient(sim.host, port=port, timeout=3, retries=0)
    assert mb.connect()
    io = rtde_io.RTDEIOInterface(sim.host)
    r = rtde_receive.RTDEReceiveInterface(sim.host)
    try:
        # RTDE sets, Modbus reads (register 1: standard outputs 0-7, tool outputs in bits 8-9)
        assert io.setStandardDigitalOut(4, True) and io.setToolDigitalOut(0, True)
        assert _wait(lambda: mb.read_holding_registers(1, count=1).registers[0] == (1 << 4) | (1 << 8))
        # Modbus sets (set-output mask, register 2), RTDE reads
        assert not mb.write_register(2, 1 << 6).isError()
        assert _wait(lambda: r.getDigitalOutState(6) and r.getDigitalOutState(4) and r.getDigitalOutState(16))
        # general-purpose registers, and the TCP pose in 0.1 mm / mrad
        assert not mb.write_register(130, 4242).isError()
        assert mb.read_holding_registers(130, count=1).registers[0] == 4242
        regs = mb.read_holding_registers(400, count=6).registers
        pose = np.array([v - 65536 if v > 32767 else v for v in regs], dtype=float)
        tcp = np.array(r.getActualTCPPose())
        np.testing.assert_allclose(pose[:3] * 1e-4, tcp[:3], atol=1e-4)
        np.testing.assert_allclose(pose[3:] * 1e-3, tcp[3:], atol=1e-3)
        # an address outside UR's table: an exception answer, and the server keeps serving
        assert mb.read_holding_registers(9000, count=1).isError()
        assert mb.read_holding_registers(130, count=1).registers[0] == 4242
    finally:
        mb.close()
        io.disconnect()
        r.disconnect()
