"""A servoJ stream at 500 Hz from ur_rtde's initPeriod/waitPeriod loop against the simulated controller:
the recorded joint path follows the commanded one within the motion model's following error, every
command reaches the controller and no control period (so no data package) is missed."""

from __future__ import annotations

import math
import os
import threading
import time

import numpy as np
import pytest
import rtde_control

from drivers.ur import _realtime_loop, _restore_scheduling
from sim import recording
from sim.motion import HOME, servo_following_error
from tests import sim_fixtures

make_sim = sim_fixtures.make_sim  # fixture

AMPLITUDE = np.array([0.3, -0.2, 0.25, 0.2, 0.3, 0.4])  # rad
FREQUENCY = 0.25  # Hz
LOOKAHEAD, GAIN = 0.1, 300.0

# Streams at the controller rate: run on their own, after the parallel run (./run test), so that no other
# test competes for the two cores while the 2 ms loop runs.
pytestmark = pytest.mark.realtime


class StallProbe:
    """A real-time thread sleeping to an absolute 2 ms schedule, as the simulator's loop does: the periods
    it finds itself more than a period late are what this machine stalled (the same for any process)."""

    def __init__(self) -> None:
        self.late = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
        except (OSError, AttributeError):
            pass
        t0, k = time.perf_counter(), 0
        while not self._stop.is_set():
            k += 1
            delay = t0 + k * 0.002 - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            behind = int((time.perf_counter() - t0) / 0.002) - k
            if behind > 0:
                self.late += behind
                k += behind

    def __enter__(self) -> StallProbe:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


def _stream(sim, seconds: float) -> int:
    # the streaming thread SCHED_FIFO below the simulated controller, as the driver's stream runs
    # (drivers.ur.LOOP_PRIORITY); ur_rtde's own threads, started by the interface, inherit it
    before = _realtime_loop()
    try:
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
    finally:
        if before is not None:
            _restore_scheduling(before)
    return n


def _check(sim, rec_path, n_sent: int, machine_late: int) -> None:
    state = sim.state()
    sim.stop()
    rec = recording.load(rec_path)
    servo = np.flatnonzero(np.any(np.abs(rec.target_q - HOME) > 0, axis=1))
    assert len(servo) > 0.9 * n_sent
    first, last = servo[0], servo[-1]
    cmd, act = rec.target_q[first:last], rec.actual_q[first:last]
    # every command reached the controller: one new target per 2 ms period
    changes = np.count_nonzero(np.any(np.diff(cmd, axis=0) != 0, axis=1)) + 1
    assert changes >= 0.95 * n_sent, (f"{changes} new targets in {n_sent} periods; the machine stalled "
                                      f"{machine_late} periods, the controller ran {state['late_ticks']} late")
    # the joints follow within the model's following error (after the first 0.3 s of run-in)
    v_max = float(np.max(AMPLITUDE * 2 * math.pi * FREQUENCY))
    bound = servo_following_error(v_max, LOOKAHEAD, GAIN)
    err = np.abs(act - cmd)[150:]
    assert err.max() <= 1.05 * bound + 1e-3, (err.max(), bound)
    assert err.max() > 0.3 * bound  # the lag is modelled, not zero
    # simulated time advanced one 2 ms period per period, and the control loop kept the wall clock's
    # schedule: a period whose tick comes more than 2 ms late is caught up (its data package sent late).
    # The loop runs late no more periods than this machine stalls a real-time thread (the probe; a shared
    # virtual machine stalls for tens of ms now and then), give or take 0.5 % of the periods
    assert np.allclose(np.diff(rec.t), 0.002)
    assert state["late_ticks"] <= 2 * machine_late + max(2, 0.005 * n_sent), (state["late_ticks"], machine_late)


def test_servoj_stream_5s_follows_the_commanded_path(make_sim, tmp_path):
    path = tmp_path / "servo5.npz"
    sim = make_sim(record=path)
    with StallProbe() as probe:
        n = _stream(sim, 5.0)
    _check(sim, path, n, probe.late)


@pytest.mark.slow
def test_servoj_stream_60s_at_500hz(make_sim, tmp_path):
    path = tmp_path / "servo60.npz"
    sim = make_sim(record=path)
    with StallProbe() as probe:
        n = _stream(sim, 60.0)
    _check(sim, path, n, probe.late)
