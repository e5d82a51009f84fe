"""Recording of what the simulated controller executes (read back, plotted) and the `python -m sim` entry."""

from __future__ import annotations

import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import rtde_control
import rtde_io
import rtde_receive

from planner.kinematics import forward
from sim import recording
from sim.motion import HOME
from tests import sim_fixtures

make_sim = sim_fixtures.make_sim  # fixture
REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_recording_reads_back_moves_io_and_safety_events(make_sim, tmp_path, suffix):
    path = tmp_path / f"run{suffix}"
    sim = make_sim(record=path)
    c = rtde_control.RTDEControlInterface(sim.host)
    io = rtde_io.RTDEIOInterface(sim.host)
    q1 = HOME + [0.2, -0.1, 0.1, 0.0, 0.1, 0.2]
    try:
        assert c.moveJ(q1.tolist(), 1.0, 2.0)
        assert io.setStandardDigitalOut(2, True)
        time.sleep(0.02)
        assert not c.moveL([1.6, 0, 0.3, 0, 3.14, 0], 0.25, 1.2)  # protective stop
    finally:
        c.disconnect()
        io.disconnect()
    sim.stop()
    assert path.exists() and [p.name for p in tmp_path.iterdir()] in ([path.name], [path.name, "run.events.csv"],
                                                                   ["run.events.csv", path.name])
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask  # the umask's mode, not mkstemp's 0600
    rec = recording.load(path)
    assert np.all(np.diff(rec.t) > 0)
    k = int(np.argmax(np.all(np.abs(rec.actual_q - q1) < 1e-9, axis=1)))
    assert k > 0
    np.testing.assert_allclose(rec.tcp_pose[k], forward("ur5e", q1), atol=1e-7)
    assert rec.digital_out[-1] == 1 << 2 and rec.digital_out[0] == 0
    assert rec.safety_mode[-1] == 3 and rec.safety_mode[0] == 1
    texts = [e[2] for e in rec.events]
    assert any("Protective stop" in t for t in texts)
    assert any("started" in t for t in texts)
    png = recording.plot(rec, tmp_path / "planned_vs_actual.png")
    assert png.stat().st_size > 10_000


def test_load_reports_missing_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        recording.load(tmp_path / "nope.npz")


def test_python_m_sim_runs_until_interrupted(tmp_path):
    host = sim_fixtures.next_host()
    rec = tmp_path / "cli.npz"
    proc = subprocess.Popen([sys.executable, "-m", "sim", "--host", host, "--no-modbus", "--record", str(rec)],
                            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert f"on {host}" in line, line + proc.stderr.read()
        r = rtde_receive.RTDEReceiveInterface(host)
        assert r.getRobotMode() == 7
        r.disconnect()
        os.kill(proc.pid, signal.SIGINT)
        try:
            assert proc.wait(20) == 0
        except subprocess.TimeoutExpired:
            pytest.fail(f"python -m sim ran on 20 s after SIGINT; its signals: "
                        f"{sim_fixtures.signal_state(proc.pid)}, this process's: {sim_fixtures.signal_state(os.getpid())}")
        assert rec.exists() and len(recording.load(rec).t) > 10
    finally:
        if proc.poll() is None:
            proc.kill()
    bad = subprocess.run([sys.executable, "-m", "sim", "--host", "192.0.2.1"], cwd=REPO, capture_output=True,
                         text=True, timeout=60)
    assert bad.returncode == 2 and "not a loopback address" in bad.stderr
