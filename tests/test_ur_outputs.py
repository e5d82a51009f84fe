"""The UR output table (planner.kinematics.ur_outputs) is the one layout of the digital outputs: every pin of every
kind switches the same bit of the 18-bit word whether the exported program (its URScript setter), the RTDE driver
(ur_rtde's setter, RTDE's input fields) or the Modbus driver (UR's registers) switches it on the simulated
controller; the settings and the I/O events accept exactly its pins; the reports name its bits."""

from __future__ import annotations

import socket

import numpy as np
import pytest
import rtde_receive
from hypothesis import given, settings
from hypothesis import strategies as st

import drivers.report
from drivers.modbus_io import ModbusToolIO
from drivers.ur import RTDEOutputs
from planner import PlannerError, PlanSettings
from planner.export import job_program
from planner.export.script_text import output_switch
from planner.kinematics.ur_outputs import (
    DIGITAL_BITS,
    DIGITAL_MASK,
    UR_OUTPUTS,
    bit_name,
    from_modbus,
    from_ur_bits,
    output_bit,
    to_modbus,
    to_ur_bits,
)
from planner.motion import IOEvent, MotionInputError
from tests import sim_fixtures

make_sim = sim_fixtures.make_sim  # fixture

PINS = [(k.name, p) for k in UR_OUTPUTS.values() for p in range(k.pins)]


def word(pins) -> int:
    """The 18-bit word with the given (kind, pin) outputs on."""
    return sum(1 << output_bit(kind, pin) for kind, pin in pins)


def test_the_kinds_tile_the_word_and_every_bit_has_one_name():
    bits = sorted(output_bit(kind, pin) for kind, pin in PINS)
    assert bits == list(range(DIGITAL_BITS)) and DIGITAL_MASK == (1 << DIGITAL_BITS) - 1 == word(PINS)
    for kind, pin in PINS:
        assert bit_name(output_bit(kind, pin)) == f"{kind}[{pin}]"
    assert drivers.report.bit_name is bit_name  # the report's names are the table's


@pytest.mark.parametrize("kind, pin, message", [
    ("analog", 0, r"output kind must be one of \['configurable', 'standard', 'tool'\], got 'analog'"),
    ("tool", 2, "tool output pin must be within 0..1, got 2"),
    ("standard", -1, "standard output pin must be within 0..7, got -1"),
    ("configurable", 1.0, r"configurable output pin must be an integer, got 1.0 \(float\)"),
])
def test_a_pin_outside_the_table_is_refused_naming_it(kind, pin, message):
    with pytest.raises(PlannerError, match=f"^{message}$"):
        output_bit(kind, pin)


@settings(max_examples=300, deadline=None)
@given(w=st.integers(0, DIGITAL_MASK))
def test_modbus_registers_hold_the_word(w):
    """Register 1 holds the standard and tool outputs in UR's [BBBBBBBBTT] layout, register 31 the configurable
    ones; the two give back the word."""
    standard, configurable, tool = (w >> 0) & 0xFF, (w >> 8) & 0xFF, (w >> 16) & 0x3
    assert to_ur_bits(w) == to_modbus(w, 1) == standard | tool << 8  # UR's support article "Modbus server"
    assert to_modbus(w, 31) == configurable
    assert from_ur_bits(to_ur_bits(w), to_modbus(w, 31)) == w
    assert from_modbus(1, to_ur_bits(w)) | from_modbus(31, configurable) == w
    assert from_modbus(1, 0xFC00) == 0  # the undefined bits of register 1 are dropped
    assert [UR_OUTPUTS[k].pins_of(w) for k in ("standard", "configurable", "tool")] == [standard, configurable, tool]


@pytest.mark.parametrize("kind", list(UR_OUTPUTS))
def test_settings_and_events_take_exactly_the_pins_of_the_table(kind):
    pins = UR_OUTPUTS[kind].pins
    assert PlanSettings(cut_output=(kind, pins - 1)).checked().cut_output == (kind, pins - 1)
    with pytest.raises(PlannerError, match="cut_output must be"):
        PlanSettings(cut_output=(kind, pins)).checked()
    assert IOEvent(0.0, pins - 1, True, output=kind).channel == (kind, pins - 1)
    with pytest.raises(MotionInputError, match=f"^pin: {kind} digital output must be 0..{pins - 1}"):
        IOEvent(0.0, pins, True, output=kind)


def _eventually(condition, timeout: float = 5.0) -> bool:
    return sim_fixtures.eventually(condition, timeout)


def test_every_output_through_every_entry_point_of_the_simulated_controller(make_sim):
    sim = make_sim(modbus_port=5020)
    # three patterns that tell every pin from its neighbours and the kinds apart
    programmed = [(k, p) for k, p in PINS if output_bit(k, p) in (0, 3, 5, 9, 10, 14, 16)]
    streamed = [(k, p) for k, p in PINS if output_bit(k, p) in (1, 2, 7, 8, 12, 15, 17)]
    polled = [(k, p) for k, p in PINS if output_bit(k, p) % 3 == 1]
    r = rtde_receive.RTDEReceiveInterface(sim.host)
    try:
        # the exporter's switch lines (the table's URScript setters), run by the controller's interpreter
        program = "\n".join(["def outputs():", *(output_switch(k, p, True) for k, p in programmed), "end", ""])
        with socket.create_connection((sim.host, 30002), timeout=3) as s:
            s.sendall(program.encode())
        assert _eventually(lambda: sim.state()["digital_out"] == word(programmed)), sim.state()["log"]
        assert _eventually(lambda: r.getActualDigitalOutputBits() == word(programmed))

        # the RTDE driver: ur_rtde's setter of each kind, the controller's RTDE input fields
        rtde_out = RTDEOutputs(sim.host)
        try:
            rtde_out.set_bits(DIGITAL_MASK, word(streamed))
        finally:
            rtde_out.close()
        assert _eventually(lambda: r.getActualDigitalOutputBits() == word(streamed))

        # the Modbus driver: UR's registers 1-3 and 31-33
        with ModbusToolIO(sim.host, sim.ports["modbus"]) as tio:
            for kind, pin in PINS:
                tio.set_output(kind, pin, (kind, pin) in polled)
            assert sim.state()["digital_out"] == word(polled) == tio.read_outputs()
    finally:
        r.disconnect()


def test_the_exported_program_switches_the_planned_bit():
    """A job's program switches its cut output with the table's setter, and its trajectory carries the table's
    bit for it."""
    from tests.test_export_urscript import l_shape, planned

    for kind, pin in [("configurable", 3), ("tool", 0)]:
        job = planned(l_shape(), cut_output=(kind, pin))
        text = job_program(job)
        assert f"  {UR_OUTPUTS[kind].script_setter}({pin}, True)" in text.splitlines()
        io = np.concatenate([c.io for c in job.trajectory().chunks(joints=False)])
        assert set(np.unique(io).tolist()) == {0, 1 << output_bit(kind, pin)}
