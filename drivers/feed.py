"""The servo targets of a job, produced ahead of a real-time loop by a background thread (bounded memory).

:class:`TargetFeed` reads the planner's one trajectory (``job.trajectory(rate).chunks()``: joints, I/O bits,
times, poses; never a second sampler) in a thread of its own and hands it to the streaming loop in slices of
Python lists (no numpy per sample in the loop), at most ``depth`` slices ahead: memory stays bounded whatever the
job's length, and the loop never waits for the planner's inverse kinematics (a chunk of 65,536 samples takes
~0.15 s, 75 control periods). With a ``shaper`` (:class:`drivers.servo.ServoShaper`) the joints handed over are
its servo targets for the planned joints. A chunk with a pose without joints (unreachable) ends the feed with a
:class:`drivers.base.DriverError` naming the sample's time, pose and line, before its slice is handed over.
"""

from __future__ import annotations

import queue
import threading
from dataclasses import dataclass

import numpy as np

from drivers.base import DriverError

#: Samples per slice (5 s at 500 Hz).
SLICE = 2500
#: Planned positions kept before each slice (for a station's direction of travel).
HISTORY = 50


@dataclass(frozen=True, eq=False)
class TargetSlice:
    """Consecutive samples of the trajectory: ``q`` joints (lists of 6 floats, rad: the servo targets when the feed
    shapes them), ``io`` output bits, ``t``
    job times (s), ``lines`` source lines (lists); ``positions`` (HISTORY + n, 3) planned TCP positions (m) with
    up to HISTORY samples before the slice first (``history`` of them); ``start`` the job-wide index of the
    slice's first sample."""

    start: int
    q: list
    io: list
    t: list
    lines: list
    positions: np.ndarray
    history: int

    def __len__(self) -> int:
        return len(self.t)


class TargetFeed:
    """Slices of ``trajectory.chunks()`` produced ahead by a daemon thread (see the module doc).

    Iterate it in the consuming thread; :meth:`close` stops the producer (always call it, e.g. in ``finally``).
    """

    def __init__(self, trajectory, *, depth: int = 4, size: int = SLICE, shaper=None) -> None:
        self._chunks = trajectory.chunks()
        self._shaper = shaper
        self._last: np.ndarray | None = None  # the last planned joints handed over (unshaped feed)
        self._q: queue.Queue = queue.Queue(maxsize=max(1, int(depth)))
        self._size = int(size)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="target-feed", daemon=True)
        self._thread.start()

    def _put(self, item) -> bool:
        while not self._stop.is_set():
            try:
                self._q.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def _run(self) -> None:
        k = 0
        tail = np.zeros((0, 3))
        try:
            for c in self._chunks:
                n = len(c)
                if n == 0:
                    continue
                bad = np.flatnonzero(~np.isfinite(c.joints).all(axis=1))
                if bad.size:
                    i = int(bad[0])
                    raise DriverError("the job has poses without joint positions (unreachable); the run stops "
                                      "before them", t=float(c.times[i]), pose=c.poses[i], line=int(c.lines[i]))
                q = c.joints if self._shaper is None else self._shaper.shape(c.joints)
                pos = np.vstack((tail, c.poses[:, :3]))
                h0 = tail.shape[0]
                for a in range(0, n, self._size):
                    b = min(a + self._size, n)
                    h = min(h0 + a, HISTORY)
                    sl = TargetSlice(k + a, q[a:b].tolist(), c.io[a:b].tolist(), c.times[a:b].tolist(),
                                     c.lines[a:b].tolist(), pos[h0 + a - h:h0 + b].copy(), h)
                    if not self._put(sl):
                        return
                k += n
                self._last = c.joints[-1].copy()
                tail = pos[-HISTORY:].copy()
            self._put(None)
        except BaseException as exc:  # handed to the consumer, raised there
            self._put(exc)

    def __iter__(self):
        while True:
            item = self._q.get()
            if item is None:
                return
            if isinstance(item, BaseException):
                raise item
            yield item

    def hold(self, n: int) -> list:
        """After the last slice: ``n`` targets (lists of 6 floats) holding the arm on the job's last planned joints
        (shaped by the feed's shaper, if any; the last target handed over, otherwise)."""
        if self._shaper is not None:
            return self._shaper.hold(n).tolist()
        return [list(self._last)] * max(int(n), 0) if self._last is not None else []

    def close(self) -> None:
        """Stop the producer and drop what it made."""
        self._stop.set()
        try:
            while True:
                self._q.get_nowait()
        except queue.Empty:
            pass
        self._thread.join(5.0)
