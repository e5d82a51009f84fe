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

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from drivers.base import DriverError
from drivers.geometry import PolylineIndex, distance_to_polyline, joint_limit_margin
from drivers.pacing import LoopStats
from drivers.plan_window import PlannedPath, bit_switches
from drivers.recording import BLOCK, ExecutionTrace, Recording
from planner.kinematics.ur_outputs import bit_name
from planner.wording import counted

__all__ = ["ExecutionReport", "IOSwitch", "PathDeviation", "PathDeviationError", "PolylineIndex", "bit_name",
           "distance_to_polyline", "execution_report", "joint_limit_margin", "new_recording", "planned_path"]


#: The range of a path tolerance, m (exclusive, inclusive).
PATH_TOLERANCE_RANGE = (0.0, 1.0)


def check_tolerance(tolerance) -> float | None:
    """A path tolerance, m: None, or a finite number > 0 (ValueError naming ``path_tolerance`` otherwise)."""
    if tolerance is None:
        return None
    try:
        tol = float(tolerance)
    except (TypeError, ValueError):
        raise ValueError(f"path_tolerance must be a distance in m, got {tolerance!r}") from None
    if not (math.isfinite(tol) and PATH_TOLERANCE_RANGE[0] < tol <= PATH_TOLERANCE_RANGE[1]):
        raise ValueError(f"path_tolerance must be within (0, 1] m, got {tolerance!r}")
    return tol


@dataclass(frozen=True)
class Seam:
    """Where a job run as several programs (program mode, each under the controller's size limit) went from one to
    the next: ``program`` (1-based) started ``wait`` s (controller time) after the one before ended at job time
    ``job_time`` s (the recording's clock), the arm at rest between two moves there; ``line`` the source line of the
    program's first move."""

    program: int
    job_time: float
    wait: float
    line: int

    def describe(self) -> str:
        return (f"program {self.program} at t = {self.job_time:.3f} s (line {self.line}): {1e3 * self.wait:.1f} ms "
                "at rest")


class PathDeviationError(DriverError):
    """The tracked TCP left the planned path by more than the path tolerance (a run made to fail on it)."""

    kind = "path deviation"


@dataclass(frozen=True)
class PathDeviation:
    """A stretch of the run where the tracked TCP was further than the path tolerance from the planned path.

    t_start, t_end: job times of the first and last recorded sample beyond the tolerance, s; error: the largest
    distance there, m, at job time ``t`` s, near the planned pose ``pose`` (6,) from source line ``line``;
    cause: why, as far as the run shows it ("protective stop", "missed control periods", "servo lag ...",
    "the program's blends ...")."""

    t_start: float
    t_end: float
    error: float
    t: float
    line: int
    pose: tuple
    cause: str

    def describe(self) -> str:
        span = (f"t = {self.t_start:.3f} s" if self.t_end - self.t_start < 1e-9
                else f"t = {self.t_start:.3f}..{self.t_end:.3f} s")
        return (f"{self.error * 1e3:.3f} mm off the path at t = {self.t:.3f} s, source line {self.line} "
                f"(beyond the tolerance over {span}): {self.cause}")


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
    recorded samples nearest its station, ms (longer than the planned state lasted there); NaN otherwise;
    missed_periods: control periods the streaming loop missed before the planned switch (each delays the rest of
    the job by one period: the loop never catches up), 0 in program mode; ``period``: the control period, s. The
    switch's lateness against the plan, ``delay_ms``, is then ``missed_ms`` (those periods) plus ``model_delay_ms``
    (the rest: the servo's and the I/O path's latency, what the model does not predict).
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
    missed_periods: int = 0
    period: float = 0.002

    @property
    def delay_ms(self) -> float:
        """Actual switch time minus planned, ms (NaN if not switched)."""
        return (self.actual_t - self.planned_t) * 1e3

    @property
    def missed_ms(self) -> float:
        """The part of :attr:`delay_ms` that the streaming loop's missed periods before the switch account for, ms."""
        return self.missed_periods * self.period * 1e3

    @property
    def model_delay_ms(self) -> float:
        """:attr:`delay_ms` less :attr:`missed_ms`: the servo's and the I/O path's latency, ms."""
        return self.delay_ms - self.missed_ms

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
    path_tolerance: float = math.nan
    deviations: tuple = ()
    deviation_count: int = 0
    programs: int = 0
    program_bytes: int = 0
    seams: tuple = ()

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
        if self.programs > 1:
            waits = [sm.wait for sm in self.seams]
            longest = max(self.seams, key=lambda sm: sm.wait) if self.seams else None
            lines.append(f"  {self.programs} programs of at most {self.program_bytes} bytes (the controller's limit), "
                         f"run one after the other; {counted(len(self.seams), 'seam')} between moves, the arm at rest: "
                         f"{sum(waits):.3f} s in all" + (f", the longest {longest.describe()}" if longest else ""))
        if self.samples > 1 and math.isfinite(self.recorded_every):
            how = f"{self.recording}, " if self.recording else ""
            gaps = (f"{counted(self.gaps, 'gap')}: ~{self.missed} samples missed, the longest "
                    f"{1e3 * self.longest_gap:.1f} ms" if self.gaps else "no gap")
            lines.append(f"  recording: {how}a sample every {1e3 * self.recorded_every:.1f} ms of job time; {gaps}")
        if self.samples:
            at = "" if math.isnan(self.max_path_error_t) else f" at t = {self.max_path_error_t:.3f} s"
            lines.append("  tracked TCP path: largest distance from the planned path "
                         f"{self.max_path_error * 1e3:.3f} mm{at}")
            if math.isfinite(self.path_tolerance):
                if self.deviation_count:
                    lines.append(f"  PATH TOLERANCE {self.path_tolerance * 1e3:.3f} mm exceeded "
                                 f"{counted(self.deviation_count, 'time')}:")
                    for dv in self.deviations[:8]:
                        lines.append(f"    {dv.describe()}")
                    if self.deviation_count > 8:
                        lines.append(f"    ... {self.deviation_count - 8} more")
                else:
                    lines.append(f"  within the path tolerance {self.path_tolerance * 1e3:.3f} mm")
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
                    late = (f"; {e.delay_ms:+.1f} ms against the plan: {e.missed_ms:.0f} ms of "
                            f"{counted(e.missed_periods, 'missed control period')} before it, {e.model_delay_ms:+.1f} "
                            "ms of servo and I/O latency" if self.loop is not None and math.isfinite(e.delay_ms)
                            else "")
                    lines.append(f"    {bit_name(e.bit)} {state} at s = {e.actual_s:.4f} m "
                                 f"(planned {e.planned_s:.4f} m, {e.distance_mm:.3f} mm from the station; {there}"
                                 f"{late})")
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


def execution_report(job, recorded_times, recorded_tcp=None, recorded_joints=None, recorded_io=None, *, mode: str,
                     failure: DriverError | None = None, planned=None, loop: LoopStats | None = None,
                     recording: str = "", stalls=(), lag_cause: str = "",
                     fail_on_deviation: bool = False, programs: int = 0, program_bytes: int = 0,
                     seams=()) -> ExecutionReport:
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
    stalls : job times (s) at which the streaming loop missed control periods (the causes of deviations)
    lag_cause : what the tracking error of the mode comes from, in words (the cause of a deviation none of the
        others explains)
    fail_on_deviation : a run whose tracked path left the path tolerance (the recording's) fails with
        :class:`PathDeviationError` at its largest deviation (unless it failed otherwise)
    programs, program_bytes, seams : a program-mode run in several programs: how many, the limit each kept to
        (bytes), and the :class:`Seam` between each two
    """
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
    st = np.sort(np.asarray(list(stalls), dtype=float))
    period = 1.0 / float(job.settings.rate)
    if st.size or period != 0.002:  # the missed periods before each switch (planned job time), one entry per period
        events = [dataclasses.replace(e, missed_periods=int(np.searchsorted(st, e.planned_t, side="right")),
                                      period=period) for e in events]
    deviations = _deviations(rec, plan, failure, stalls, lag_cause or f"{mode} tracking")
    if fail_on_deviation and failure is None:
        failure = deviation_failure(rec, plan, stalls, lag_cause or f"{mode} tracking", deviations)
    return ExecutionReport(
        mode=mode, ok=failure is None, reason="" if failure is None else failure.reason,
        planned_duration=plan.duration, duration=rec.duration, samples=int(rec.samples),
        max_path_error=rec.max_error if rec.samples else 0.0, max_path_error_t=rec.max_error_t,
        io_events=tuple(events), joint_limit_margin=rec.margin if math.isfinite(rec.margin) else math.nan,
        failure=failure, path_length=plan.length, loop=loop, trace=trace, recorded_every=rec.step, gaps=rec.gaps,
        missed=rec.missed, longest_gap=rec.longest_gap, recording=recording,
        path_tolerance=math.nan if rec.tolerance is None else rec.tolerance, deviations=tuple(deviations),
        deviation_count=rec.excursion_count, programs=int(programs), program_bytes=int(program_bytes),
        seams=tuple(seams))


def deviation_failure(rec: Recording, plan: PlannedPath, stalls, lag_cause: str,
                      deviations: list[PathDeviation] | None = None) -> PathDeviationError | None:
    """The failure of a run made to fail on a path deviation: PathDeviationError at the recording's largest
    deviation so far (its place and cause), None when the tracked TCP stayed within the tolerance (or none was
    given). A streaming loop calls it as it records, to stop the arm as soon as it leaves the path."""
    if deviations is None:
        deviations = _deviations(rec, plan, None, stalls, lag_cause)
    if not deviations or rec.tolerance is None:
        return None
    worst = max(deviations, key=lambda dv: dv.error)
    return PathDeviationError(f"the tracked TCP left the planned path by {worst.error * 1e3:.3f} mm, beyond the path "
                              f"tolerance {rec.tolerance * 1e3:.3f} mm: {worst.cause}",
                              t=worst.t, pose=worst.pose, line=worst.line)


#: A deviation within this much job time of a missed control period or of a stop is put down to it, s.
CAUSE_WINDOW = 0.1


def _deviations(rec: Recording, plan: PlannedPath, failure, stalls, lag_cause: str) -> list[PathDeviation]:
    """The recording's excursions beyond its tolerance as :class:`PathDeviation` (place and cause)."""
    from drivers.base import EmergencyStopError, ProtectiveStopError

    out = []
    st = np.asarray(list(stalls), dtype=float)
    for ex in rec.excursions:
        _, pose, line = plan.at(ex.segment)
        a, b = ex.t_start - CAUSE_WINDOW, ex.t_end + CAUSE_WINDOW
        if (isinstance(failure, (ProtectiveStopError, EmergencyStopError)) and failure.t is not None
                and a <= failure.t <= b):
            cause = failure.kind
        elif st.size and ((st >= a) & (st <= ex.t_end)).any():
            n = int(((st >= a) & (st <= ex.t_end)).sum())
            cause = f"missed control periods (the streaming loop missed {counted(n, 'period')} just before)"
        else:
            cause = lag_cause
        out.append(PathDeviation(ex.t_start, ex.t_end, ex.error, ex.t, int(line),
                                 tuple(float(x) for x in pose), cause))
    return out


def as_planned(job, planned=None) -> PlannedPath:
    """``planned`` as a :class:`drivers.plan_window.PlannedPath`: itself; the arrays of :func:`planned_path` (kept,
    searched whole); read from ``job`` (a window at a time) when None."""
    if isinstance(planned, PlannedPath):
        return planned
    if planned is None:
        return PlannedPath(job)
    return PlannedPath(job, arrays=tuple(planned))


def new_recording(job, planned, *, block: int | None = None, prefetch: bool = False,
                  tolerance: float | None = None):
    """An empty :class:`drivers.recording.Recording` for a run of ``job`` against its planned path (a
    :class:`drivers.plan_window.PlannedPath`, or the arrays of :func:`planned_path`); ``block``: samples reduced
    at a time (default :data:`drivers.recording.BLOCK`; a real-time loop reduces small blocks, a fraction of its
    period each); ``prefetch``: the plan window's pieces made ahead in a thread (for a real-time loop);
    ``tolerance``: the path tolerance, m, whose excursions the report lists (:class:`PathDeviation`)."""
    plan = as_planned(job, planned)
    src = plan if plan.arrays is None else np.asarray(plan.arrays[1])[:, :3]
    return Recording(src, job.settings.robot, plan.length, block=BLOCK if block is None else block,
                     prefetch=prefetch, tolerance=tolerance)


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
