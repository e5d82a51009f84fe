"""The execution report's figures from recorded samples: distance to the planned path (not time-aligned), I/O
switches against their stations, joint-limit margin, failures with their place."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.base import DriverError, ProtectiveStopError
from drivers.report import distance_to_polyline, execution_report, planned_path
from planner import PlanSettings, plan

PART = (0.4, 0.9965, -0.1, 0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def job():
    return plan("examples/nx_first_pass.cls", PlanSettings(robot="ur5e", part_frame=PART, cut_output=("standard", 0)))


def _brute(points, path):
    a, b = path[:-1], path[1:]
    d = b - a
    w = np.clip(np.einsum("nkj,kj->nk", points[:, None] - a[None], d) / np.einsum("kj,kj->k", d, d), 0, 1)
    return np.linalg.norm(points[:, None] - (a[None] + w[..., None] * d[None]), axis=2).min(axis=1)


def test_distance_to_polyline_matches_brute_force():
    rng = np.random.default_rng(1)
    s = np.linspace(0, 3 * np.pi, 400)
    path = np.c_[np.cos(s), np.sin(s), 0.1 * s] * 0.1
    path = np.repeat(path, 2, axis=0)  # rests (repeated vertices) as at move boundaries
    pts = path[rng.integers(0, len(path), 300)] + rng.normal(scale=1e-3, size=(300, 3))
    d, _ = distance_to_polyline(pts, path)
    np.testing.assert_allclose(d, _brute(pts, path[::2]), atol=1e-12)


def test_planned_run_has_no_path_error_and_switches_on_its_stations(job):
    c = job.trajectory().collect()
    rep = execution_report(job, c.times, c.poses, c.joints, c.io, mode="replay")
    assert rep.ok and rep.max_path_error < 1e-12
    assert rep.planned_duration == pytest.approx(job.trajectory().duration)
    assert [(e.bit, e.value) for e in rep.io_events] == [(0, True), (0, False)]
    assert all(e.distance_mm < 1e-9 and e.actual_s == pytest.approx(e.planned_s) for e in rep.io_events)
    lim = math.tau  # UR5e joints: +-2 pi
    assert rep.joint_limit_margin == pytest.approx(float(np.min(lim - np.abs(c.joints))))


def test_late_but_on_the_path_is_no_path_error_offset_is(job):
    c = job.trajectory().collect()
    late = np.concatenate((np.repeat(c.poses[:1], 200, axis=0), c.poses))  # 0.4 s late, same path
    t = np.arange(len(late)) / 500.0
    q = np.concatenate((np.repeat(c.joints[:1], 200, axis=0), c.joints))
    io = np.concatenate((np.zeros(200, np.int64), c.io))
    rep = execution_report(job, t, late, q, io, mode="replay")
    assert rep.max_path_error < 1e-12
    assert rep.duration == pytest.approx(rep.planned_duration + 0.4)
    off = c.poses.copy()
    off[:, 2] += 0.3e-3
    rep = execution_report(job, c.times, off, c.joints, c.io, mode="replay")
    assert rep.max_path_error == pytest.approx(0.3e-3, rel=1e-3)
    assert max(e.distance_mm for e in rep.io_events) == pytest.approx(0.3, rel=1e-3)


def test_switch_late_by_ten_samples_is_measured_along_the_path(job):
    c = job.trajectory().collect()
    io = np.concatenate((np.zeros(10, np.int64), c.io))  # every switch 10 samples (20 ms) late
    poses = np.concatenate((c.poses, np.repeat(c.poses[-1:], 10, axis=0)))  # the tool rests at the end
    q = np.concatenate((c.joints, np.repeat(c.joints[-1:], 10, axis=0)))
    rep = execution_report(job, np.arange(len(io)) / 500.0, poses, q, io, mode="replay")
    assert rep.io_events[0].distance_mm > 1e-3  # on at the start of the cut (accelerating from rest): it moved on
    pt, pp, pio, _, ps = planned_path(job)
    for e in rep.io_events:
        k = int(round(e.planned_t * 500))
        # the switch is seen first at sample k + 10; the last sample with the old state is k + 9: the station
        # is behind that step, so its nearest point is the step's start
        a, b = pp[min(k + 9, len(pp) - 1), :3], pp[min(k + 10, len(pp) - 1), :3]
        assert e.distance_mm == pytest.approx(np.linalg.norm(a - pp[k, :3]) * 1e3, abs=1e-9)
        assert e.resolution_mm == pytest.approx(np.linalg.norm(b - a) * 1e3, abs=1e-9)
        assert e.actual_t == pytest.approx(e.planned_t + 0.018)


def test_missing_switch_and_failure_are_reported(job):
    c = job.trajectory().collect()
    n = len(c.times) // 2
    err = ProtectiveStopError("protective stop (safety mode PROTECTIVE_STOP)", t=c.times[n], pose=c.poses[n],
                              line=int(c.lines[n]))
    rep = execution_report(job, c.times[:n], c.poses[:n], c.joints[:n], c.io[:n], mode="stream", failure=err)
    assert not rep.ok and rep.failure is err and rep.reason.startswith("protective stop")
    assert [e.switched for e in rep.io_events] == [True, False]
    text = "\n".join(rep.describe())
    assert "FAILED" in text and f"source line {err.line}" in text and "not switched" in text
    assert isinstance(err, DriverError) and err.kind == "protective stop"


def test_recorded_arrays_must_agree(job):
    with pytest.raises(ValueError, match="recorded_io has 2 samples"):
        execution_report(job, [0.0, 0.1, 0.2], np.zeros((3, 6)), np.zeros((3, 6)), [0, 0], mode="x")


def test_recording_reduced_in_blocks_with_a_small_trace_gives_the_same_report(job):
    """The report from a Recording fed sample by sample in blocks of 700 with a trace of at most 300 samples equals
    the report from the whole arrays: same path error, margin, duration and the same I/O switches (the trace
    keeps every output change and the sample before it), with outputs toggled 40 times."""
    from drivers.recording import Recording
    from drivers.report import new_recording

    c = job.trajectory().collect()
    rng = np.random.default_rng(3)
    x = c.poses + np.r_[rng.normal(scale=2e-5, size=(len(c.times), 3)).T, np.zeros((3, len(c.times)))].T
    io = c.io.copy()
    for a in np.sort(rng.choice(np.arange(100, len(io) - 100), 40, replace=False)):
        io[a:a + 3] ^= 1 << 17  # the tool output blips on for three samples
    full = execution_report(job, c.times, x, c.joints, io, mode="replay")
    planned = planned_path(job)
    rec = Recording(planned[1][:, :3], "ur5e", float(planned[4][-1]), max_trace=300, block=700)
    for i in range(len(c.times)):
        rec.add(float(c.times[i]), x[i], c.joints[i], int(io[i]))
    small = execution_report(job, rec, mode="replay", planned=planned)
    assert len(small.trace) <= 300 < len(full.trace)
    assert small.max_path_error == full.max_path_error and small.max_path_error_t == full.max_path_error_t
    assert small.joint_limit_margin == full.joint_limit_margin and small.duration == full.duration
    assert small.samples == full.samples == len(c.times)
    assert small.io_events == full.io_events and len(small.io_events) == 2  # the plan switches standard[0] only
    tr = small.trace
    assert np.count_nonzero(tr.io[1:] != tr.io[:-1]) == np.count_nonzero(io[1:] != io[:-1]) == 82
    assert isinstance(new_recording(job, planned), Recording)


APT_THREE_PASSES = """FEDRAT/MMPM,1200
GOTO/0,0,0
GOTO/40,0,0
RAPID
GOTO/40,0.4,0
GOTO/0,0.4,0
RAPID
GOTO/0,0.8,0
GOTO/40,0.8,0
"""


def test_a_sparse_recording_that_misses_a_brief_off_leaves_it_unresolved_not_shifted(tmp_path):
    """Three passes 0.4 mm apart joined by short rapids: the output is off for a moment between them. Recorded
    every 0.5 s (program mode in fast-forward), the off-on pairs are not seen; the ordered alignment leaves them
    unmatched and marked unresolved, and still matches the first on and the last off to their own stations
    (in-order matching used to give the last off to the first pass's off, 80 mm away)."""
    path = tmp_path / "three.apt"
    path.write_text(APT_THREE_PASSES)
    job = plan(path, PlanSettings(path="cam", robot="ur5e", part_frame=PART, cut_output=("standard", 0)))
    c = job.trajectory().collect()
    on = np.flatnonzero(c.io & 1)
    gaps = np.flatnonzero(np.diff(on) > 1)
    assert len(gaps) == 2  # two brief offs between the three passes
    off_s = (on[gaps + 1] - on[gaps]) / 500.0
    assert (off_s < 0.5).all()
    step = 250  # every 0.5 s
    keep = np.unique(np.r_[np.arange(0, c.times.size, step), c.times.size - 1])
    keep = keep[~np.isin(keep, np.r_[[np.arange(on[g] + 1, on[g + 1]) for g in gaps]].ravel())]  # offs unseen
    rep = execution_report(job, c.times[keep], c.poses[keep], c.joints[keep], c.io[keep], mode="replay")
    ev = rep.io_events
    assert [(e.value, e.switched, e.unresolved) for e in ev] == [
        (True, True, False), (False, False, True), (True, False, True),
        (False, False, True), (True, False, True), (False, True, False)]
    assert ev[0].distance_mm <= ev[0].resolution_mm + 1e-9 and ev[-1].distance_mm <= ev[-1].resolution_mm + 1e-9
    assert all(1e3 * off_s.max() < e.unresolved_ms <= 1000.0 + 1e-6 for e in ev if e.unresolved)  # 1 or 2 steps
    assert "4 too brief for the recording to show" in "\n".join(rep.describe())
    # the same recording at the controller's rate sees every switch on its station
    full = execution_report(job, c.times, c.poses, c.joints, c.io, mode="replay")
    assert all(e.switched and e.distance_mm < 1e-9 for e in full.io_events) and len(full.io_events) == 6
    # densely recorded, an output left on through the first rapid is a miss, not unresolved
    stuck = c.io.copy()
    stuck[on[gaps[0]]:on[gaps[0] + 1]] |= 1
    rep = execution_report(job, c.times, c.poses, c.joints, stuck, mode="replay")
    assert [(e.switched, e.unresolved) for e in rep.io_events[1:3]] == [(False, False), (False, False)]
    assert all(e.switched for e in rep.io_events[3:]) and "2 not made" in "\n".join(rep.describe())
