"""A servoJ stream at 500 Hz from ur_rtde's initPeriod/waitPeriod loop against the simulated controller:
the recorded joint path follows the commanded one within the motion model's following error, every
command reaches the controller and no control period (so no data package) is missed."""

from __future__ import annotations

import math

import numpy as np
import pytest
import rtde_control

from sim import recording
from sim.motion import HOME, servo_following_error
from tests import sim_fixtures

make_sim = sim_fixtures.make_sim  # fixture

AMPLITUDE = np.array([0.3, -0.2, 0.25, 0.2, 0.3, 0.4])  # rad
FREQUENCY = 0.25  # Hz
LOOKAHEAD, GAIN = 0.1, 300.0


def _stream(sim, seconds: float) -> int:
    c = rtde_control.RTDEControlInterface(sim.host)
    n = int(round(seconds * 500))
    try:
        for k in range(n):
            t0 = c.initPeriod()
            s = math.sin(2 * math.pi * FREQUENCY * k * 0.002)
            c.servoJ((HOME + AMPLITUDE * s).tolist(), 0.5, 0.5, 0.002, LOOKAHEAD, GAIN)
            c.waitPeriod(t0)
        c.servoStop(10.0)
        c.stopScript()
    finally:
        c.disconnect()
    return n


def _check(sim, rec_path, n_sent: int) -> None:
    state = sim.state()
    sim.stop()
    rec = recording.load(rec_path)
    servo = np.flatnonzero(np.any(np.abs(rec.target_q - HOME) > 0, axis=1))
    assert len(servo) > 0.9 * n_sent
    first, last = servo[0], servo[-1]
    cmd, act = rec.target_q[first:last], rec.actual_q[first:last]
    # every command reached the controller: one new target per 2 ms period
    changes = np.count_nonzero(np.any(np.diff(cmd, axis=0) != 0, axis=1)) + 1
    assert changes >= 0.95 * n_sent, (changes, n_sent)
    # the joints follow within the model's following error (after the first 0.3 s of run-in)
    v_max = float(np.max(AMPLITUDE * 2 * math.pi * FREQUENCY))
    bound = servo_following_error(v_max, LOOKAHEAD, GAIN)
    err = np.abs(act - cmd)[150:]
    assert err.max() <= 1.05 * bound + 1e-3, (err.max(), bound)
    assert err.max() > 0.3 * bound  # the lag is modelled, not zero
    # simulated time advanced one 2 ms period per period, and the control loop kept the wall clock's
    # schedule: a period whose tick came more than 2 ms late loses its data package. On an idle machine
    # that never happens (bench/bench_sim.py measures it); this shared 2-core test machine may delay
    # even a SCHED_FIFO thread now and then (other sessions' processes), so up to 1 % of the periods are
    # tolerated here
    assert np.allclose(np.diff(rec.t), 0.002)
    assert state["late_ticks"] <= max(2, 0.01 * n_sent), state["late_ticks"]


def test_servoj_stream_5s_follows_the_commanded_path(make_sim, tmp_path):
    path = tmp_path / "servo5.npz"
    sim = make_sim(record=path)
    _check(sim, path, _stream(sim, 5.0))


@pytest.mark.slow
def test_servoj_stream_60s_at_500hz(make_sim, tmp_path):
    path = tmp_path / "servo60.npz"
    sim = make_sim(record=path)
    _check(sim, path, _stream(sim, 60.0))
