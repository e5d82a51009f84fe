"""RTDEIOInterface against the simulated controller: digital, tool and configurable outputs, the speed
slider, analog outputs and input registers, seen back through RTDEReceiveInterface."""

from __future__ import annotations

import time

import numpy as np
import pytest
import rtde_control
import rtde_io
import rtde_receive

from sim.motion import HOME
from tests import sim_fixtures

make_sim = sim_fixtures.make_sim  # fixture


def _wait(cond, timeout=1.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.005)
    return cond()


def test_outputs_slider_and_registers(make_sim):
    sim = make_sim()
    io = rtde_io.RTDEIOInterface(sim.host)
    r = rtde_receive.RTDEReceiveInterface(sim.host)
    try:
        assert io.setStandardDigitalOut(3, True)
        assert _wait(lambda: r.getDigitalOutState(3))
        assert io.setConfigurableDigitalOut(2, True)
        assert _wait(lambda: r.getDigitalOutState(8 + 2))
        assert io.setToolDigitalOut(1, True)
        assert _wait(lambda: r.getDigitalOutState(17))
        assert r.getActualDigitalOutputBits() == (1 << 3) | (1 << 10) | (1 << 17)
        assert io.setStandardDigitalOut(3, False)
        assert _wait(lambda: not r.getDigitalOutState(3))
        assert io.setAnalogOutputVoltage(0, 0.25)
        assert _wait(lambda: abs(r.getStandardAnalogOutput0() - 2.5) < 1e-12)
        assert io.setAnalogOutputCurrent(1, 0.5)
        assert _wait(lambda: abs(r.getStandardAnalogOutput1() - 0.012) < 1e-12)
        assert io.setInputIntRegister(18, -42) and io.setInputDoubleRegister(22, 3.5)
        assert _wait(lambda: sim.state()["in_int"][18] == -42 and sim.state()["in_double"][22] == 3.5)
        with pytest.raises(Exception, match="18-22"):
            io.setInputIntRegister(5, 1)
        # inputs driven from the simulated wiring
        sim.set_digital_in(0b101, 0b101)
        assert _wait(lambda: r.getDigitalInState(0) and r.getDigitalInState(2) and not r.getDigitalInState(1))
        assert io.setSpeedSlider(0.5)
        assert _wait(lambda: r.getTargetSpeedFraction() == 0.5)
    finally:
        io.disconnect()
        r.disconnect()


def test_speed_slider_slows_moves(make_sim):
    sim = make_sim()
    c = rtde_control.RTDEControlInterface(sim.host)
    io = rtde_io.RTDEIOInterface(sim.host)
    try:
        target = (HOME + [0.3, 0, 0, 0, 0, 0]).tolist()
        t = time.monotonic()
        assert c.moveJ(target, 1.0, 4.0)
        full = time.monotonic() - t
        assert io.setSpeedSlider(0.5)
        time.sleep(0.05)
        t = time.monotonic()
        assert c.moveJ(HOME.tolist(), 1.0, 4.0)
        half = time.monotonic() - t
        np.testing.assert_allclose(sim.state()["q"], HOME, atol=1e-9)
        assert 1.7 < half / full < 2.3
    finally:
        c.stopScript()
        c.disconnect()
        io.disconnect()
