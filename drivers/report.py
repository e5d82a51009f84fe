"""The execution report: how a run followed its plan, computed from what was recorded during the run.

ONE implementation for every driver: :class:`drivers.ur.URDriver` records the actual TCP, joints and digital
outputs from RTDE, :class:`drivers.sim.SimDriver` from its in-process motion model; both call
:func:`execution_report`.

Figures: the tracked TCP path's largest distance from the PLANNED PATH (the distance to the planned path
polyline at the controller rate, not a time-aligned difference: a run that is late but on the path has no
path error); duration against the planned one; every switch of a digital output with its planned and actual
arc length along the planned path and its distance from the planned station; the joints' smallest margin to
their position limits; the failure, if any, with the robot's reason and the job's time, pose and line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from drivers.base import DriverError
from drivers.pacing import LoopStats

if TYPE_CHECKING:  # pragma: no cover
    from drivers.recording import ExecutionTrace


def bit_name(bit: int) -> str:
    """Readable name of a digital output bit: standard[3], configurable[1], tool[0]."""
    if bit < 8:
        return f"standard[{bit}]"
    if bit < 16:
        return f"configurable[{bit - 8}]"
    return f"tool[{bit - 16}]"


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
    old state and the first that saw the new one (the sampling's uncertainty about where the switch happened).
    """

    bit: int
    value: bool
    planned_s: float
    actual_s: float
    distance_mm: float
    planned_t: float = math.nan
    actual_t: float = math.nan
    resolution_mm: float = math.nan

    @property
    def switched(self) -> bool:
        return not math.isnan(self.actual_s)


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
    positions and speed, output bits; at most ~20,000 samples, every output change kept): what a plot draws.
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
        if self.samples:
            at = "" if math.isnan(self.max_path_error_t) else f" at t = {self.max_path_error_t:.3f} s"
            lines.append("  tracked TCP path: largest distance from the planned path "
                         f"{self.max_path_error * 1e3:.3f} mm{at}")
            lines.append(f"  joint-limit margin {self.joint_limit_margin:.3f} rad "
                         f"({math.degrees(self.joint_limit_margin):.1f} deg)")
        if self.io_events:
            done = [e for e in self.io_events if e.switched]
            missed = len(self.io_events) - len(done)
            worst = max((e.distance_mm for e in done), default=math.nan)
            lines.append(f"  I/O: {len(done)} of {len(self.io_events)} switches made"
                         + (f", {missed} not made" if missed else "")
                         + (f"; largest distance from its station {worst:.3f} mm" if done else ""))
            for e in self.io_events[:8]:
                state = "on " if e.value else "off"
                if e.switched:
                    lines.append(f"    {bit_name(e.bit)} {state} at s = {e.actual_s:.4f} m "
                                 f"(planned {e.planned_s:.4f} m, {e.distance_mm:.3f} mm from the station; "
                                 f"sampled every {e.resolution_mm:.3f} mm of travel there)")
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


def _switches(times: np.ndarray, io: np.ndarray, first: int) -> list[tuple[int, bool, int]]:
    """(bit, value, index) of every change of a bit in the io samples, from the state ``first`` before them."""
    io = np.asarray(io, dtype=np.int64)
    if io.size == 0:
        return []
    prev = np.concatenate(([first], io[:-1]))
    change = io ^ prev
    out = []
    for i in np.flatnonzero(change):
        bits = int(change[i])
        b = 0
        while bits:
            if bits & 1:
                out.append((b, bool((int(io[i]) >> b) & 1), int(i)))
            bits >>= 1
            b += 1
    return out


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
                     failure: DriverError | None = None, planned=None, loop: LoopStats | None = None
                     ) -> ExecutionReport:
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
    planned : the result of :func:`planned_path` (computed from the job when None)
    loop : the streaming loop's timing, if any
    """
    from drivers.recording import Recording

    pt, pp, pio, _, ps = planned if planned is not None else planned_path(job)
    pp = pp[:, :3]
    if isinstance(recorded_times, Recording):
        rec = recorded_times
    else:
        t = np.asarray(recorded_times, dtype=float).reshape(-1)
        n = t.size
        io = np.asarray(recorded_io, dtype=np.int64).reshape(-1) if n else np.zeros(0, np.int64)
        if io.size != n:
            raise ValueError(f"recorded_io has {io.size} samples, recorded_times {n}")
        rec = new_recording(job, (pt, pp, pio, None, ps))
        if n:
            rec.extend(t, recorded_tcp, recorded_joints, io)
    rec.finish()
    trace = rec.trace()
    planned_duration = float(pt[-1] - pt[0]) if pt.size else 0.0
    events = _io_events(trace.t, trace.xyz, trace.io, pt, pp, pio, ps)
    return ExecutionReport(
        mode=mode, ok=failure is None, reason="" if failure is None else failure.reason,
        planned_duration=planned_duration, duration=rec.duration, samples=int(rec.samples),
        max_path_error=rec.max_error if rec.samples else 0.0, max_path_error_t=rec.max_error_t,
        io_events=tuple(events), joint_limit_margin=rec.margin if math.isfinite(rec.margin) else math.nan,
        failure=failure, path_length=float(ps[-1]) if ps.size else 0.0, loop=loop, trace=trace)


def new_recording(job, planned, *, block: int | None = None):
    """An empty :class:`drivers.recording.Recording` for a run of ``job`` against its planned path (the result
    of :func:`planned_path`); ``block``: samples reduced at a time (default :data:`drivers.recording.BLOCK`; a
    real-time loop reduces small blocks, a fraction of its period each)."""
    from drivers.recording import BLOCK, Recording

    pp, ps = planned[1], planned[4]
    return Recording(pp[:, :3], job.settings.robot, float(ps[-1]) if ps.size else 0.0,
                     block=BLOCK if block is None else block)


def planned_switches(times: np.ndarray, io: np.ndarray) -> list[tuple[int, bool, int]]:
    """(bit, value, index) of the planned switches of a trajectory's I/O column: every change of a bit, except a
    change undone one sample later (the trajectory's output is off for the one sample between two cuts joined at a
    corner: the drivers keep it on, :class:`drivers.stations.Stations`)."""
    from drivers.stations import BLIP

    sw = _switches(times, io, 0)
    dropped: set[int] = set()
    last: dict[int, int] = {}  # bit -> index in sw of its last switch kept
    for n, (b, v, i) in enumerate(sw):
        j = last.pop(b, None)
        if j is not None and i - sw[j][2] <= BLIP and sw[j][1] != v:
            dropped.update((j, n))  # undone at once: no switch
            continue
        last[b] = n
    return [x for n, x in enumerate(sw) if n not in dropped]


def _io_events(t, tcp, io, pt, pp, pio, ps) -> list[IOSwitch]:
    """Planned switches matched, bit by bit and in order, with the recorded ones."""
    planned = planned_switches(pt, pio)
    actual = _switches(t, io, 0)  # the driver clears the job's outputs before the run
    act_by: dict[tuple[int, bool], list[int]] = {}
    for b, v, i in actual:
        act_by.setdefault((b, v), []).append(i)
    used: dict[tuple[int, bool], int] = {}
    out = []
    for b, v, i in planned:
        station = pp[i]
        j0 = max(i - 1, 0)
        j1 = min(i + 1, pp.shape[0] - 1)
        tan = pp[j1] - pp[j0]
        nt = np.linalg.norm(tan)
        tan = tan / nt if nt > 0 else tan
        k = used.get((b, v), 0)
        cands = act_by.get((b, v), [])
        if k < len(cands):
            used[(b, v)] = k + 1
            j = cands[k]
            a, c = tcp[max(j - 1, 0), :3], tcp[j, :3]
            step = c - a
            ls = float(np.dot(step, step))
            u = 0.0 if ls == 0.0 else float(np.clip(np.dot(station - a, step) / ls, 0.0, 1.0))
            p = a + u * step  # the TCP's recorded step between the old state and the new, nearest the station
            tj = float(t[max(j - 1, 0)] + u * (t[j] - t[max(j - 1, 0)]))
            out.append(IOSwitch(b, v, float(ps[i]), float(ps[i] + np.dot(p - station, tan)),
                                float(np.linalg.norm(p - station) * 1e3), float(pt[i]), tj,
                                float(math.sqrt(ls) * 1e3)))
        else:
            out.append(IOSwitch(b, v, float(ps[i]), math.nan, math.nan, float(pt[i]), math.nan))
    return out
