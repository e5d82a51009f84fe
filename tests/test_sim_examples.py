"""ur_rtde's own Python examples (examples/py of the installed version's source distribution, fetched from the
package registry), run unchanged against the simulator but for the controller's address, each checked for what it
is meant to do, from the simulator's recording of every 2 ms.

Left out: ``move_until_contact.py`` (contact detection is not simulated: the arm would move down until a limit),
``joint_pd_torque_control.py`` (direct joint torque control is not simulated), ``realtime_control_example.py``
(needs psutil, which is not a dependency, and runs until Ctrl-C at real-time priority 80, above the simulator's
control loop), ``test_external_control.py`` (needs the External Control URCap on a pendant at 192.168.56.101).
"""

from __future__ import annotations

import csv
import importlib.metadata
import os
import signal
import subprocess
import sys
import tarfile
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from planner.kinematics import forward
from sim import recording
from sim.motion import DT, HOME, JOINT_ACCEL_MAX, servo_following_error
from tests import sim_fixtures
from tests.sim_fixtures import signal_state

make_sim = sim_fixtures.make_sim  # fixture
#: ``python -c`` running an example script (argv[1:]) as from a terminal: SIGINT unblocked and raising KeyboardInterrupt.
AS_FROM_A_TERMINAL = ("import runpy, signal, sys; signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT}); "
                      "signal.signal(signal.SIGINT, signal.default_int_handler); sys.argv = sys.argv[1:]; "
                      "runpy.run_path(sys.argv[0], run_name='__main__')")
EXAMPLE_Q = [-1.54, -1.83, -2.28, -0.59, 1.60, 0.023]  # the start joints of the servo, speed and force examples


@pytest.fixture(scope="session")
def examples(pytestconfig) -> Path:
    """examples/py of the installed ur_rtde's source distribution (downloaded once into pytest's cache)."""
    version = importlib.metadata.version("ur_rtde")
    cache = pytestconfig.cache.mkdir(f"ur_rtde-{version}-sdist")
    folder = cache / f"ur_rtde-{version}" / "examples" / "py"
    if not folder.is_dir():
        cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--no-binary", ":all:",
               f"ur-rtde=={version}", "-d", str(cache)]
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        archives = sorted(cache.glob(f"ur_rtde-{version}.tar.gz"))
        if done.returncode or not archives:
            pytest.fail(f"cannot fetch ur_rtde {version}'s source distribution: {done.stderr.strip()[-500:]}")
        with tarfile.open(archives[0]) as tar:
            members = [m for m in tar.getmembers() if "/examples/py/" in m.name and m.isfile()]
            tar.extractall(cache, members=members, filter="data")
    assert folder.is_dir(), folder
    return folder


def _run(examples: Path, name: str, host: str, tmp_path: Path, args=(), interrupt_after: float | None = None,
         timeout: float = 90.0) -> str:
    """Run example ``name`` against ``host`` (its one address literal replaced); its output; fails on an error."""
    text = (examples / name).read_text()
    for literal in ('"127.0.0.1"', '"localhost"', "'localhost'"):
        text = text.replace(literal, repr(host))
    script = tmp_path / name
    script.write_text(text)
    # run as a person runs it from a terminal: Ctrl-C raises KeyboardInterrupt in it, whatever this process's thread
    # blocks or ignores (CI saw a SIGINT never reach the example, three times in one run of the whole suite)
    proc = subprocess.Popen([sys.executable, "-c", AS_FROM_A_TERMINAL, str(script), *args], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, cwd=tmp_path)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(proc.stdout.readline, "")), daemon=True)
    reader.start()
    try:
        if interrupt_after is not None:
            # interrupted once it has begun its loop (its first line printed): a SIGINT during its imports or its
            # connection (seconds on a loaded machine) is lost in ur_rtde's C++ code, and the example runs on
            deadline = time.monotonic() + timeout
            while not lines and proc.poll() is None and time.monotonic() < deadline:
                time.sleep(0.05)
            time.sleep(interrupt_after)
            proc.send_signal(signal.SIGINT)
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        state = signal_state(proc.pid)
        proc.kill()
        proc.wait()
        reader.join(5.0)
        pytest.fail(f"{name} did not finish within {timeout} s (its signals: {state}, this process's: "
                    f"{signal_state(os.getpid())}):\n{''.join(lines)[-2000:]}")
    reader.join(10.0)
    out = "".join(lines)
    assert proc.returncode == 0, f"{name} failed ({proc.returncode}):\n{out[-2000:]}"
    return out


def _recorded(sim, tmp_path: Path) -> recording.Recording:
    sim.stop()
    rec = recording.load(tmp_path / "run.npz")
    faults = [e for e in rec.events if "Protective stop" in e[2] or "Runtime error" in e[2]]
    assert not faults, faults
    assert np.all(rec.safety_mode == 1)
    return rec


def _accelerations(q: np.ndarray) -> np.ndarray:
    return np.abs(np.diff(q, 2, axis=0)) / DT**2


def test_io_example_switches_the_outputs(make_sim, examples, tmp_path):
    sim = make_sim()
    out = _run(examples, "io_example.py", sim.host, tmp_path)
    lines = out.splitlines()
    # before: both low; after (read back 10 ms after setting them: a race on any controller) printed too
    assert lines[:2] == ["Standard digital out (7) is LOW", "Tool digital out (16) is LOW"]
    assert [x.rsplit(" ", 1)[0] for x in lines[2:]] == ["Standard digital out (7) is", "Tool digital out (16) is"]
    st = sim.state()
    assert st["digital_out"] == (1 << 7) | (1 << 16)
    assert st["analog_out"][1] == pytest.approx(0.004 + 0.016 * 0.25)  # current ratio 0.25 of 4-20 mA


def test_move_async_example_stops_its_moves_and_returns(make_sim, examples, tmp_path):
    sim = make_sim(record=tmp_path / "run.npz")
    _run(examples, "move_async_example.py", sim.host, tmp_path)
    rec = _recorded(sim, tmp_path)
    q = rec.actual_q
    # the first move (joint 0 by +0.2 rad) is stopped by stopJ before its target, the second (tool up 0.1 m) by stopL
    assert 0.02 < q[:, 0].max() - HOME[0] < 0.2 - 0.01
    z0 = forward("ur5e", HOME)[2]
    assert 0.005 < rec.tcp_pose[:, 2].max() - z0 < 0.1 - 0.005
    np.testing.assert_allclose(q[-1], HOME, atol=1e-9)  # back at the start
    assert _accelerations(q).max() <= JOINT_ACCEL_MAX


def test_movel_path_with_blend_example_reaches_its_last_pose(make_sim, examples, tmp_path):
    sim = make_sim(record=tmp_path / "run.npz")
    _run(examples, "movel_path_with_blend_example.py", sim.host, tmp_path)
    rec = _recorded(sim, tmp_path)
    first, last = [-0.143, -0.435, 0.20, -0.001, 3.12, 0.04], [-0.32, -0.61, 0.31, -0.001, 3.12, 0.04]
    np.testing.assert_allclose(rec.tcp_pose[-1], last, atol=1e-6)
    # the first waypoint has no blend: the tool passes through it at rest
    near = np.linalg.norm(rec.tcp_pose[:, :3] - first[:3], axis=1)
    assert near.min() < 1e-5
    assert _accelerations(rec.actual_q).max() <= JOINT_ACCEL_MAX


def test_move_path_async_example_reports_progress_and_finishes(make_sim, examples, tmp_path):
    sim = make_sim(record=tmp_path / "run.npz")
    out = _run(examples, "move_path_async_example.py", sim.host, tmp_path)
    assert "Async path started.." in out and "Async path finished..." in out
    assert out.count("Moving to path waypoint") >= 3
    rec = _recorded(sim, tmp_path)
    np.testing.assert_allclose(rec.tcp_pose[-1], [-0.140, -0.400, 0.100, 0, 3.14, 0], atol=1e-6)
    # the path was run twice (synchronously, then asynchronously): its top corner was visited twice
    top = np.linalg.norm(rec.tcp_pose[:, :3] - [-0.140, -0.600, 0.300], axis=1) < 0.11
    assert np.count_nonzero(np.diff(top.astype(int)) == 1) == 2


def test_servoj_example_follows_its_ramp(make_sim, examples, tmp_path):
    sim = make_sim(record=tmp_path / "run.npz")
    _run(examples, "servoj_example.py", sim.host, tmp_path)
    rec = _recorded(sim, tmp_path)
    end = np.array(EXAMPLE_Q)
    end[:2] += 1000 * 0.001  # the last servo target, 1 rad further on joints 0 and 1
    # where servoStop left it: behind the last target by at most the servo's following error at 0.5 rad/s
    lag = end[:2] - rec.actual_q[-1, :2]
    assert np.all((0 < lag) & (lag < servo_following_error(0.5, 0.1, 300))), lag
    np.testing.assert_allclose(rec.actual_q[-1, 2:], EXAMPLE_Q[2:], atol=1e-9)


def test_speedj_example_speeds_up_its_two_joints(make_sim, examples, tmp_path):
    sim = make_sim(record=tmp_path / "run.npz")
    _run(examples, "speedj_example.py", sim.host, tmp_path)
    rec = _recorded(sim, tmp_path)
    moved = rec.actual_q[-1] - EXAMPLE_Q
    # 1000 periods of a speed ramping by 0.0005 rad/s each: 0.5 rad/s reached, at least 0.5 rad covered (more when
    # the client's loop runs slower than 500 Hz: the arm keeps each speed until the next command)
    assert moved[0] == pytest.approx(moved[1]) and moved[0] > 0.45
    np.testing.assert_allclose(moved[2:], 0.0, atol=1e-9)
    qd = np.diff(rec.actual_q[:, 0]) / DT
    assert 0.45 < qd.max() < 0.55


def test_forcemode_example_runs_its_force_mode_in_place(make_sim, examples, tmp_path):
    """Force mode is accepted and not simulated (README): the arm reaches the example's start and stays there."""
    sim = make_sim(record=tmp_path / "run.npz")
    _run(examples, "forcemode_example.py", sim.host, tmp_path)
    rec = _recorded(sim, tmp_path)
    at = np.flatnonzero(np.all(np.abs(rec.actual_q - EXAMPLE_Q) < 1e-9, axis=1))
    assert len(at) and rec.t[-1] - rec.t[at[0]] > 3.5  # at the start joints through the 4 s of force mode
    np.testing.assert_allclose(rec.actual_q[at[0]:], np.broadcast_to(EXAMPLE_Q, rec.actual_q[at[0]:].shape))


def test_record_data_example_records_at_the_rate_asked(make_sim, examples, tmp_path):
    sim = make_sim()
    _run(examples, "record_data_example.py", sim.host, tmp_path, args=["-ip", sim.host, "-f", "250"],
         interrupt_after=3.0)
    with open(tmp_path / "robot_data.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    t = np.array([float(r["timestamp"]) for r in rows])
    assert len(rows) > 250  # more than a second of data
    assert np.median(np.diff(t)) == pytest.approx(0.004)  # 250 Hz on the controller's clock
    assert np.diff(t).min() >= 0  # the example samples on its own clock: a package may be written twice
    # the CSV holds 6 significant digits
    np.testing.assert_allclose([float(rows[-1][f"actual_q_{j}"]) for j in range(6)], HOME, atol=1e-6)
