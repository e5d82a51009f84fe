"""python-urx (PyPI ``urx``, unchanged) against the simulated controller: it reads the joints and the pose from the
secondary interface (30002) and the real-time interface (30003), sends its one-line programs (movel, the CB
controllers' ``digital_out[n] = b``) on 30002, and the arm and the outputs do what they say.

The client is ``urx.URRobot``, urx's robot without math3d: ``urx.Robot`` cannot run on Python 3.11 with any math3d
the registry has (4.0 has no ``PoseVector.tolist``, which urx 0.11.0's ``getl`` calls; 3.x uses
``collections.Iterable``, gone since Python 3.10).

urx 0.11.0, the registry's release, recognizes a controller of 3.x by the size of its robot mode data (38 or 46
bytes); PolyScope 5 sends 47, so urx takes it for an older controller: ``is_running()`` stays False (it waits for
robot mode 0) and every move with ``wait=True`` raises "Robot stopped", and it reads the masterboard's digital words
in the 16-bit layout of controllers before 3.0 (``get_digital_out`` reads the inputs' low bits). So it does against a
real e-Series controller (python-urx's issues #60, #107); the moves here are sent with ``wait=False`` and followed
through urx's own getters, and the outputs read through RTDE.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
import rtde_receive
import urx

from planner.kinematics import forward
from sim.motion import HOME
from tests import sim_fixtures
from tests.sim_fixtures import eventually

make_sim = sim_fixtures.make_sim  # fixture
# urx's monitors call Condition.notifyAll at every package
pytestmark = pytest.mark.filterwarnings("ignore:notifyAll:DeprecationWarning")


def test_python_urx_reads_the_arm_moves_it_linearly_and_sets_outputs(make_sim):
    sim = make_sim()
    rob = urx.URRobot(sim.host, use_rt=True)
    receive = rtde_receive.RTDEReceiveInterface(sim.host)
    try:
        # joints and pose from the secondary interface, joints from the real-time one: the controller's
        np.testing.assert_allclose(rob.getj(wait=True), HOME, atol=1e-12)
        start = np.array(rob.getl(wait=True))
        np.testing.assert_allclose(start, forward("ur5e", HOME), atol=1e-9)
        rt = rob.get_realtime_monitor()
        np.testing.assert_allclose(rt.q_actual(wait=True), HOME, atol=1e-12)
        np.testing.assert_allclose(receive.getActualQ(), HOME, atol=1e-12)

        # a movel 8 cm down and 5 cm sideways: reached, on a straight line (the real-time monitor's buffer of every
        # 2 ms package)
        target = start + [0.05, 0.0, -0.08, 0.0, 0.0, 0.0]
        rt.start_buffering()
        rob.movel(target.tolist(), acc=0.5, vel=0.1, wait=False)
        assert eventually(lambda: np.allclose(rob.getl(), target, atol=2e-6), timeout=10.0), rob.getl()
        time.sleep(0.1)
        rt.stop_buffering()
        tcp = np.array([row[2][:3] for row in rt.get_buffer()])
        assert len(tcp) > 300  # > 0.6 s of packages at 500 Hz
        d = (target - start)[:3]
        rel = tcp - start[:3]
        along = rel @ d / (d @ d)
        off_line = np.linalg.norm(rel - np.outer(along, d), axis=1)
        assert off_line.max() < 1e-6 and along.min() > -1e-9 and along.max() == np.float64(along[-1])
        np.testing.assert_allclose(receive.getActualTCPPose(), target, atol=2e-6)

        # set_digital_out: standard output 2, then tool output 0 (urx's number 8)
        rob.set_digital_out(2, True)
        assert eventually(lambda: receive.getActualDigitalOutputBits() == 1 << 2)
        rob.set_digital_out(8, True)
        assert eventually(lambda: receive.getActualDigitalOutputBits() == (1 << 2) | (1 << 16))
        rob.set_digital_out(2, False)
        assert eventually(lambda: receive.getActualDigitalOutputBits() == 1 << 16)
    finally:
        receive.disconnect()
        rob.close()
