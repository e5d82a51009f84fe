"""The execution report: how a run followed its plan, computed from what was recorded during the run.

ONE implementation for every driver: :class:`drivers.ur.URDriver` records the actual TCP, joints and digital
outputs from RTDE, :class:`drivers.sim.SimDriver` from its in-process motion model; both call
:func:`execution_report`.

Figures: the tracked TCP path's largest distance from the PLANNED PATH (the distance to the planned path
polyline at the controller rate, not a time-aligned difference: a run that is late but on the path has no
path error; searched over a window of the plan around the run's place, so that the report's memory does not
grow with the job: :mod:`drivers.plan_window`); duration against the planned one; every switch of a digital
output with its planned and actual arc length along the planned path and its distance from the planned station;
the joints' smallest margin to their position limits; the recording's gaps (data packages missed); the failure,
if any, with the robot's reason and the job's time, pose and line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from drivers.base import DriverError
from drivers.pacing import LoopStats
from drivers.plan_window import PlannedPath, bit_switches
from planner.kinematics.ur_outputs import bit_name
from planner.wording import counted

if TYPE_CHECKING:  # pragma: no cover
    from drivers.recording import ExecutionTrace


@dataclass(frozen=True)
class IOSwitch:
    """One switch of a digital output: planned and actual.

    bit: output bit (standard 0-7, configurable 8-15, tool 16-17); value: the new state;
    planned_s: arc length of the planned station along the planned TCP path, m;
    actual_s: arc length along the planned path where the output actually switched (the actual TCP's position
    projected on the path's tangent at the station), m; NaN if it never switched;
    distance_mm: distance of the actual TCP at the switch from the planned station, mm (NaN if never switched):
    the switch happened between two recorded samples, so this is the station's distance from the TCP's recorded
    step between them (a point, for the first sample);
    planned_t, actual_t: job time of the planned and of the actual switch, s (NaN if missing);
    resolution_mm: length of that recorded step, mm: how far the TCP moved between the last sample that saw the
    old state and the first that saw the new one (the sampling's uncertainty about where the switch happened);
    unresolved_ms: for a switch not seen, when the recording could not have shown it: the time between the
    recorded samples nearest its station, ms (longer than the planned state lasted there); NaN otherwise.
    """

    bit: int
    value: bool
    planned_s: float
    actual_s: float
    distance_mm: float
    planned_t: float = math.nan
    actual_t: float = math.nan
    resolution_mm: float = math.nan
    unresolved_ms: float = math.nan

    @property
    def switched(self) -> bool:
        return not math.isnan(self.actual_s)

    @property
    def unresolved(self) -> bool:
        """Not seen, and the recording was too sparse there to see it (not counted as missed)."""
        return not math.isnan(self.unresolved_ms)


@dataclass(frozen=True)
class ExecutionReport:
    """How a run went.

    mode: "stream" or "program" (or the driver's own, e.g. "dry-run");
    ok: finished without a failure; reason: the failure's reason ("" when ok);
    planned_duration: duration of the planned trajectory, s; duration: recorded run time, s;
    samples: recorded samples; max_path_error: largest distance of the tracked TCP from the planned path, m;
    max_path_error_t: job time of that sample, s; io_events: tuple of :class:`IOSwitch`;
    joint_limit_margin: smallest distance of a recorded joint from its position limit, rad;
    failure: the :class:`drivers.base.DriverError` or None;
    loop: the streaming loop's timing (:class:`drivers.pacing.LoopStats`: period p50/p99/max, missed periods) or
    None (no real-time loop: program mode, an in-process dry run);
    trace: a bounded trace of the recording (:class:`drivers.recording.ExecutionTrace`: times, actual TCP
    positions and speed, output bits; at most ~20,000 samples, every output change kept): what a plot draws;
    recorded_every: the recording's usual step between samples, s; gaps: steps between recorded samples longer than
    1.5 x that (data packages missed, ``missed`` of them in all; the longest ``longest_gap`` s);
    recording: how the samples were recorded (the drivers: "every data package", through a connection of its own).
    """

    mode: str
    ok: bool
    reason: str
    planned_duration: float
    duration: float
    samples: int
    max_path_error: float
    io_events: tuple
    joint_limit_margin: float
    failure: DriverError | None = None
    max_path_error_t: float = math.nan
    path_length: float = 0.0
    loop: LoopStats | None = None
    trace: ExecutionTrace | None = None
    recorded_every: float = math.nan
    gaps: int = 0
    missed: int = 0
    longest_gap: float = 0.0
    recording: str = ""

    @property
    def max_io_distance_mm(self) -> float:
        """Largest distance of a switch from its station, mm (NaN without switches; inf if one was missed)."""
        if not self.io_events:
            return math.nan
        return max(math.inf if not e.switched else e.distance_mm for e in self.io_events)

    def describe(self) -> list[str]:
        """The report as lines of text (what the CLI prints)."""
        head = "ok" if self.ok else f"FAILED: {self.failure if self.failure is not None else self.reason}"
        lines = [f"execution ({self.mode}): {head}"]
        pct = ""
        if self.planned_duration > 0:
            pct = f" ({100.0 * self.duration / self.planned_duration:.1f} % of planned)"
        lines.append(f"  duration {self.duration:.3f} s, planned {self.planned_duration:.3f} s{pct}; "
                     f"{self.samples} samples recorded")
        if self.loop is not None and self.loop.n:
            lines.append("  " + self.loop.describe())
        if self.samples > 1 and math.isfinite(self.recorded_every):
            how = f"{self.recording}, " if self.recording else ""
            gaps = (f"{counted(self.gaps, 'gap')}: ~{self.missed} samples missed, the longest "
                    f"{1e3 * self.longest_gap:.1f} ms" if self.gaps else "no gap")
            lines.append(f"  recording: {how}a sample every {1e3 * self.recorded_every:.1f} ms of job time; {gaps}")
        if self.samples:
            at = "" if math.isnan(self.max_path_error_t) else f" at t = {self.max_path_error_t:.3f} s"
            lines.append("  tracked TCP path: largest distance from the planned path "
                         f"{self.max_path_error * 1e3:.3f} mm{at}")
            lines.append(f"  joint-limit margin {self.joint_limit_margin:.3f} rad "
                         f"({math.degrees(self.joint_limit_margin):.1f} deg)")
        if self.io_events:
            done = [e for e in self.io_events if e.switched]
            unresolved = sum(1 for e in self.io_events if e.unresolved)
            missed = len(self.io_events) - len(done) - unresolved
            worst = max((e.distance_mm for e in done), default=math.nan)
            lines.append(f"  I/O: {len(done)} of {len(self.io_events)} switches made"
                         + (f", {missed} not made" if missed else "")
                         + (f", {unresolved} too brief for the recording to show" if unresolved else "")
                         + (f"; largest distance from its station {worst:.3f} mm" if done else ""))
            for e in self.io_events[:8]:
                state = "on " if e.value else "off"
                if e.switched:  # under 0.5 um between the samples around it: the arm stood still (a stop)
                    there = (f"sampled every {e.resolution_mm:.3f} mm of travel there" if e.resolution_mm >= 5e-4
                             else "the TCP at rest there")
                    lines.append(f"    {bit_name(e.bit)} {state} at s = {e.actual_s:.4f} m "
                                 f"(planned {e.planned_s:.4f} m, {e.distance_mm:.3f} mm from the station; {there})")
                elif e.unresolved:
                    lines.append(f"    {bit_name(e.bit)} {state} planned at s = {e.planned_s:.4f} m: not seen, the "
                                 f"recording's samples there are {e.unresolved_ms:.1f} ms apart")
                else:
                    lines.append(f"    {bit_name(e.bit)} {state} planned at s = {e.planned_s:.4f} m: not switched")
            if len(self.io_events) > 8:
                lines.append(f"    ... {len(self.io_events) - 8} more")
        return lines


def planned_path(job, rate: float | None = None):
    """The planned TCP path at the controller rate: times (n,) s, poses (n, 6) p[x, y, z, rx, ry, rz] m, rad,
    io bits (n,), source lines (n,) and cumulative arc length (n,) m. Read from the job's one trajectory (no
    second sampler)."""
    tr = job.trajectory(rate)
    ts, ps, io, ln = [], [], [], []
    for c in tr.chunks(joints=False):
        ts.append(c.times)
        ps.append(c.poses)
        io.append(c.io)
        ln.append(c.lines)
    if not ts:
        z = np.zeros(0)
        return z, np.zeros((0, 6)), np.zeros(0, np.int64), np.zeros(0, np.int64), z
    t = np.concatenate(ts)
    p = np.concatenate(ps)
    s = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(p[:, :3], axis=0), axis=1))))
    return t, p, np.concatenate(io), np.concatenate(ln), s


class PolylineIndex:
    """A polyline ``path`` (n, 3) prepared once for many :meth:`distance` queries (a k-d tree of its vertices,
    repeated vertices dropped)."""

    def __init__(self, path: np.ndarray) -> None:
        path = np.asarray(path, dtype=float).reshape(-1, 3)
        self.n = path.shape[0]
        # drop repeated vertices (the tool rests at move boundaries): they make the k nearest all the same point
        keep = np.concatenate(([True], np.linalg.norm(np.diff(path, axis=0), axis=1) > 1e-12)) if self.n else \
            np.zeros(0, bool)
        self.idx_map = np.flatnonzero(keep)
        self.v = path[keep]
        self.tree = cKDTree(self.v) if self.v.shape[0] > 1 else None

    def distance(self, points: np.ndarray, *, k: int = 8) -> tuple[np.ndarray, np.ndarray]:
        """Distance (m) of each point (m, 3) from the polyline, and the index of the nearest segment's start
        (m,), as :func:`distance_to_polyline`."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        m = points.shape[0]
        if self.n == 0 or m == 0:
            return np.full(m, np.nan), np.zeros(m, np.int64)
        v = self.v
        if self.tree is None:
            return np.linalg.norm(points - v[0], axis=1), np.zeros(m, np.int64)
        kk = min(k, v.shape[0])
        _, near = self.tree.query(points, k=kk)
        near = near.reshape(m, kk)
        nseg = v.shape[0] - 1
        seg = np.concatenate((np.clip(near - 1, 0, nseg - 1), np.clip(near, 0, nseg - 1)), axis=1)  # (m, 2k)
        a = v[seg]
        d = v[seg + 1] - a
        w = points[:, None, :] - a
        dd = np.einsum("mkj,mkj->mk", d, d)
        u = np.clip(np.einsum("mkj,mkj->mk", w, d) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
        dist = np.linalg.norm(w - u[..., None] * d, axis=2)
        best = dist.argmin(axis=1)
        rows = np.arange(m)
        return dist[rows, best], self.idx_map[seg[rows, best]]


def distance_to_polyline(points: np.ndarray, path: np.ndarray, *, k: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Distance (m) of each point (m, 3) from the polyline ``path`` (n, 3), and the index of the segment
    start nearest to it (m,). The candidate segments are those next to the ``k`` nearest vertices (exact for a
    polyline sampled densely against the distances measured, as the planned path at the controller rate is).
    Many queries against one path: :class:`PolylineIndex`."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    path = np.asarray(path, dtype=float).reshape(-1, 3)
    if path.shape[0] == 0 or points.shape[0] == 0:
        return np.full(points.shape[0], np.nan), np.zeros(points.shape[0], np.int64)
    return PolylineIndex(path).distance(points, k=k)


def joint_limit_margin(model: str | None, joints: np.ndarray) -> float:
    """Smallest distance of the recorded joints (n, 6) rad from the model's position limits, rad (NaN without)."""
    q = np.asarray(joints, dtype=float).reshape(-1, 6)
    q = q[np.isfinite(q).all(axis=1)]
    if model is None or q.shape[0] == 0:
        return math.nan
    from planner.kinematics.ur_models import get_model

    m = get_model(model)
    lo, hi = np.asarray(m.q_min), np.asarray(m.q_max)
    return float(np.minimum(q - lo, hi - q).min())


def execution_report(job, recorded_times, recorded_tcp=None, recorded_joints=None, recorded_io=None, *, mode: str,
                     failure: DriverError | None = None, planned=None, loop: LoopStats | None = None,
                     recording: str = "") -> ExecutionReport:
    """The report of a run from what was recorded.

    Parameters
    ----------
    job : PlannedJob
    recorded_times : (n,) job time of each recorded sample, s (0 at the start of the planned trajectory); or a
        :class:`drivers.recording.Recording` the run reduced as it went (then the three arrays are not given)
    recorded_tcp : (n, 6) actual TCP poses p[x, y, z, rx, ry, rz] in the base frame, m, rad
    recorded_joints : (n, 6) actual joints, rad
    recorded_io : (n,) actual digital output bits (standard 0-7, configurable 8-15, tool 16-17)
    mode : str
    failure : DriverError or None
    planned : the planned path: a :class:`drivers.plan_window.PlannedPath` (read from the job when None: bounded
        memory, the path searched a window at a time) or the arrays of :func:`planned_path` (searched whole)
    loop : the streaming loop's timing, if any
    recording : how the samples were recorded (said in the report)
    """
    from drivers.recording import Recording

    plan = as_planned(job, planned)
    if isinstance(recorded_times, Recording):
        rec = recorded_times
    else:
        t = np.asarray(recorded_times, dtype=float).reshape(-1)
        n = t.size
        io = np.asarray(recorded_io, dtype=np.int64).reshape(-1) if n else np.zeros(0, np.int64)
        if io.size != n:
            raise ValueError(f"recorded_io has {io.size} samples, recorded_times {n}")
        rec = new_recording(job, plan)
        if n:
            rec.extend(t, recorded_tcp, recorded_joints, io)
    rec.finish()
    trace = rec.trace()
    events = _io_events(trace, plan)
    return ExecutionReport(
        mode=mode, ok=failure is None, reason="" if failure is None else failure.reason,
        planned_duration=plan.duration, duration=rec.duration, samples=int(rec.samples),
        max_path_error=rec.max_error if rec.samples else 0.0, max_path_error_t=rec.max_error_t,
        io_events=tuple(events), joint_limit_margin=rec.margin if math.isfinite(rec.margin) else math.nan,
        failure=failure, path_length=plan.length, loop=loop, trace=trace, recorded_every=rec.step, gaps=rec.gaps,
        missed=rec.missed, longest_gap=rec.longest_gap, recording=recording)


def as_planned(job, planned=None) -> PlannedPath:
    """``planned`` as a :class:`drivers.plan_window.PlannedPath`: itself; the arrays of :func:`planned_path` (kept,
    searched whole); read from ``job`` (a window at a time) when None."""
    if isinstance(planned, PlannedPath):
        return planned
    if planned is None:
        return PlannedPath(job)
    return PlannedPath(job, arrays=tuple(planned))


def new_recording(job, planned, *, block: int | None = None, prefetch: bool = False):
    """An empty :class:`drivers.recording.Recording` for a run of ``job`` against its planned path (a
    :class:`drivers.plan_window.PlannedPath`, or the arrays of :func:`planned_path`); ``block``: samples reduced
    at a time (default :data:`drivers.recording.BLOCK`; a real-time loop reduces small blocks, a fraction of its
    period each); ``prefetch``: the plan window's pieces made ahead in a thread (for a real-time loop)."""
    from drivers.recording import BLOCK, Recording

    plan = as_planned(job, planned)
    src = plan if plan.arrays is None else np.asarray(plan.arrays[1])[:, :3]
    return Recording(src, job.settings.robot, plan.length, block=BLOCK if block is None else block,
                     prefetch=prefetch)


def _io_events(trace, plan: PlannedPath) -> list[IOSwitch]:
    """Planned switches matched with the recorded ones, bit and value apart, by an ordered alignment (each
    planned switch to at most one recorded switch, in order) of least total distance from the stations, a switch
    left unmatched costing UNMATCHED_COST. A sparse recording (program mode in fast-forward) can miss an output
    that is off for a moment between two passes: such a pair is left unmatched (and marked unresolved when the
    recording's samples there are further apart than it lasted) instead of shifting every later match.

    ``trace``: the run's :class:`drivers.recording.ExecutionTrace` (every output change and the sample before it
    kept, with the planned segment nearest each sample); ``plan``: the planned switches and their stations."""
    t, tcp, io = trace.t, trace.xyz, trace.io
    planned = plan.switches
    actual = bit_switches(io, 0)  # the driver clears the job's outputs before the run
    act_by: dict[tuple[int, bool], list[int]] = {}
    for b, v, j in actual:
        act_by.setdefault((b, v), []).append(j)
    plan_by: dict[tuple[int, bool], list[int]] = {}
    for n, (b, v, _) in enumerate(planned):
        plan_by.setdefault((b, v), []).append(n)
    match: dict[int, int] = {}  # index in planned -> recorded sample index
    for key, ns in plan_by.items():
        js = act_by.get(key, [])
        if js:
            stations = np.array([plan.stations[planned[n][2]].xyz for n in ns]).reshape(-1, 3)
            for x, y in _align(stations, tcp, js):
                match[ns[x]] = js[y]
    out = []
    seg = trace.segment if trace.segment is not None else np.zeros(t.size, np.int64)
    for n, (b, v, i) in enumerate(planned):
        st = plan.stations[i]
        station, tan = st.xyz, st.tangent
        if n not in match:
            out.append(IOSwitch(b, v, st.s, math.nan, math.nan, st.t, math.nan,
                                unresolved_ms=_unresolved_ms(n, planned, t, seg)))
            continue
        j = match[n]
        p, u, ls = _nearest_on_step(station, tcp, j)
        tj = float(t[max(j - 1, 0)] + u * (t[j] - t[max(j - 1, 0)]))
        out.append(IOSwitch(b, v, st.s, float(st.s + np.dot(p - station, tan)),
                            float(np.linalg.norm(p - station) * 1e3), st.t, tj, float(math.sqrt(ls) * 1e3)))
    return out


#: Cost of leaving a planned or a recorded switch unmatched in :func:`_io_events`' alignment, m: a switch is
#: matched to a recorded one up to 2 x this away from its station, else both count as unmatched.
UNMATCHED_COST = 0.05


def _nearest_on_step(station, tcp, j):
    """The point of the TCP's recorded step from sample j - 1 to j nearest ``station``, its fraction u along the
    step and the step's squared length."""
    a, c = tcp[max(j - 1, 0), :3], tcp[j, :3]
    step = c - a
    ls = float(np.dot(step, step))
    u = 0.0 if ls == 0.0 else float(np.clip(np.dot(station - a, step) / ls, 0.0, 1.0))
    return a + u * step, u, ls


def _align(stations, tcp, js) -> list[tuple[int, int]]:
    """Ordered alignment of planned stations (m, 3) with recorded switch samples js (k,): pairs (a, c) of least
    total cost (distance of the recorded step from the station; UNMATCHED_COST per switch left over)."""
    m, k = stations.shape[0], len(js)
    jj = np.asarray(js)
    a = tcp[np.maximum(jj - 1, 0), :3]
    d = tcp[jj, :3] - a
    dd = np.einsum("kj,kj->k", d, d)
    w = np.einsum("mkj,kj->mk", stations[:, None] - a[None], d)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.clip(np.where(dd > 0, w / dd, 0.0), 0.0, 1.0)
    cost = np.linalg.norm(stations[:, None] - (a[None] + u[..., None] * d[None]), axis=2)  # (m, k)
    skip = UNMATCHED_COST
    acc = np.zeros((m + 1, k + 1))
    acc[0, :] = skip * np.arange(k + 1)
    acc[:, 0] = skip * np.arange(m + 1)
    for x in range(1, m + 1):  # the edit-distance recurrence (a cell depends on the one before it in its row)
        row, prev, cx = acc[x], acc[x - 1], cost[x - 1]
        for y in range(1, k + 1):
            row[y] = min(prev[y - 1] + cx[y - 1], prev[y] + skip, row[y - 1] + skip)
    pairs = []
    x, y = m, k
    while x > 0 and y > 0:
        if acc[x, y] == acc[x - 1, y - 1] + cost[x - 1, y - 1]:
            pairs.append((x - 1, y - 1))
            x, y = x - 1, y - 1
        elif acc[x, y] == acc[x - 1, y] + skip:
            x -= 1
        else:
            y -= 1
    return pairs[::-1]


def _unresolved_ms(n, planned, t, seg) -> float:
    """For planned switch n not seen: when the recording has no sample inside a planned state the switch begins
    or ends (the planned samples between it and the neighbouring switch of its bit, ends excluded), the time
    between the recorded samples on either side of that state, ms: the recording could not show it. NaN when
    the recording saw the stretch (the switch was missed)."""
    b, _, i = planned[n]
    same = [q[2] for q in planned if q[0] == b]
    k = same.index(i)
    states = ([(same[k - 1], i)] if k > 0 else []) + ([(i, same[k + 1])] if k + 1 < len(same) else [])
    for lo, hi in states:
        if seg.size == 0:
            continue
        if ((seg > lo) & (seg < hi - 1)).any():
            continue  # seen inside that state
        before, after = np.flatnonzero(seg <= lo), np.flatnonzero(seg >= hi - 1)
        if before.size and after.size and after[0] > before[-1]:
            return float(t[after[0]] - t[before[-1]]) * 1e3
    return math.nan
