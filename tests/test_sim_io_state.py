"""sim.io_state.IOState: masks, validation, change callbacks, snapshot, thread safety."""

from __future__ import annotations

import math
import sys
import threading

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.io_state import DIGITAL_MASK, REGISTER_FIRST, REGISTER_LAST, IOState

words = st.integers(min_value=0, max_value=DIGITAL_MASK)


@settings(max_examples=200, deadline=None)
@given(start=words, ops=st.lists(st.tuples(words, words), min_size=1, max_size=20))
def test_masked_writes_change_only_the_masked_bits(start, ops):
    io = IOState()
    io.set_digital_out(DIGITAL_MASK, start)
    io.set_digital_in(DIGITAL_MASK, start ^ DIGITAL_MASK)
    expected = start
    for mask, value in ops:
        before = io.digital_out
        io.set_digital_out(mask, value)
        after = io.digital_out
        assert after & ~mask == before & ~mask  # bits outside the mask untouched
        assert after & mask == value & mask  # bits inside take value's bits
        expected = (expected & ~mask) | (value & mask)
    assert io.digital_out == expected
    assert io.digital_in == start ^ DIGITAL_MASK  # outputs never leak into inputs


@settings(max_examples=100, deadline=None)
@given(ops=st.lists(st.tuples(words, words), min_size=1, max_size=10))
def test_callbacks_replay_to_the_state(ops):
    io = IOState()
    seen: list[int] = []
    io.subscribe(lambda name, value: seen.append(value) if name == "digital_in" else None)
    state = 0
    changes = 0
    for mask, value in ops:
        new = (state & ~mask) | (value & mask)
        changes += new != state
        state = new
        io.set_digital_in(mask, value)
    assert len(seen) == changes  # one call per real change, none for a write that changes nothing
    assert (seen[-1] if seen else 0) == io.digital_in == state


@pytest.mark.parametrize(
    ("call", "words_in_message"),
    [
        (lambda io: io.set_digital_out(1 << 18, 0), ["digital output mask", "18"]),
        (lambda io: io.set_digital_out(0, -1), ["digital output value"]),
        (lambda io: io.set_digital_in(0.5, 1), ["digital input mask", "integer"]),
        (lambda io: io.set_digital_in("3", 1), ["digital input mask", "integer"]),
        (lambda io: io.set_analog_out(2, 1.0), ["analog output index", "0 or 1"]),
        (lambda io: io.set_analog_out(0, math.nan), ["analog output 0", "finite"]),
        (lambda io: io.set_analog_out(1, math.inf), ["analog output 1", "finite"]),
        (lambda io: io.set_analog_out(0, 10.5), ["analog output 0", "0.0..10.0"]),
        (lambda io: io.set_analog_in(-1, 1.0), ["analog input index"]),
        (lambda io: io.set_analog_in(1, "x"), ["analog input 1", "number"]),
        (lambda io: io.set_speed_slider(1.01), ["speed slider", "0..1"]),
        (lambda io: io.set_speed_slider(math.nan), ["speed slider", "finite"]),
        (lambda io: io.set_tool_voltage(5), ["tool voltage", "(0, 12, 24)"]),
        (lambda io: io.set_register(127, 0), ["register address", "128..255"]),
        (lambda io: io.set_register(256, 0), ["register address", "128..255"]),
        (lambda io: io.get_register(0), ["register address"]),
        (lambda io: io.set_register(200, 65536), ["register 200 value", "0..65535"]),
        (lambda io: io.set_register(200, -1), ["register 200 value"]),
        (lambda io: io.set_register(200, 1.5), ["register 200 value", "integer"]),
        (lambda io: io.get_registers(250, 7), ["count 7", "250"]),
        (lambda io: io.subscribe(3), ["callback", "callable"]),
        (lambda io: io.unsubscribe(print), ["not subscribed"]),
    ],
)
def test_bad_arguments_are_named(call, words_in_message):
    io = IOState()
    before = io.snapshot()
    with pytest.raises(ValueError) as err:
        call(io)
    for word in words_in_message:
        assert word in str(err.value)
    assert io.snapshot() == before  # a refused call changes nothing


def test_numpy_integers_are_accepted():
    io = IOState()
    io.set_digital_out(np.uint32(0b110), np.int64(0b010))
    io.set_register(np.int16(130), np.uint16(65535))
    assert io.digital_out == 0b010
    assert io.get_register(130) == 65535


def test_registers_cover_128_to_255():
    io = IOState()
    for a in range(REGISTER_FIRST, REGISTER_LAST + 1):
        io.set_register(a, (a * 257) & 0xFFFF)
    assert io.get_registers(REGISTER_FIRST, 128) == tuple((a * 257) & 0xFFFF for a in range(128, 256))
    assert io.snapshot()["registers"] == io.get_registers(REGISTER_FIRST, 128)
    assert io.get_register(255) == (255 * 257) & 0xFFFF


def test_analog_values_and_domains():
    io = IOState()
    assert io.analog_io_types == 0b1111  # all voltage
    io.set_analog_out(1, 7.5)
    io.set_analog_in(0, 2.25)
    assert io.analog_out == (0.0, 7.5)
    assert io.analog_in == (2.25, 0.0)
    events = []
    io.subscribe(lambda n, v: events.append((n, v)))
    io.set_analog_domain(output=True, index=1, voltage=False)  # output 1 to current: reset to 4 mA
    assert io.analog_io_types == 0b0111
    assert io.analog_out == (0.0, 0.004)
    assert events == [("analog_io_types", 0b0111), ("analog_out", (0.0, 0.004))]
    with pytest.raises(ValueError, match="0.004..0.02 A"):
        io.set_analog_out(1, 5.0)  # volts are not amperes
    io.set_analog_out(1, 0.02)
    assert io.analog_out[1] == 0.02


def test_snapshot_and_named_events():
    io = IOState()
    events = []
    io.subscribe(lambda n, v: events.append((n, v)))
    io.set_digital_out(0x30000, 0x10000)
    io.set_speed_slider(0.25)
    io.set_tool_voltage(24)
    io.set_register(129, 7)
    io.set_register(129, 7)  # no change, no event
    io.set_speed_slider(0.25)
    assert events == [("digital_out", 0x10000), ("speed_slider", 0.25), ("tool_voltage", 24), ("register", (129, 7))]
    snap = io.snapshot()
    assert snap["digital_out"] == 0x10000
    assert snap["speed_slider"] == 0.25
    assert snap["tool_voltage"] == 24
    assert snap["registers"][129 - 128] == 7
    assert set(snap) == {"digital_out", "digital_in", "analog_out", "analog_in", "analog_io_types", "speed_slider",
                         "tool_voltage", "registers"}


def test_unsubscribe_stops_the_calls():
    io = IOState()
    calls = []

    def cb(name, value):
        calls.append(name)

    io.subscribe(cb)
    io.set_speed_slider(0.5)
    io.unsubscribe(cb)
    io.set_speed_slider(0.6)
    assert calls == ["speed_slider"]


def test_concurrent_writers_lose_no_bit():
    """18 threads each own one output bit and toggle it 400 times under masks; without the lock the
    read-modify-write of the word would lose other threads' bits (it does, every run, with the lock
    replaced by a no-op: the tiny switch interval makes the interpreter change threads inside it)."""
    io = IOState()
    log: list[int] = []
    io.subscribe(lambda name, value: log.append(value))
    barrier = threading.Barrier(18)

    def worker(bit: int) -> None:
        barrier.wait()
        for i in range(400):
            io.set_digital_out(1 << bit, (i & 1) << bit)
        io.set_digital_out(1 << bit, 1 << bit)

    threads = [threading.Thread(target=worker, args=(b,)) for b in range(18)]
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    try:
        for t in threads:
            t.start()
        for t in threads:
            t.join(10)
    finally:
        sys.setswitchinterval(interval)
    assert not any(t.is_alive() for t in threads)
    assert io.digital_out == DIGITAL_MASK
    # the callbacks ran in change order: consecutive notified words differ in exactly one bit
    assert log[-1] == DIGITAL_MASK
    diffs = np.bitwise_xor(np.array(log[1:]), np.array(log[:-1]))
    assert np.all(diffs > 0) and np.all(diffs & (diffs - 1) == 0)


def test_locked_groups_changes():
    io = IOState()
    seen = []

    def reader():
        for _ in range(2000):
            s = io.snapshot()
            seen.append((s["digital_out"], s["registers"][0]))

    t = threading.Thread(target=reader)
    t.start()
    for i in range(1, 500):
        with io.locked():
            io.set_digital_out(0xFF, i & 0xFF)
            io.set_register(128, i & 0xFF)
    t.join(10)
    assert all(d == r for d, r in seen)  # never half of a locked group
