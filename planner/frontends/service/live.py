"""Live joint states of the executions this service process runs: what the page's 3D view shows of the arm while a job
runs (``GET /v1/executions/{id}/live``, Server-Sent Events).

The execution's worker process relays the driver's recorded samples, thinned to ``tasks.functions.LIVE_RATE`` (job
time, joints, TCP position, output bits; :class:`~.tasks.lifecycle.Live` messages); the runner (in this process)
appends them here. Each execution keeps its last :data:`KEEP` samples (a page that connects or reconnects gets the
recent past, then what follows), numbered from 1 (an event's id: a reconnecting page sends the last it had,
``Last-Event-ID``). Executions run by another process (a Celery worker) are not seen here: their page shows progress
only.
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict, deque

import numpy as np

#: Samples kept per execution.
KEEP = 20_000
#: Executions kept (the oldest forgotten first).
EXECUTIONS = 16


class LiveFeed:
    """One execution's samples: rows (seq, t s, q0..q5 rad, x, y, z m, io bits); ``ended`` once it ended."""

    def __init__(self) -> None:
        self.rows: deque = deque(maxlen=KEEP)
        self.seq = 0
        self.ended = False
        self.changed = threading.Condition()

    def add(self, t: np.ndarray, q: np.ndarray, xyz: np.ndarray, io: np.ndarray) -> None:
        n = int(np.asarray(t).size)
        if not n:
            return
        block = np.column_stack((np.arange(self.seq + 1, self.seq + n + 1), t, q, xyz, io)).astype(float)
        with self.changed:
            self.rows.extend(block)
            self.seq += n
            self.changed.notify_all()

    def end(self) -> None:
        with self.changed:
            self.ended = True
            self.changed.notify_all()

    def after(self, seq: int, wait: float = 0.0) -> tuple[np.ndarray, bool]:
        """The rows numbered above ``seq`` (waiting up to ``wait`` s for one), and whether the execution ended."""
        deadline = time.monotonic() + wait
        with self.changed:
            while self.seq <= seq and not self.ended and time.monotonic() < deadline:
                self.changed.wait(max(deadline - time.monotonic(), 0.0))
            if self.seq <= seq:
                return np.zeros((0, 14)), self.ended
            rows = [r for r in self.rows if r[0] > seq]
            return np.array(rows), self.ended


class LiveHub:
    """The feeds of this process's executions, by execution id."""

    def __init__(self) -> None:
        self.feeds: OrderedDict[str, LiveFeed] = OrderedDict()
        self.lock = threading.Lock()

    def feed(self, execution_id: str, create: bool = False) -> LiveFeed | None:
        with self.lock:
            f = self.feeds.get(execution_id)
            if f is None and create:
                f = self.feeds[execution_id] = LiveFeed()
                while len(self.feeds) > EXECUTIONS:
                    self.feeds.popitem(last=False)
            return f

    def add(self, execution_id: str, t, q, xyz, io) -> None:
        f = self.feed(execution_id, create=True)
        assert f is not None
        f.add(t, q, xyz, io)

    def end(self, execution_id: str) -> None:
        f = self.feed(execution_id)
        if f is not None:
            f.end()


#: This process's hub.
HUB = LiveHub()
