"""What a run records, reduced as it goes: the report's figures and a bounded trace, never the whole recording.

A driver adds one sample per control period (:meth:`Recording.add`: job time, actual TCP pose, actual joints,
actual digital output bits). Every ``block`` samples the block is reduced and dropped:

- the largest distance of the actual TCP from the PLANNED PATH (the planned polyline at the controller rate, over
  a window of it around the run's place: :class:`drivers.plan_window.PlanWindow`) and its time; the smallest
  joint-limit margin; the first and last time and the number of samples; the recording's gaps (steps between
  samples longer than 1.5 x its usual step: data packages missed);
- the trace (:class:`ExecutionTrace`): times, TCP positions, TCP speed and output bits of at most ``max_trace``
  samples, decimated by distance travelled (one sample per ``spacing`` metres, the spacing doubled whenever the
  trace would pass its bound) and keeping EVERY sample at which an output changed together with the sample before
  it (so the I/O switches computed from the trace are the ones of the whole recording, exactly).

So a run's memory does not grow with its length, nor does the planned path's it is compared with (read lazily,
a window of it at a time: :mod:`drivers.plan_window`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drivers.geometry import PolylineIndex, joint_limit_margin
from drivers.plan_window import PlannedPath, PlanWindow

#: Samples reduced at a time.
BLOCK = 2500
#: Samples of the trace at most.
MAX_TRACE = 20_000
#: A step between recorded samples longer than this many times the usual step is a gap (packages missed).
GAP = 1.5
#: Excursions beyond the path tolerance kept (the first ones; the rest are counted).
MAX_EXCURSIONS = 20


@dataclass
class Excursion:
    """Where the tracked TCP left the planned path by more than the path tolerance: job times ``t_start`` to
    ``t_end`` s (the first and last recorded sample beyond it), the largest distance ``error`` m there, at job time
    ``t`` s, nearest the planned sample ``segment`` (its start)."""

    t_start: float
    t_end: float
    error: float
    t: float
    segment: int


class _WholePath:
    """Planned positions (m, 3) already in memory, searched whole (:meth:`PlanWindow.distance`'s interface)."""

    def __init__(self, xyz: np.ndarray) -> None:
        self.index = PolylineIndex(xyz)
        self.n = self.index.n

    def distance(self, points: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.index.distance(points)


@dataclass(frozen=True, eq=False)
class ExecutionTrace:
    """A bounded trace of what a run recorded (see the module doc).

    t (n,) job time, s; xyz (n, 3) actual TCP position, m (base frame); speed (n,) actual TCP speed, m/s (over
    the recorded step ending at the sample); io (n,) actual digital output bits; spacing: the distance
    decimation's final spacing, m; segment (n,): index of the planned segment nearest each sample (its start)."""

    t: np.ndarray
    xyz: np.ndarray
    speed: np.ndarray
    io: np.ndarray
    spacing: float
    segment: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.t.size)


class Recording:
    """A run's samples, reduced block by block (see the module doc).

    Parameters
    ----------
    planned : PlannedPath or ndarray (m, 3)
        The planned path the actual TCP is measured against: a :class:`drivers.plan_window.PlannedPath` (read a
        window at a time), or its positions at the controller rate, m (in memory: searched whole).
    model : str or None
        UR model (for the joint-limit margin).
    path_length : float
        The planned path's length, m (sets the trace's first spacing: about ``max_trace / 2`` samples for a run
        that follows it).
    prefetch : bool
        Make the plan window's next pieces ahead in a thread of their own (a real-time loop's recording).
    tolerance : float, optional
        Path tolerance, m: the excursions of the tracked TCP beyond it are kept (:attr:`excursions`, the first
        MAX_EXCURSIONS of them; :attr:`excursion_count` all).
    """

    def __init__(self, planned: PlannedPath | np.ndarray, model: str | None, path_length: float = 0.0, *,
                 max_trace: int = MAX_TRACE, block: int = BLOCK, prefetch: bool = False,
                 tolerance: float | None = None) -> None:
        if max_trace < 16:
            raise ValueError(f"max_trace must be >= 16 samples, got {max_trace!r}")
        self.planned: PlanWindow | _WholePath = (PlanWindow(planned, prefetch=prefetch)
                                                 if isinstance(planned, PlannedPath) else _WholePath(planned))
        self.model = model
        self.max_trace = int(max_trace)
        self.block = max(1, int(block))
        self.spacing = max(float(path_length), 0.0) / (self.max_trace / 2) or 1e-4
        self.samples = 0
        self.t_first = math.nan
        self.t_last = math.nan
        self.max_error = 0.0
        self.max_error_t = math.nan
        self.margin = math.inf
        #: index of the planned segment nearest the last sample reduced (its start): where the run is
        self.last_segment = 0
        #: the recording's usual step between samples, s (the largest median of a block's); its gaps: steps longer than
        #: GAP x that, the samples missed in them, the longest, s
        self.step = math.nan
        self.gaps = 0
        self.missed = 0
        self.longest_gap = 0.0
        self.tolerance = None if tolerance is None else float(tolerance)
        #: Called with every batch :meth:`extend` receives (t, x, q, bits), before it is reduced: a live view's feed
        #: (it must return at once: a real-time loop calls it)
        self.listener: Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], None] | None = None
        self.excursions: list[Excursion] = []
        self.excursion_count = 0
        self._open: Excursion | None = None  # the excursion the last sample reduced is in
        self._t: list = []
        self._x: list = []
        self._q: list = []
        self._b: list = []
        # the trace's undecided last sample: (t, xyz, speed, io, changed there, distance travelled to it, segment)
        self._tail: tuple | None = None
        self._trace: list[np.ndarray] = []  # blocks of rows (t, x, y, z, speed, io, keep-flag 1 = must keep, segment)
        self._rows = 0

    def add(self, t: float, x, q, bits: int) -> None:
        """One sample: job time s, actual TCP pose (6,) p[x, y, z, rx, ry, rz], actual joints (6,) rad, bits."""
        self._t.append(t)
        self._x.append(x)
        self._q.append(q)
        self._b.append(bits)
        if len(self._t) >= self.block:
            self._reduce()

    @property
    def pending(self) -> int:
        """Samples added and not yet reduced."""
        return len(self._t)

    def reduce_pending(self) -> None:
        """Reduce the samples added so far now (a real-time loop calls this when its period has time to spare;
        :meth:`add` reduces by itself every ``block`` samples otherwise)."""
        self._reduce()

    def extend(self, t, x, q, bits) -> None:
        """Many samples: (n,), (n, 6), (n, 6), (n,)."""
        t = np.asarray(t, dtype=float).reshape(-1)
        n = t.size
        x = np.asarray(x, dtype=float).reshape(n, 6)
        q = np.asarray(q, dtype=float).reshape(n, 6)
        b = np.asarray(bits, dtype=np.int64).reshape(n)
        if self.listener is not None and n:
            self.listener(t, x, q, b)
        for a in range(0, n, self.block):
            self._reduce_arrays(t[a:a + self.block], x[a:a + self.block], q[a:a + self.block], b[a:a + self.block])

    def _reduce(self) -> None:
        if not self._t:
            return
        t = np.asarray(self._t, dtype=float)
        x = np.asarray(self._x, dtype=float).reshape(-1, 6)
        q = np.asarray(self._q, dtype=float).reshape(-1, 6)
        b = np.asarray(self._b, dtype=np.int64)
        self._t, self._x, self._q, self._b = [], [], [], []
        self._reduce_arrays(t, x, q, b)

    def _reduce_arrays(self, t: np.ndarray, x: np.ndarray, q: np.ndarray, b: np.ndarray) -> None:
        n = t.size
        if n == 0:
            return
        xyz = x[:, :3]
        if self.samples == 0:
            self.t_first = float(t[0])
        self.samples += n
        self.t_last = float(t[-1])
        seg = np.zeros(n, np.int64)
        if self.planned.n:
            d, seg = self.planned.distance(xyz, t)
            if np.isfinite(d).any():
                w = int(np.nanargmax(d))
                if d[w] > self.max_error or math.isnan(self.max_error_t):
                    self.max_error, self.max_error_t = float(d[w]), float(t[w])
            self.last_segment = int(seg[-1])
            if self.tolerance is not None:
                self._excursions(d, t, seg)
        m = joint_limit_margin(self.model, q)
        if not math.isnan(m):
            self.margin = min(self.margin, m)
        # the trace: the undecided last sample of the previous block (the tail) first, then this block's; a sample's
        # fate is decided once the next one is known (kept before an output change)
        if self._tail is None:  # the run's first sample: the outputs were cleared before the run
            tail = (float(t[0]), xyz[0], 0.0, 0, float(b[0] != 0), 0.0, int(seg[0]))
            t, xyz, b, seg = t[1:], xyz[1:], b[1:], seg[1:]
        else:
            tail = self._tail
        tt = np.concatenate(([tail[0]], t))
        pp = np.vstack((tail[1][None], xyz))
        bb = np.concatenate(([tail[3]], b))
        ss = np.concatenate(([tail[6]], seg))
        step = np.linalg.norm(np.diff(pp, axis=0), axis=1)
        dt = np.diff(tt)
        self._count_gaps(dt)
        speed = np.concatenate(([tail[2]], np.where(dt > 0, step / np.where(dt > 0, dt, 1.0), 0.0)))
        cum = tail[5] + np.concatenate(([0.0], np.cumsum(step)))
        change = np.concatenate(([tail[4] > 0], bb[1:] != bb[:-1]))
        must = change.copy()
        must[:-1] |= change[1:]  # the sample before a change
        if self._rows == 0 and not self._trace:
            must[0] = True  # the run's first sample
        cell = np.floor(cum / self.spacing)
        keep = must.copy()
        keep[1:] |= cell[1:] != cell[:-1]
        # all but the last are decided; the last waits for the next block (or finish())
        idx = np.flatnonzero(keep[:-1])
        if idx.size:
            rows = np.column_stack((tt[idx], pp[idx], speed[idx], bb[idx].astype(float), must[idx].astype(float),
                                    ss[idx].astype(float)))
            self._trace.append(rows)
            self._rows += rows.shape[0]
        self._tail = (float(tt[-1]), pp[-1].copy(), float(speed[-1]), int(bb[-1]), float(change[-1]), float(cum[-1]),
                      int(ss[-1]))
        while self._rows > self.max_trace:
            self._thin()

    def _excursions(self, d: np.ndarray, t: np.ndarray, seg: np.ndarray) -> None:
        """Extend the excursions beyond the tolerance by a block's distances ``d`` (n,) at times ``t``."""
        tol = self.tolerance
        over = np.nan_to_num(d, nan=0.0) > tol
        if not over.any():
            self._open = None
            return
        # runs of consecutive samples beyond the tolerance: starts and ends (inclusive)
        edge = np.diff(np.concatenate(([0], over.astype(np.int8), [0])))
        starts, ends = np.flatnonzero(edge == 1), np.flatnonzero(edge == -1) - 1
        for a, b in zip(starts, ends, strict=True):
            w = a + int(np.nanargmax(d[a:b + 1]))
            cur = self._open if a == 0 else None
            if cur is not None:
                cur.t_end = float(t[b])
                if d[w] > cur.error:
                    cur.error, cur.t, cur.segment = float(d[w]), float(t[w]), int(seg[w])
            else:
                cur = Excursion(float(t[a]), float(t[b]), float(d[w]), float(t[w]), int(seg[w]))
                self.excursion_count += 1
                if len(self.excursions) < MAX_EXCURSIONS:
                    self.excursions.append(cur)
            self._open = cur if b == over.size - 1 else None

    def _count_gaps(self, dt: np.ndarray) -> None:
        """Steps longer than GAP x the usual step (the largest median of a block of at least 20 steps so far: a
        controller catching up after a stall sends its packages closer together, never further apart): gaps."""
        pos = dt[dt > 0]
        if pos.size >= 20:
            med = float(np.median(pos))
            self.step = med if not math.isfinite(self.step) else max(self.step, med)
        if not math.isfinite(self.step) or pos.size == 0:
            return
        long = pos[pos > GAP * self.step]
        if long.size:
            self.gaps += int(long.size)
            self.missed += int(np.maximum(np.rint(long / self.step) - 1, 1).sum())
            self.longest_gap = max(self.longest_gap, float(long.max()))

    def _thin(self) -> None:
        """Halve the trace's distance samples (double the spacing); the must-keep samples stay."""
        rows = np.concatenate(self._trace)
        must = rows[:, 6] > 0
        free = np.flatnonzero(~must)
        drop = free[1::2]
        if drop.size == 0:
            raise RuntimeError("the trace cannot hold the run's output changes (more than max_trace of them)")
        rows = np.delete(rows, drop, axis=0)
        self._trace = [rows]
        self._rows = rows.shape[0]
        self.spacing *= 2.0

    def finish(self) -> None:
        """Reduce what is left and keep the run's last sample (call once, when the run has ended)."""
        self._reduce()
        if self._tail is not None:
            t, xyz, speed, io, _, _, seg = self._tail
            self._trace.append(np.array([[t, *xyz, speed, float(io), 1.0, float(seg)]]))
            self._rows += 1
            self._tail = None
        if isinstance(self.planned, PlanWindow):
            self.planned.close()

    @property
    def duration(self) -> float:
        return float(self.t_last - self.t_first) if self.samples > 1 else 0.0

    def trace(self) -> ExecutionTrace:
        """The bounded trace (after :meth:`finish`)."""
        rows = np.concatenate(self._trace) if self._trace else np.zeros((0, 8))
        return ExecutionTrace(rows[:, 0].copy(), rows[:, 1:4].copy(), rows[:, 4].copy(),
                              rows[:, 5].astype(np.int64), self.spacing, rows[:, 7].astype(np.int64))
