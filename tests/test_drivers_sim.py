"""drivers.sim.SimDriver: the simulated controller's motion model in-process, as a RobotDriver.

The demo job (the first pass of the real NX file, placed for a UR5e as ``planner demo`` places it) is run
in-process, and the same job by drivers.ur.URDriver through real ur_rtde (outputs through real pymodbus) into a
SimController child process: the recorded joint paths agree to the servo following error (stream) and to round-off
(program: no real-time client in the loop), and so do the two execution reports."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from drivers.base import CancelledError, DriverError, NotReadyError, ProtectiveStopError, RobotDriver
from drivers.report import planned_path
from drivers.servo import ServoModel, ServoShaper
from drivers.sim import SimDriver
from drivers.ur import URDriver
from planner import PlanSettings, plan
from planner.frontends.cli.main import DEMO_PART, EXAMPLE_CLS, example_path
from sim import recording
from sim.motion import DT, servo_following_error
from tests import sim_fixtures

make_sim = sim_fixtures.make_sim  # fixture

LOOKAHEAD, GAIN = 0.1, 300.0


def demo_job(feed_override: float = 1.0, **kwargs):
    part = DEMO_PART
    settings = PlanSettings(robot="ur5e", part_frame=part, cut_output=("tool", 0), feed_override=feed_override,
                            **kwargs)
    return plan(example_path(EXAMPLE_CLS), settings)


@pytest.fixture(scope="module")
def fast_job():
    """The demo job at 10 x its feed (about 7 s of motion)."""
    return demo_job(10.0)


def planned_joints(job) -> np.ndarray:
    return np.concatenate([c.joints for c in job.trajectory().chunks()])


def following_bound(Q: np.ndarray) -> float:
    """The motion model's servo following error for the fastest joint of the planned joints, rad."""
    v = float(np.abs(np.diff(Q, axis=0)).max() / DT)
    return servo_following_error(v, LOOKAHEAD, GAIN)


# -- in-process runs ----------------------------------------------------------------------------------

def test_is_a_robot_driver():
    assert isinstance(SimDriver(), RobotDriver)


def test_stream_follows_the_planned_joints(fast_job):
    """Unshaped targets (the former defaults, lookahead 0.1 s, gain 300): the planner's own joints are commanded as
    they are and the arm lags them by the servo's following error."""
    Q = planned_joints(fast_job)
    with SimDriver(record=True, lookahead=LOOKAHEAD, gain=GAIN, compensate=False) as d:
        report = d.execute(fast_job, mode="stream")
        rec = d.recording
        state = d.state()
    assert report.ok, "\n".join(report.describe())
    assert report.mode == "stream"
    n = len(Q)
    # one servo target per sample, in order: the commanded joints are the planner's own
    np.testing.assert_array_equal(rec["target_q"][:n], Q)
    lag = np.abs(rec["actual_q"][:n] - Q).max()
    bound = following_bound(Q)
    assert lag <= 1.01 * bound, (lag, bound)
    assert lag > 0.1 * bound  # the servo lag is modelled, not zero
    # recorded for the planned duration, the 0.3 s hold of the last target and 10 periods of the stop
    assert report.duration == pytest.approx(report.planned_duration + 0.3 + 10 * DT, abs=2 * DT)
    assert report.max_path_error < 0.5e-3  # at 10 x the feed the servo lag cuts the corners by about 0.2 mm
    assert len(report.io_events) == 2 and all(e.switched for e in report.io_events)
    # at rest at the job's last joints (the last target held until the lagging arm arrived), outputs as the job
    # leaves them (off after the cut)
    assert np.abs(np.asarray(state.joints) - Q[-1]).max() < 0.01 * bound
    assert state.digital_out == 0 and state.ready and not state.program_running


def test_stream_shaped_targets_put_the_arm_on_the_planned_joints(fast_job):
    """The defaults (lookahead 0.03 s, gain 2000, targets shaped by the servo model): the targets lead the plan and
    the arm, one control period after each, is on the planned joints to round-off: no lag, no corner cut."""
    Q = planned_joints(fast_job)
    with SimDriver(record=True) as d:
        report = d.execute(fast_job, mode="stream")
        rec = d.recording
        state = d.state()
    assert report.ok, "\n".join(report.describe())
    n = len(Q)
    lead = np.abs(rec["target_q"][:n] - Q).max()
    assert lead > 1e-3  # shaped: the targets are not the planned joints (~v * 20 ms ahead)
    assert np.abs(rec["actual_q"][:n] - Q).max() < 1e-9
    assert report.max_path_error < 1e-6  # 0.2 mm with the former defaults (the test above)
    assert report.max_io_distance_mm < 1e-3
    assert np.abs(np.asarray(state.joints) - Q[-1]).max() < 1e-9 and state.digital_out == 0


def test_demo_job_dry_run_meets_the_streaming_targets():
    """The demo job at its own feed, streamed in-process: the issue's targets for the stream through ur_rtde
    (actual TCP within 0.2 mm of the planned path). The tool output's switch lags its station by the servo
    following distance unless switched when the actual TCP reaches it, as the drivers do: within 1 mm."""
    job = demo_job()
    with SimDriver() as d:
        report = d.execute(job, mode="stream")
    assert report.ok, "\n".join(report.describe())
    assert report.max_path_error < 0.2e-3
    assert all(e.switched for e in report.io_events)
    assert report.max_io_distance_mm < 1.0


def test_program_runs_the_exported_script_within_its_tolerance(fast_job):
    with SimDriver() as d:
        report = d.execute(fast_job, mode="program")
    assert report.ok, "\n".join(report.describe())
    assert report.max_path_error < 0.05e-3  # movep within 10 um of the path, blends of at most 0.25 mm radius
    assert all(e.switched and e.distance_mm < 0.05 for e in report.io_events)
    # movep runs on trapezoids (no jerk limit): a few per cent faster than the planned jerk-limited feed
    assert report.duration == pytest.approx(report.planned_duration, rel=0.05)


def test_progress_reaches_the_end(fast_job):
    seen = []
    with SimDriver() as d:
        d.execute(fast_job, mode="stream", progress=lambda stage, done, total: seen.append((stage, done, total)))
    assert seen and all(s == "execute" for s, _, _ in seen)
    assert [x[1] for x in seen] == sorted(x[1] for x in seen)
    assert seen[-1][1] == seen[-1][2] == planned_path(fast_job)[0].size


@pytest.mark.parametrize("mode", ["stream", "program"])
def test_cancel_from_another_thread_stops_the_arm(fast_job, mode):
    cancel = threading.Event()
    with SimDriver(speed=10.0) as d:  # paced: about 0.7 s of wall time for the job
        d.move_to_start(fast_job)

        def cancel_at_0_6_s(stage, k, total):  # from the driver's progress, at 0.6 s of job time (however loaded)
            if k * DT >= 0.6:
                threading.Thread(target=cancel.set).start()  # (from another thread)

        report = d.execute(fast_job, mode=mode, cancel=cancel, progress=cancel_at_0_6_s)
        state = d.state()
        qd = d.core.motion.qd
    assert not report.ok and isinstance(report.failure, CancelledError)
    f = report.failure
    assert "cancelled by the caller" in f.reason
    assert 0.5 < f.t < report.planned_duration and len(f.pose) == 6 and f.line is not None
    planned = fast_job.trajectory().collect(joints=False)
    k = int(round(f.t / DT))
    np.testing.assert_allclose(f.pose, planned.poses[k])
    assert f.line == planned.lines[k]
    assert np.abs(qd).max() == 0.0 and state.digital_out == 0  # at rest, the job's output off


def test_stop_from_another_thread(fast_job):
    with SimDriver(speed=10.0) as d:
        d.move_to_start(fast_job)
        threading.Timer(0.3, d.stop).start()
        report = d.execute(fast_job, mode="stream")
    assert isinstance(report.failure, CancelledError) and "driver.stop()" in report.failure.reason


def test_pause_holds_the_arm_on_the_path(fast_job):
    with SimDriver(speed=10.0) as d:
        def pause_and_resume():
            d.pause()
            time.sleep(0.2)  # 2 s of simulated time
            d.resume()

        d.move_to_start(fast_job)
        threading.Timer(0.35, pause_and_resume).start()
        report = d.execute(fast_job, mode="stream")
    with SimDriver() as d:
        base = d.execute(fast_job, mode="stream")
    assert report.ok, "\n".join(report.describe())
    # held on the path, not off it: within the stream mode's accuracy figure (0.05 mm) of the unpaused run (the
    # servo shaping of the stop and the restart, wherever the pause falls, moves it by up to about 0.02 mm)
    assert report.max_path_error == pytest.approx(base.max_path_error, abs=0.05e-3)
    # the arm held still for about 2 s of recorded control periods (the job clock stops meanwhile)
    assert report.samples - base.samples == pytest.approx(2.0 / DT, rel=0.3)
    assert report.duration == pytest.approx(base.duration)


def test_joint_limit_is_a_protective_stop_with_time_pose_and_line(fast_job):
    """A joint leaving its position limits is a protective stop (here a reduced safety limit on the joint that
    moves most, halfway along its travel)."""
    Q = planned_joints(fast_job)
    j = int(np.argmax(np.ptp(Q, axis=0)))
    up = Q[:, j].max() - Q[0, j] > Q[0, j] - Q[:, j].min()
    with SimDriver() as d:
        d.move_to_start(fast_job)
        m = d.core.motion
        if up:
            m.upper = m.upper.copy()
            m.upper[j] = 0.5 * (Q[0, j] + Q[:, j].max())
        else:
            m.lower = m.lower.copy()
            m.lower[j] = 0.5 * (Q[0, j] + Q[:, j].min())
        report = d.execute(fast_job, mode="stream")
        state = d.state()
        qd = m.qd.copy()
    f = report.failure
    assert isinstance(f, ProtectiveStopError), report.describe()
    assert f"joint {j}" in f.reason and "outside its limits" in f.reason
    assert 0 < f.t < report.planned_duration and len(f.pose) == 6 and f.line > 0
    # the planned pose named is the one being commanded when the limit was crossed: the shaped target leads the plan
    # by the servo's lag (lookahead / 2 + 10 / gain: 20 ms), so the plan crosses it within that lag
    k = int(round(f.t / DT))
    lead = int(np.ceil(ServoModel(0.03, 2000.0).lag / DT)) + 1
    ahead = Q[k:k + lead, j]
    assert (ahead.max() > m.upper[j]) if up else (ahead.min() < m.lower[j])
    assert (Q[k - lead, j] <= m.upper[j]) if up else (Q[k - lead, j] >= m.lower[j])
    assert state.protective_stop and np.abs(qd).max() == 0.0 and state.digital_out == 0


def test_refusals():
    d = SimDriver()
    job = demo_job(10.0)
    with pytest.raises(NotReadyError, match="connect"):
        d.execute(job)
    d.connect()
    with pytest.raises(ValueError, match="mode must be one of"):
        d.execute(job, mode="servoL")
    with pytest.raises(DriverError, match="planned for ur5e, the simulated robot is a ur10e"):
        SimDriver("ur10e").execute(job)
    with pytest.raises(ValueError, match="lookahead"):
        SimDriver(lookahead=0.5)
    with pytest.raises(ValueError, match="speed must be > 0"):
        SimDriver(speed=0)


# -- the same job on the simulated controller through URDriver (real ur_rtde, outputs through real pymodbus) --

def _run_urdriver(sim, job, mode: str):
    driver = URDriver(sim.host, "ur5e", io="modbus", modbus_port=sim.ports["modbus"])
    driver.connect()
    try:
        return driver.execute(job, mode=mode)
    finally:
        driver.close()


def _compare_stream(make_sim, tmp_path, job):
    path = tmp_path / "ctrl.npz"
    sim = make_sim(record=path, modbus_port=5020)
    ur_report = _run_urdriver(sim, job, "stream")
    sim.stop()
    assert ur_report.ok, "\n".join(ur_report.describe())
    ctrl = recording.load(path)
    with SimDriver(record=True) as d:
        report = d.execute(job, mode="stream")
        rec = d.recording
    assert report.ok
    Q = planned_joints(job)
    U = ServoShaper(ServoModel(0.03, 2000.0), job.start_joints).shape(Q)  # the targets both drivers send
    index = {q.tobytes(): k for k, q in enumerate(U)}
    ks = np.array([index.get(q.tobytes(), -1) for q in ctrl.target_q])
    rows = np.flatnonzero(ks >= 0)
    # from the first target that moves (the stream's start) to the last one (then the hold); the controller reads
    # the latest target each period, so under load two targets arriving within one of its periods show as one:
    # neither target 1 nor the last need be in its recording
    rows = rows[rows >= rows[np.flatnonzero(ks[rows] >= 1)[0]]]
    rows = rows[: np.flatnonzero(ks[rows] == ks[rows].max())[0] + 1]
    assert len(np.unique(ks[rows])) > 0.95 * len(Q)  # (nearly) every target reached the controller
    diff = np.abs(ctrl.actual_q[rows] - rec["actual_q"][ks[rows]]).max()
    bound = following_bound(Q)
    assert diff <= bound, (diff, bound)
    # the two reports agree: the path error, and where the outputs switched along the path
    assert abs(ur_report.max_path_error - report.max_path_error) < 0.05e-3
    assert len(ur_report.io_events) == len(report.io_events) == 2
    for a, b in zip(ur_report.io_events, report.io_events, strict=True):
        assert a.switched and b.switched and abs(a.actual_s - b.actual_s) < 0.2e-3
    return diff, bound, report, ur_report


@pytest.mark.realtime  # streams through ur_rtde at 500 Hz
def test_stream_records_the_simulated_controllers_trajectory(make_sim, tmp_path):
    job = demo_job(4.0)
    diff, bound, *_ = _compare_stream(make_sim, tmp_path, job)
    assert diff < 0.5 * bound


def _compare_program(make_sim, tmp_path, job):
    path = tmp_path / "ctrl_program.npz"
    sim = make_sim(record=path, modbus_port=5020)
    ur_report = _run_urdriver(sim, job, "program")
    sim.stop()
    assert ur_report.ok, "\n".join(ur_report.describe())
    ctrl = recording.load(path)
    t_start = next(t for t, src, text in ctrl.events if src == "Program" and text == "program planner_job started")
    rows = np.flatnonzero(ctrl.t > t_start + 1e-9)
    with SimDriver(record=True) as d:
        report = d.execute(job, mode="program")
        rec = d.recording
    assert report.ok
    n = len(rec["t"])
    assert len(rows) >= n
    np.testing.assert_allclose(ctrl.actual_q[rows[:n]], rec["actual_q"], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(ctrl.digital_out[rows[:n]], rec["digital_out"])
    assert abs(ur_report.max_path_error - report.max_path_error) < 0.01e-3


def test_program_records_the_simulated_controllers_trajectory(make_sim, tmp_path):
    _compare_program(make_sim, tmp_path, demo_job(4.0))


@pytest.mark.slow
@pytest.mark.realtime
def test_whole_demo_job_on_both(make_sim, tmp_path):
    """The demo job at its own feed (62 s of motion, twice in real time)."""
    job = demo_job()
    diff, bound, report, ur_report = _compare_stream(make_sim, tmp_path, job)
    assert report.max_path_error < 0.2e-3 and ur_report.max_path_error < 0.2e-3
    assert report.max_io_distance_mm < 1.0 and ur_report.max_io_distance_mm < 1.0
    _compare_program(make_sim, tmp_path, job)


_LONG_CHILD = """
import json, resource, sys
from drivers.sim import SimDriver
from planner import PlanSettings, plan
job = plan("examples/nx_first_pass.cls", PlanSettings(robot="ur5e", part_frame=(0.4, 0.9965, -0.1, 0, 0, 0),
                                                     cut_output=("standard", 0), feed_override=float(sys.argv[1])))
with SimDriver() as d:
    rep = d.execute(job, mode="stream")
print(json.dumps({"n": job.trajectory().n_samples, "rss_kib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
                  "ok": rep.ok, "trace": len(rep.trace), "samples": rep.samples, "error": rep.max_path_error,
                  "io": [e.distance_mm for e in rep.io_events]}))
"""


@pytest.mark.slow
def test_long_stream_memory_is_bounded_by_the_plan_not_the_recording():
    """The demo pass at 0.45x and 0.15x its feed (68k and 204k samples, 2 and 7 min of motion) through SimDriver,
    each in a child process: the peak RSS grows by less than 400 bytes per sample of the job (the planned path
    the report measures against: ~80 B of arrays and its k-d tree; the recording itself is reduced as it goes and
    the trace stays under 20,000 samples). Recording every sample, as the drivers did, grew by ~3.6 kB/sample."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).resolve().parents[1]
    runs = []
    for fo in ("0.45", "0.15"):
        p = subprocess.run([sys.executable, "-c", _LONG_CHILD, fo], cwd=repo, capture_output=True, text=True,
                           timeout=600)
        assert p.returncode == 0, p.stderr[-2000:]
        runs.append(json.loads(p.stdout.strip().splitlines()[-1]))
    short, long = runs
    assert long["n"] > 2.9 * short["n"] and short["n"] > 65_536  # both longer than one trajectory chunk
    for r in runs:
        assert r["ok"] and r["samples"] >= r["n"]
        assert r["trace"] <= 20_000
        assert r["error"] < 0.2e-3 and len(r["io"]) == 2 and max(r["io"]) < 1.0
    growth = (long["rss_kib"] - short["rss_kib"]) * 1024 / (long["n"] - short["n"])
    assert growth < 400, f"{growth:.0f} bytes per sample"


def reconfiguring_job(tmp_path):
    """Real NX passes of lines 20238-20330 at 10x their feed (18 s): three passes, then the arm changes its
    configuration by a joint move (3.8 s) before the rapid at line 20299 and the pass after it
    (tests/test_cam_reconfigure.py shows why), the cut output on standard DO 0 during the cuts."""
    from tests.test_cam_reconfigure import NX_PART, _nx_excerpt

    src = tmp_path / "ust_a2_20238.cls"
    src.write_text(_nx_excerpt(20238, 20330))
    job = plan(src, PlanSettings(path="cam", feed=0.05, part_frame=NX_PART, robot="ur5e", feed_override=10.0,
                                 cut_output=("standard", 0)))
    assert job.reachable and not job.problems and len(job.reconfigurations) == 1
    assert job.duration < 20.0
    return job


#: servoJ lookahead of the reconfiguring job's runs: at 10x the feed (0.5 m/s) the default 0.1 s lags 0.3 mm off
#: the path at the end of a pass; 0.05 s keeps it within 0.2 mm.
RECONF_LOOKAHEAD = 0.05


def check_reconfigured_run(job, report, t, actual_q, commanded_q=None) -> None:
    """A stream run of ``reconfiguring_job`` (lookahead RECONF_LOOKAHEAD): no fault, every pass within 0.2 mm of
    its planned path, every output switch within 1 mm of its station, and the joint move of the reconfiguration
    made (the arm's joints follow the planned ones through it, within the servo's following error, and end on
    the new configuration)."""
    assert report.ok, "\n".join(report.describe())
    assert report.max_path_error <= 0.2e-3, report.describe()
    n_cuts = sum(1 for m in job.moves if m.kind == "cut")
    assert 2 <= len(report.io_events) <= 2 * n_cuts
    assert all(e.switched and e.distance_mm <= 1.0 for e in report.io_events), report.describe()
    moves = job.trajectory().moves()
    (mv,) = [m for m in moves if m["kind"] == "reconfiguration"]
    q_from, q_to = np.asarray(mv["q_from"]), np.asarray(mv["q_to"])
    assert np.abs(q_to - q_from).max() > 1.0  # a real change of configuration, not a small adjustment
    Q = planned_joints(job)
    bound = servo_following_error(float(np.abs(np.diff(Q, axis=0)).max() / DT), RECONF_LOOKAHEAD, GAIN)
    rate = job.settings.rate
    t0, t1 = mv["t_start"], mv["t_start"] + mv["duration_s"]
    # through the joint move (and half a second either side) the joints follow the planned ones within the
    # servo's following error: time-aligned on the job clock
    window = (t > t0 - 0.5) & (t < t1 + 0.5)
    assert window.sum() > 0.9 * (t1 - t0 + 1.0) * rate
    k = np.clip(np.round(t[window] * rate).astype(int), 0, len(Q) - 1)
    assert np.abs(actual_q[window] - Q[k]).max() <= bound
    assert np.abs(actual_q[-1] - Q[-1]).max() < 1e-3  # at rest on the job's last joints: the new configuration
    if commanded_q is not None:
        assert np.abs(actual_q - commanded_q).max() <= bound


def test_stream_whole_job_with_a_reconfiguration(tmp_path):
    job = reconfiguring_job(tmp_path)
    with SimDriver(record=True, lookahead=RECONF_LOOKAHEAD) as d:
        rep = d.execute(job, mode="stream")
        rec = d.recording
    check_reconfigured_run(job, rep, rec["t"], rec["actual_q"], rec["target_q"])
