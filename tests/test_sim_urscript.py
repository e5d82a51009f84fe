"""URScript programs the planner's exporter writes, run by the simulated controller from the script ports."""

from __future__ import annotations

import re
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import rtde_receive

from planner.kinematics import forward
from sim import recording
from sim.motion import HOME
from tests import sim_fixtures

make_sim = sim_fixtures.make_sim  # fixture
REPO = Path(__file__).resolve().parents[1]
_POSE = re.compile(r"^\s*(movep|movel)\(p\[([^\]]*)\].*r=([-0-9.e]+)\)")


def _send(host: str, text: str, port: int = 30002) -> None:
    with socket.create_connection((host, port)) as s:
        s.sendall(text.encode())


def _run(sim, text: str, timeout: float = 60.0) -> None:
    r = rtde_receive.RTDEReceiveInterface(sim.host)
    try:
        _send(sim.host, text)
        end = time.monotonic() + timeout
        time.sleep(0.05)
        while r.getRuntimeState() == 2 and time.monotonic() < end:
            time.sleep(0.02)
        assert r.getRuntimeState() == 1, "the program did not finish"
    finally:
        r.disconnect()


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("export") / "one.script"
    subprocess.run([sys.executable, "-m", "planner.frontends.cli", "plan", "examples/nx_first_pass.cls", "--pass", "longest",
                    "--robot", "ur5e", "--part-frame", "400mm,996.5mm,-100mm,0,0,0", "-o", str(out)],
                   cwd=REPO, check=True, capture_output=True, timeout=600)
    return out


def test_exported_movep_program_runs_along_its_path(make_sim, tmp_path, exported):
    text = exported.read_text()
    targets = np.array([[float(x) for x in m.group(2).split(",")] for m in map(_POSE.match, text.splitlines()) if m])
    radii = [float(m.group(3)) for m in map(_POSE.match, text.splitlines()) if m]
    rec_path = tmp_path / "job.npz"
    sim = make_sim(speed=20.0, record=rec_path)
    _run(sim, text)
    state = sim.state()
    assert state["safety_mode"] == "NORMAL"
    np.testing.assert_allclose(state["tcp_pose"][:3], targets[-1][:3], atol=1e-6)
    sim.stop()
    rec = recording.load(rec_path)
    # the tool stays on the polyline of movep targets within the blend radii (and round-off)
    start = int(np.argmin(np.linalg.norm(rec.tcp_pose[:, :3] - targets[0][:3], axis=1)))
    P = rec.tcp_pose[start:, :3]
    A, B = targets[:-1, :3], targets[1:, :3]
    d = B - A
    w = np.clip(np.einsum("nkj,kj->nk", P[:, None, :] - A[None], d) / np.einsum("kj,kj->k", d, d), 0, 1)
    dist = np.linalg.norm(P[:, None, :] - (A[None] + w[..., None] * d[None]), axis=2).min(axis=1)
    assert dist.max() <= max(radii) + 1e-6, dist.max()
    assert any("started" in e[2] for e in rec.events)


def test_io_sleep_variables_and_servoj(make_sim):
    sim = make_sim(speed=5.0)
    q1 = (HOME + [0.2, 0, 0, 0, 0, 0]).tolist()
    q2 = (HOME + [0.2 + 1e-3, 0, 0, 0, 0, 0]).tolist()  # servoj targets near the arm (a jump is a protective stop)
    prog = "\n".join([
        "def io_job():",
        "  # a comment",
        f"  local q = {q2}",
        "  local dz = 0.05",
        "  textmsg(\"job \", 1)",
        "  set_standard_digital_out(2, True)",
        "  set_tool_digital_out(1, True)",
        f"  movej({q1}, a=2.0, v=1.0)",
        "  sleep(0.1)",
        "  sync()",
        "  servoj(q, t=0.002, lookahead_time=0.1, gain=300)",
        "  servoj(q, 0, 0, 0.5, 0.1, 300)",
        "  stopj(2.0)",
        f"  movel(p[{', '.join(str(x) for x in forward('ur5e', HOME) + [0, 0, -0.05, 0, 0, 0])}], a=1.2, v=0.25)",
        "  set_standard_digital_out(2, False)",
        "end",
        "",
    ])
    _run(sim, prog)
    st = sim.state()
    assert st["safety_mode"] == "NORMAL", st["log"]
    assert st["digital_out"] == 1 << 17
    assert any(m[2] == "job 1" for m in st["log"])
    np.testing.assert_allclose(st["tcp_pose"], forward("ur5e", HOME) + [0, 0, -0.05, 0, 0, 0], atol=1e-6)


@pytest.mark.parametrize("bad, why", [
    ("  popup(\"hi\")", "does not support popup"),
    ("  if True:", "cannot compile"),
    ("  movej(undefined_q, a=1, v=1)", "undefined variable 'undefined_q'"),
    ("  movel(p[1, 2, 3], a=1, v=1)", "6 values"),
    ("  movej([0, 0, 0, 0, 0, 0], a=1, v=1, speed=3)", "no argument 'speed'"),
])
def test_programs_outside_the_subset_are_refused_whole(make_sim, bad, why):
    sim = make_sim()
    prog = "def job():\n  set_standard_digital_out(1, True)\n  movej([0.1, -1.5, 1.5, -1.5, -1.5, 0.0], a=1, v=1)\n" \
           f"{bad}\nend\n"
    _send(sim.host, prog)
    time.sleep(0.2)
    st = sim.state()
    assert st["runtime_state"] == "STOPPED" and st["digital_out"] == 0
    np.testing.assert_allclose(st["q"], HOME, atol=0)  # never half-run
    assert any("Compile error" in m[2] and "line 4" in m[2] and why in m[2] for m in st["log"]), st["log"]


def test_unreachable_move_in_a_program_is_a_protective_stop(make_sim):
    sim = make_sim()
    _send(sim.host, "def far():\n  movel(p[1.5, 0.0, 0.3, 0.0, 3.14, 0.0], a=1.2, v=0.25)\nend\n")
    time.sleep(0.3)
    st = sim.state()
    assert st["safety_mode"] == "PROTECTIVE_STOP" and st["runtime_state"] == "STOPPED"


def test_the_deprecated_output_setters_python_urx_sends(make_sim):
    """set_digital_out(n, b) and the CB controllers' digital_out[n] = b (python-urx's set_digital_out): outputs 0-7
    standard, 8-9 the tool's; a number beyond 9 stops the program with an error naming its line."""
    sim = make_sim()
    _run(sim, "def job():\n  digital_out[3] = True\n  set_digital_out(9, True)\n  digital_out[8]=True\n"
              "  set_digital_out(3, False)\n  set_digital_out(5, True)\nend\n")
    assert sim.state()["digital_out"] == (1 << 5) | (1 << 16) | (1 << 17)
    _send(sim.host, "digital_out[0] = True\n")  # one line, as python-urx sends it
    assert sim_fixtures.eventually(lambda: sim.state()["digital_out"] & 1)
    _send(sim.host, "def job():\n  set_digital_out(10, True)\nend\n")
    assert sim_fixtures.eventually(lambda: any("line 2" in m[2] and "set_digital_out" in m[2]
                                               for m in sim.state()["log"])), sim.state()["log"]
    assert not sim.state()["digital_out"] & (1 << 10)
