"""The planned path a run is compared with, in bounded memory: a summary read once, and a moving window.

A whole job at the controller rate is millions of samples (the NX job of ``../shared/data``: 12.9 million at
500 Hz, ~1 GB as arrays and as much again for a k-d tree of them). Nothing here holds the whole of it:

- :class:`PlannedPath`: the job's planned path read ONCE from its one trajectory (``job.trajectory(rate).chunks``,
  no second sampler), chunk by chunk, keeping only what the report needs of it: the number of samples, the
  duration, the length, the last pose, and each planned output switch with its station (time, position, arc
  length, direction of travel). :meth:`PlannedPath.pieces` reads the path again, lazily, in pieces;
  :meth:`PlannedPath.at` gives one sample's time, pose and line (the place of a failure).
- :class:`PlanWindow`: the distance of recorded samples, in time order, from the planned path, over a window of
  the plan around where the run is: the recorded TCP follows the plan with a bounded lag, so the planned samples
  whose job time is within ``back`` s before and ``ahead`` s after the recorded time (shifted by the run's
  measured offset from the plan: a program's timing differs from the plan's, a paused stream falls behind) hold
  the nearest point. The window moves in pieces of :data:`PIECE` samples (a k-d tree each, built once); pieces
  behind it are dropped. Memory: a few pieces, whatever the job's length.

A plan given as arrays (:func:`drivers.report.planned_path`'s result, already in memory) is searched whole
instead: that is the exact distance to the whole polyline, as before the window.
"""

from __future__ import annotations

import queue
import threading
from collections import deque
from dataclasses import dataclass

import numpy as np

#: Planned samples per piece of the window (131 s at 500 Hz; a k-d tree each, ~6 MB).
PIECE = 65_536
#: The window around each recorded sample: planned job time from ``t + offset - BACK`` to ``t + offset + AHEAD``, s.
BACK = 20.0
AHEAD = 20.0
#: Recorded samples are compared in spans of at most this much recorded time, s; the offset is measured after each.
SPAN = 10.0


@dataclass(frozen=True)
class PlannedStation:
    """Where a planned switch is: job time ``t`` s, position ``xyz`` (3,) m, arc length ``s`` m along the planned
    path, unit direction of travel ``tangent`` (3,) (zeros at rest)."""

    t: float
    xyz: np.ndarray
    s: float
    tangent: np.ndarray


def bit_switches(io: np.ndarray, first: int, offset: int = 0) -> list[tuple[int, bool, int]]:
    """(bit, value, index + offset) of every change of a bit in the io samples, from the state ``first`` before
    them."""
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
                out.append((b, bool((int(io[i]) >> b) & 1), int(i) + offset))
            bits >>= 1
            b += 1
    return out


def drop_blips(sw: list[tuple[int, bool, int]]) -> list[tuple[int, bool, int]]:
    """The switches (bit, value, index) without those undone :data:`drivers.stations.BLIP` samples later (the
    trajectory's output off for the one sample between two cuts joined at a corner: the drivers keep it on)."""
    from drivers.stations import BLIP

    dropped: set[int] = set()
    last: dict[int, int] = {}  # bit -> index in sw of its last switch kept
    for n, (b, v, i) in enumerate(sw):
        j = last.pop(b, None)
        if j is not None and i - sw[j][2] <= BLIP and sw[j][1] != v:
            dropped.update((j, n))  # undone at once: no switch
            continue
        last[b] = n
    return [x for n, x in enumerate(sw) if n not in dropped]


class PlannedPath:
    """A job's planned TCP path at the controller rate, summarized in one pass (see the module doc).

    Parameters
    ----------
    job : PlannedJob
    rate : float, optional
        Samples per second (default: the job's).
    arrays : tuple, optional
        Instead of reading the job: (times (n,), poses (n, 6), io (n,), lines (n,), arc length (n,)) as
        :func:`drivers.report.planned_path` gives them (kept: searched whole).

    Attributes: ``n`` samples, ``rate``, ``t_first``/``t_last`` s, ``length`` m, ``first_pose``/``last_pose`` (6,),
    ``switches`` [(bit, value, sample index)] (blips dropped), ``stations`` {index: :class:`PlannedStation`},
    ``mask`` (the output bits the job switches), ``arrays`` (the arrays given, or None).
    """

    def __init__(self, job=None, rate: float | None = None, *, arrays=None) -> None:
        self.job = job
        self.arrays = arrays
        if arrays is not None:
            t, p, io, ln, s = arrays
            self.rate = float(rate) if rate is not None else (
                float(1.0 / np.median(np.diff(t))) if np.size(t) > 1 else 500.0)
            self._summarize([(0, np.asarray(t, float), np.asarray(p, float), np.asarray(io, np.int64),
                              np.asarray(ln, np.int64))])
        else:
            self.rate = float(job.settings.rate if rate is None else rate)
            self._summarize(self.pieces())

    def _summarize(self, pieces) -> None:
        n, length, mask = 0, 0.0, 0
        t_first = t_last = float("nan")
        first_pose = last_pose = np.full(6, np.nan)
        prev_xyz: np.ndarray | None = None
        prev_io = 0
        raw: list[tuple[int, bool, int]] = []
        st: dict[int, list] = {}  # index -> [t, xyz, s, previous xyz, next xyz or None]
        waiting: list[int] = []  # switch indices at a piece's last sample: their next position comes later
        for k0, t, p, io, _ in pieces:
            m = t.size
            if m == 0:
                continue
            xyz = p[:, :3]
            ext = xyz if prev_xyz is None else np.vstack((prev_xyz[None], xyz))
            step = np.linalg.norm(np.diff(ext, axis=0), axis=1)
            s = length + (np.cumsum(step) if prev_xyz is not None else np.concatenate(([0.0], np.cumsum(step))))
            for i in waiting:  # their next sample is this piece's first (copies: a view would keep the piece)
                st[i][4] = xyz[0].copy()
            waiting = []
            sw = bit_switches(io, prev_io, k0)
            for _, _, i in sw:
                j = i - k0
                if i not in st:
                    before = xyz[j - 1] if j > 0 else (prev_xyz if prev_xyz is not None else xyz[0])
                    after = xyz[j + 1].copy() if j + 1 < m else None
                    st[i] = [float(t[j]), xyz[j].copy(), float(s[j]), np.asarray(before, float).copy(), after]
                    if after is None:
                        waiting.append(i)
            raw += sw
            for v in np.unique(io):
                mask |= int(v)
            if n == 0:
                t_first, first_pose = float(t[0]), p[0].copy()
            n += m
            t_last, last_pose = float(t[-1]), p[-1].copy()
            length = float(s[-1])
            prev_xyz, prev_io = xyz[-1].copy(), int(io[-1])
        self.n, self.length, self.mask = n, length, mask
        self.t_first, self.t_last = t_first, t_last
        self.first_pose, self.last_pose = first_pose, last_pose
        self.switches = drop_blips(raw)
        self.stations: dict[int, PlannedStation] = {}
        for _, _, i in self.switches:
            t, xyz, s, before, after = st[i]
            tan = (xyz if after is None else after) - before
            nt = float(np.linalg.norm(tan))
            self.stations[i] = PlannedStation(t, xyz, s, tan / nt if nt > 0 else tan)

    @property
    def duration(self) -> float:
        """Planned duration, s (0 without samples)."""
        return self.t_last - self.t_first if self.n else 0.0

    def pieces(self, size: int | None = None):
        """The planned path again, in order: (first sample index, times (m,), poses (m, 6), io (m,), lines (m,)),
        the trajectory's chunks cut and joined into pieces of ``size`` samples (default :data:`PIECE`; the last one
        shorter)."""
        size = PIECE if size is None else int(size)
        if self.arrays is not None:
            t, p, io, ln, _ = self.arrays
            yield 0, np.asarray(t, float), np.asarray(p, float), np.asarray(io, np.int64), np.asarray(ln, np.int64)
            return
        k0 = 0
        buf: list[tuple] = []
        count = 0
        for c in self.job.trajectory(self.rate).chunks(joints=False):
            if not len(c):
                continue
            buf.append((c.times, c.poses, c.io, c.lines))
            count += len(c)
            while count >= size:
                whole = self._merge(buf)
                yield k0, *(a[:size] for a in whole)
                k0 += size
                count -= size
                buf = [tuple(a[size:] for a in whole)] if count else []
        if count:
            yield k0, *self._merge(buf)

    @staticmethod
    def _merge(buf):
        if len(buf) == 1:
            return buf[0]
        return tuple(np.concatenate([b[i] for b in buf]) for i in range(4))

    def at(self, k: int, window=None) -> tuple[float, np.ndarray, int]:
        """Sample ``k``'s (clipped to the path) job time s, pose (6,) and source line: from ``window`` (a
        :class:`PlanWindow`) when it holds the sample, else read from the trajectory (one pass up to it)."""
        k = min(max(int(k), 0), max(self.n - 1, 0))
        if isinstance(window, PlanWindow):
            got = window.sample(k)
            if got is not None:
                return got
        for k0, t, p, _, ln in self.pieces():
            if k < k0 + t.size:
                j = k - k0
                return float(t[j]), p[j].copy(), int(ln[j])
        return float("nan"), np.full(6, np.nan), -1


class _Piece:
    """Planned samples [k0, k0 + m) with a k-d tree of their positions (and the sample before them, so that the
    segment joining two pieces belongs to the later one)."""

    __slots__ = ("k0", "t", "poses", "lines", "index", "base")

    def __init__(self, k0: int, t, poses, lines, before) -> None:
        from drivers.geometry import PolylineIndex

        self.k0, self.t, self.poses, self.lines = k0, t, poses, lines
        xyz = poses[:, :3]
        if before is None:
            self.index, self.base = PolylineIndex(xyz), k0
        else:
            self.index, self.base = PolylineIndex(np.vstack((before[None], xyz))), k0 - 1

    @property
    def t_end(self) -> float:
        return float(self.t[-1])


class PlanWindow:
    """Distances of recorded samples (in time order) from a :class:`PlannedPath` (see the module doc):
    :meth:`distance`. A plan given as arrays is searched whole (one piece, never dropped)."""

    def __init__(self, plan: PlannedPath, *, back: float | None = None, ahead: float | None = None,
                 span: float | None = None, prefetch: bool = False) -> None:
        self.plan = plan
        self.back = BACK if back is None else float(back)
        self.ahead = AHEAD if ahead is None else float(ahead)
        self.span = SPAN if span is None else float(span)
        #: the most planned samples the window held at once (its memory: ~100 B a sample with the k-d tree)
        self.max_held = 0
        self.whole = plan.arrays is not None
        self._it = self._produce()
        self._pieces: deque[_Piece] = deque()
        self._done = False
        self._queue: queue.Queue | None = None
        self._stop = threading.Event()
        if prefetch and not self.whole:
            # a real-time loop reduces its recording between its periods: the next pieces (sampled, their k-d trees
            # built: tens of ms each) are made ahead by a thread of their own, never in a period
            self._queue = queue.Queue(maxsize=2)
            threading.Thread(target=self._prefetch, name="plan-window", daemon=True).start()
        #: planned job time minus recorded time, s, as last measured (the run's lag behind the plan, negated)
        self.offset = 0.0
        if self.whole:
            self._load()
        self.n = plan.n

    def _produce(self):
        before = None
        for k0, t, p, _, ln in self.plan.pieces():
            yield _Piece(k0, t, p, ln, before)
            before = p[-1, :3].copy()

    def _prefetch(self) -> None:
        q = self._queue
        assert q is not None
        try:
            for pc in self._it:
                while not self._stop.is_set():
                    try:
                        q.put(pc, timeout=0.1)
                        break
                    except queue.Full:
                        continue
                if self._stop.is_set():
                    return
            q.put(None)
        except BaseException as exc:  # handed to the consumer
            q.put(exc)

    def _load(self) -> bool:
        if self._done:
            return False
        if self._queue is not None:
            nxt = self._queue.get()
            if isinstance(nxt, BaseException):
                self._done = True
                raise nxt
        else:
            nxt = next(self._it, None)
        if nxt is None:
            self._done = True
            return False
        self._pieces.append(nxt)
        return True

    def prime(self) -> None:
        """Load the window's first pieces now (before a real-time loop starts: never waited for in a period)."""
        self._cover(-self.back, self.ahead + self.span)

    def close(self) -> None:
        """Stop the prefetching thread, if any (the window answers no more)."""
        self._stop.set()
        if self._queue is not None:
            try:
                while True:
                    self._queue.get_nowait()
            except queue.Empty:
                pass

    def _cover(self, lo: float, hi: float) -> None:
        """Load pieces up to planned time ``hi``; drop those ending before ``lo`` (the last one kept)."""
        if self.whole:
            return
        while (not self._pieces or self._pieces[-1].t_end < hi) and self._load():
            pass
        while len(self._pieces) > 1 and self._pieces[0].t_end < lo:
            self._pieces.popleft()
        self.max_held = max(self.max_held, sum(pc.t.size for pc in self._pieces))

    def distance(self, points: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distance (m) of each recorded position (m, 3) at recorded job times (m,) s from the planned path, and the
        index of the nearest planned segment's start (m,)."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        times = np.asarray(times, dtype=float).reshape(-1)
        m = points.shape[0]
        d = np.full(m, np.inf)
        seg = np.zeros(m, np.int64)
        if m == 0 or self.plan.n == 0:
            return np.full(m, np.nan), seg
        if self.whole:
            dd, ss = self._pieces[0].index.distance(points)
            return dd, ss + self._pieces[0].base
        a = 0
        while a < m:
            b = int(np.searchsorted(times, times[a] + self.span, side="right"))
            b = max(b, a + 1)
            pt, tt = points[a:b], times[a:b]
            lo, hi = float(tt.min()) + self.offset - self.back, float(tt.max()) + self.offset + self.ahead
            self._cover(lo, hi)
            tp = tt + self.offset
            for pc in self._pieces:
                sel = np.flatnonzero((tp + self.ahead >= float(pc.t[0]) - 1.0 / self.plan.rate)
                                     & (tp - self.back <= pc.t_end))
                if sel.size == 0:
                    continue
                dd, ss = pc.index.distance(pt[sel])
                better = dd < d[a + sel]
                d[a + sel[better]] = dd[better]
                seg[a + sel[better]] = ss[better] + pc.base
            miss = ~np.isfinite(d[a:b])
            if miss.any():  # outside every piece's time (before the plan, after its end): the nearest piece
                for pc in self._pieces:
                    dd, ss = pc.index.distance(pt[miss])
                    idx = a + np.flatnonzero(miss)
                    better = dd < d[idx]
                    d[idx[better]] = dd[better]
                    seg[idx[better]] = ss[better] + pc.base
            ok = np.isfinite(d[a:b])
            if ok.any():
                self.offset = float(np.median(seg[a:b][ok] / self.plan.rate - tt[ok]))
            a = b
        return d, seg

    def sample(self, k: int) -> tuple[float, np.ndarray, int] | None:
        """Sample ``k``'s job time, pose and line if a piece of the window holds it, else None."""
        for pc in self._pieces:
            j = k - pc.k0
            if 0 <= j < pc.t.size:
                return float(pc.t[j]), pc.poses[j].copy(), int(pc.lines[j])
        return None
