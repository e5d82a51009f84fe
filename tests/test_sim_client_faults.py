"""A fault campaign: clients killed (SIGKILL) at random points of each protocol, then a fresh ur_rtde client must
work on the same simulator: its control script starts, a moveJ reaches its target, an output switches.

120 cases: 15 random kill times for each of 8 clients (ur_rtde during asynchronous moves, during synchronous and
asynchronous paths, during a 500 Hz servo stream, ur_rtde's IO interface, a program upload cut off, an RTDE handshake
cut off, a primary interface client sending commands and half lines, real-time interface clients reading part of a
package and sending half programs beside one that never reads). The kill times are drawn from a fixed seed per
client (a failure names its case and time, and repeats)."""

from __future__ import annotations

import random
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
import rtde_control
import rtde_io
import rtde_receive

from tests import sim_fixtures
from tests.sim_fixtures import eventually

make_sim = sim_fixtures.make_sim  # fixture
CASES = 15
KILL_WITHIN = 2.5  # s after the client process starts (its start, about 0.3 s, included)

_UR = """
import sys, time, math
from rtde_control import RTDEControlInterface as C, Path, PathEntry
from rtde_receive import RTDEReceiveInterface as R
host = sys.argv[1]
"""
CLIENTS = {
    "async_moves": _UR + """
c = C(host); r = R(host)
q0 = r.getActualQ()
for k in range(100):
    q = list(q0); q[0] += 0.3 * (k % 2); q[5] -= 0.2 * (k % 2)
    c.moveJ(q, 1.0, 2.0, True)
    while c.getAsyncOperationProgress() >= 0:
        time.sleep(0.005)
""",
    "paths": _UR + """
c = C(host)
p = Path()
for kind, z, blend in ((PathEntry.MoveJ, 0.10, 0.0), (PathEntry.MoveL, 0.30, 0.05), (PathEntry.MoveL, 0.25, 0.0)):
    p.addEntry(PathEntry(kind, PathEntry.PositionTcpPose, [-0.14, -0.45, z, 0, 3.14, 0, 0.5, 2.0, blend]))
for k in range(100):
    c.movePath(p, k % 2 == 1)
    while k % 2 and c.getAsyncOperationProgressEx().isAsyncOperationRunning():
        time.sleep(0.01)
""",
    "servo": _UR + """
c = C(host); r = R(host)
q0 = r.getActualQ()
for i in range(100000):
    t = c.initPeriod()
    q = list(q0); q[0] += 0.2 * math.sin(i * 0.004)
    c.servoJ(q, 0.5, 0.5, 0.002, 0.1, 300)
    c.waitPeriod(t)
""",
    "io": """
import sys, time
from rtde_io import RTDEIOInterface
from rtde_receive import RTDEReceiveInterface
io = RTDEIOInterface(sys.argv[1]); r = RTDEReceiveInterface(sys.argv[1])
for k in range(100000):
    io.setStandardDigitalOut(k % 8, k % 2 == 0)
    io.setSpeedSlider(0.5 + 0.5 * (k % 2))
    time.sleep(0.002)
""",
    "program_upload": """
import socket, sys, time
s = socket.create_connection((sys.argv[1], 30003))
body = "".join(f"  textmsg({i})\\n" for i in range(20000))
text = ("def slow_upload():\\n" + body + "end\\n").encode()
for i in range(0, len(text), 512):
    s.sendall(text[i:i + 512])
    time.sleep(0.002)
""",
    "rtde_handshake": """
import socket, struct, sys, time
def pkg(kind, payload=b""):
    return struct.pack(">HB", 3 + len(payload), ord(kind)) + payload
names = b"input_int_register_0,input_double_register_0,standard_digital_output_mask,standard_digital_output"
for k in range(1000):
    s = socket.create_connection((sys.argv[1], 30004))
    data = (pkg("V", struct.pack(">H", 2)) + pkg("v") + pkg("O", struct.pack(">d", 500.0) + b"timestamp,actual_q")
            + pkg("I", names) + pkg("S"))
    for i in range(len(data)):  # one byte at a time
        s.sendall(data[i:i + 1])
        time.sleep(0.001)
    time.sleep(0.05)
    s.close()
""",
    "primary": """
import socket, sys, time
s = socket.create_connection((sys.argv[1], 30001))
for k in range(100000):
    s.sendall(b"set robotmode run\\n")
    s.sendall(b"def half_" + str(k).encode() + b"():\\n  textmsg(")  # the rest never comes in this run
    s.recv(65536)
    time.sleep(0.01)
    s.sendall(b"1)\\nend\\n")
""",
    "realtime": """
import socket, sys, time
idle = socket.create_connection((sys.argv[1], 30003))  # never read, as ur_rtde's script connection
for k in range(100000):
    s = socket.create_connection((sys.argv[1], 30003))
    s.recv(700)  # part of a state package
    s.sendall(b"def rt_" + str(k).encode() + b"():\\n  textmsg(")  # the rest never comes on this connection
    time.sleep(0.01)
    idle.sendall(b"textmsg(" + str(k).encode() + b")\\n")
""",
}


def _probe(host: str) -> None:
    """A fresh ur_rtde client: the control script starts, a moveJ reaches its target, an output switches."""
    c = rtde_control.RTDEControlInterface(host)
    r = rtde_receive.RTDEReceiveInterface(host)
    io = rtde_io.RTDEIOInterface(host)
    try:
        assert c.isProgramRunning()
        q = np.array(r.getActualQ())
        target = q.copy()
        target[0] += 0.05 if q[0] < 0.5 else -0.05
        assert c.moveJ(target.tolist(), 1.0, 2.0)
        # on target (the receive interface's next packages show it)
        assert eventually(lambda: np.allclose(r.getActualQ(), target, rtol=0, atol=1e-9), timeout=1.0), (
            r.getActualQ(), target)
        io.setSpeedSlider(1.0)
        bit = not r.getDigitalOutState(7)
        assert io.setStandardDigitalOut(7, bit)
        assert eventually(lambda: r.getDigitalOutState(7) == bit)
        c.stopScript()
    finally:
        for client in (c, r, io):
            client.disconnect()


@pytest.mark.parametrize("client", sorted(CLIENTS))
def test_a_killed_client_leaves_the_controller_serving_the_next(make_sim, client, tmp_path):
    sim = make_sim()
    script = tmp_path / f"{client}.py"
    script.write_text(textwrap.dedent(CLIENTS[client]))
    rng = random.Random(f"{client}-{CASES}")
    for case in range(CASES):
        kill_at = rng.uniform(0.0, KILL_WITHIN)
        proc = subprocess.Popen([sys.executable, str(script), sim.host], stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE, text=True)
        time.sleep(kill_at)
        proc.kill()
        _, err = proc.communicate()
        died = [line for line in err.splitlines() if "Error" in line or "Exception" in line]
        assert not died, f"case {case}: the {client} client failed before its kill at {kill_at:.3f} s: {died}"
        try:
            _probe(sim.host)
        except Exception as exc:
            st = sim.state()
            raise AssertionError(f"case {case}: after a {client} client killed at {kill_at:.3f} s, a fresh client "
                                 f"fails: {type(exc).__name__}: {exc}; controller: {st['safety_mode']}, "
                                 f"{st['runtime_state']} {st['program']}, last messages {st['log'][-4:]}") from exc
    st = sim.state()
    assert st["safety_mode"] == "NORMAL" and st["robot_mode"] == "RUNNING"
    assert not [m for m in st["log"] if "Protective stop" in m[2]]
    assert "Traceback" not in sim.stderr()
