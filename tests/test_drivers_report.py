"""The execution report's figures from recorded samples: distance to the planned path (not time-aligned), I/O
switches against their stations, joint-limit margin, failures with their place."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.base import DriverError, ProtectiveStopError
from drivers.report import distance_to_polyline, execution_report, new_recording, planned_path
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


@pytest.fixture
def small_window(monkeypatch):
    """The plan window in pieces of 400 samples (0.8 s), 1 s back and ahead, spans of 0.5 s: the demo pass (62 s,
    31,000 samples) then moves through ~80 pieces, as a 7-hour job through its pieces of 65,536."""
    from drivers import plan_window

    monkeypatch.setattr(plan_window, "PIECE", 400)
    monkeypatch.setattr(plan_window, "BACK", 1.0)
    monkeypatch.setattr(plan_window, "AHEAD", 1.0)
    monkeypatch.setattr(plan_window, "SPAN", 0.5)


def _recordings(c):
    """(name, times, poses, io) of runs that follow the plan differently: noisy, 0.4 s late, paused 3 s mid-way,
    3 % slower throughout (a program's timing drifting 1.9 s from the plan's), offset 0.3 mm."""
    rng = np.random.default_rng(5)
    n = len(c.times)
    noisy = c.poses.copy()
    noisy[:, :3] += rng.normal(scale=2e-5, size=(n, 3))
    yield "noisy", c.times, noisy, c.io
    late = np.concatenate((np.repeat(c.poses[:1], 200, axis=0), c.poses))
    yield "late", np.arange(len(late)) / 500.0, late, np.concatenate((np.zeros(200, np.int64), c.io))
    h = n // 2
    held = np.concatenate((c.poses[:h], np.repeat(c.poses[h:h + 1], 1500, axis=0), c.poses[h:]))
    io = np.concatenate((c.io[:h], np.repeat(c.io[h:h + 1], 1500), c.io[h:]))
    yield "paused", np.arange(len(held)) / 500.0, held, io
    yield "slower", c.times * 1.03, noisy, c.io
    off = c.poses.copy()
    off[:, 2] += 0.3e-3
    yield "offset", c.times, off, c.io


def test_the_plan_window_gives_the_whole_paths_figures_in_bounded_memory(job, small_window):
    """The report against the plan read a window at a time (a few pieces of 400 samples held at once) has the
    figures of the report against the whole planned path in memory: the same largest distance at the same time,
    the same switches at the same places, for runs late, paused, drifting in time, off the path."""
    from drivers.report import new_recording

    c = job.trajectory().collect()
    whole = planned_path(job)
    for n, (name, t, x, io) in enumerate(_recordings(c)):
        q = np.zeros((len(t), 6))
        rec = new_recording(job, None, prefetch=n % 2 == 1)  # the pieces made ahead by a thread, or not
        rec.extend(t, x, q, io)
        lazy = execution_report(job, rec, mode="replay")
        full = execution_report(job, t, x, q, io, mode="replay", planned=whole)
        assert lazy.max_path_error == full.max_path_error, name
        assert lazy.max_path_error_t == full.max_path_error_t, name
        assert len(lazy.io_events) == len(full.io_events) == 2, name
        for e, f in zip(lazy.io_events, full.io_events, strict=True):  # arc lengths summed in pieces: to 1e-12
            assert (e.bit, e.value, e.distance_mm, e.planned_t, e.actual_t, e.resolution_mm) == \
                (f.bit, f.value, f.distance_mm, f.planned_t, f.actual_t, f.resolution_mm), name
            assert e.planned_s == pytest.approx(f.planned_s, rel=1e-12, abs=1e-15)
            assert e.actual_s == pytest.approx(f.actual_s, rel=1e-12, abs=1e-15)
        assert lazy.planned_duration == full.planned_duration and lazy.path_length == pytest.approx(full.path_length)
        assert np.array_equal(lazy.trace.segment, full.trace.segment), name
        held = rec.planned.max_held
        assert held <= 6 * 400 + 400, (name, held)  # the window, not the 31,000 samples of the plan
    assert len(c.times) > 12 * held


def test_planned_path_summary_and_samples_match_the_arrays(job, small_window):
    from drivers.plan_window import PlannedPath

    pt, pp, pio, pl, ps = planned_path(job)
    lazy, arrays = PlannedPath(job), PlannedPath(job, arrays=(pt, pp, pio, pl, ps))
    assert lazy.n == arrays.n == pt.size and lazy.duration == arrays.duration == pt[-1]
    assert lazy.length == pytest.approx(ps[-1], rel=1e-12) and lazy.mask == arrays.mask == 1
    assert lazy.switches == arrays.switches and len(lazy.switches) == 2
    for i in lazy.stations:
        a, b = lazy.stations[i], arrays.stations[i]
        assert a.t == b.t and np.array_equal(a.xyz, b.xyz) and np.allclose(a.tangent, b.tangent, atol=1e-12)
        assert a.s == pytest.approx(b.s, rel=1e-12)
    for k in (0, 399, 400, 12345, pt.size - 1, pt.size + 5):
        t, pose, line = lazy.at(k)
        kk = min(k, pt.size - 1)
        assert t == pt[kk] and np.array_equal(pose, pp[kk]) and line == pl[kk]


def test_the_recordings_gaps_are_counted_and_reported(job):
    """Three stretches of 10 samples missing from a recording at the controller rate: 3 gaps, 30 samples missed,
    the longest 22 ms; a whole recording has none."""
    c = job.trajectory().collect()
    keep = np.ones(len(c.times), bool)
    for a in (3000, 9000, 20000):
        keep[a:a + 10] = False
    rep = execution_report(job, c.times[keep], c.poses[keep], c.joints[keep], c.io[keep], mode="replay",
                           recording="every data package")
    assert (rep.gaps, rep.missed) == (3, 30) and rep.longest_gap == pytest.approx(0.022)
    assert rep.recorded_every == pytest.approx(0.002)
    assert "recording: every data package, a sample every 2.0 ms of job time; 3 gaps: ~30 samples missed, " \
           "the longest 22.0 ms" in "\n".join(rep.describe())
    full = execution_report(job, c.times, c.poses, c.joints, c.io, mode="replay")
    assert full.gaps == full.missed == 0 and "no gap" in "\n".join(full.describe())


def test_packages_closer_together_after_a_stall_are_not_gaps(job):
    """A fast-forward program recording (a package every 10 control periods, 20 ms of job time), read and reduced
    25 packages at a time as program mode does, in which a controller catching up after three stalls sent 50
    packages 2 ms apart each time: no gap, the usual step still 20 ms (the catch-up blocks' median is 2 ms: the
    20 ms steps after them counted as gaps before); a real hole of 6 packages later is one gap."""
    c = job.trajectory().collect()
    k = np.arange(0, len(c.times), 10)
    for a in (3000, 12000, 21000):  # 50 packages 2 ms apart instead of 5 packages 20 ms apart
        k = np.r_[k[k < a], np.arange(a, a + 50), k[k >= a + 50]]
    k = k[(k < 25000) | (k >= 25060)]  # the 6 packages of 25000-25050 lost
    rec = new_recording(job, None, block=25)
    for a in range(0, k.size, 25):
        b = k[a:a + 25]
        rec.extend(c.times[b], c.poses[b], c.joints[b], c.io[b])
    rep = execution_report(job, rec, mode="program")
    assert rep.recorded_every == pytest.approx(0.020)
    assert (rep.gaps, rep.missed) == (1, 6) and rep.longest_gap == pytest.approx(0.140)


def test_the_switch_lines_say_how_finely_the_recording_placed_them(job):
    """Both switches of the plan happen with the arm at rest (the cut starts and ends at a stop): recorded at the
    controller rate, the step around each is under 0.5 um, said as "the TCP at rest there" (not "sampled every
    0.000 mm"); recorded every 20 ms, the spray comes on 3 um into the start, said as such. One missing stretch
    is "1 gap"."""
    c = job.trajectory().collect()
    rep = execution_report(job, c.times, c.poses, c.joints, c.io, mode="replay")
    assert all(e.resolution_mm < 5e-4 for e in rep.io_events)
    text = "\n".join(rep.describe())
    assert text.count("mm from the station; the TCP at rest there)") == 2 and "sampled every" not in text
    i = np.unique(np.r_[0:len(c.times):10, len(c.times) - 1])
    rep = execution_report(job, c.times[i], c.poses[i], c.joints[i], c.io[i], mode="replay")
    on = rep.io_events[0]
    assert on.resolution_mm > 1e-3
    assert f"on  at s = {on.actual_s:.4f} m (planned {on.planned_s:.4f} m, {on.distance_mm:.3f} mm from the " \
           f"station; sampled every {on.resolution_mm:.3f} mm of travel there)" in "\n".join(rep.describe())
    keep = np.ones(len(c.times), bool)
    keep[3000:3010] = False
    rep = execution_report(job, c.times[keep], c.poses[keep], c.joints[keep], c.io[keep], mode="replay",
                           recording="every data package")
    assert "; 1 gap: ~10 samples missed" in "\n".join(rep.describe())


def test_a_switchs_lateness_is_split_into_missed_periods_and_the_rest(job):
    """A stream whose loop missed 3 periods between the two switches: the whole rest of the run is 3 periods late
    (the loop never catches up); the report puts the second switch's 6 ms down to the missed periods and leaves
    the rest (here the samples' own resolution, under a period) as servo and I/O latency."""
    from drivers.pacing import LoopStats

    c = job.trajectory().collect()
    on, off = (int(k) for k in np.flatnonzero(np.diff(c.io)) + 1)
    stall = (on + off) // 2
    # the arm holds its pose for 3 periods at the stall, then runs on: every later sample 3 periods later
    poses = np.concatenate((c.poses[:stall], np.repeat(c.poses[stall - 1:stall], 3, axis=0), c.poses[stall:]))
    q = np.concatenate((c.joints[:stall], np.repeat(c.joints[stall - 1:stall], 3, axis=0), c.joints[stall:]))
    io = np.concatenate((c.io[:stall], np.repeat(c.io[stall - 1:stall], 3), c.io[stall:]))
    t = np.arange(len(io)) / 500.0
    loop = LoopStats(0.002, len(io), 500.0, 0.002, 0.002, 0.008, 3)
    rep = execution_report(job, t, poses, q, io, mode="stream", loop=loop, stalls=[c.times[stall]] * 3)
    first, second = rep.io_events
    assert (first.missed_periods, second.missed_periods) == (0, 3)
    assert abs(first.delay_ms) < 2.0 and first.model_delay_ms == first.delay_ms
    assert second.delay_ms == pytest.approx(6.0, abs=2.0) and second.missed_ms == pytest.approx(6.0)
    assert abs(second.model_delay_ms) < 2.0
    text = "\n".join(rep.describe())
    assert "6 ms of 3 missed control periods before it" in text and "ms of servo and I/O latency" in text
