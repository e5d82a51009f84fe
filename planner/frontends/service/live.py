"""Live joint states of executions: what the page's 3D view shows of the arm while a job runs
(``GET /v1/executions/{id}/live``, Server-Sent Events).

The execution's worker process relays the driver's recorded samples, thinned to ``tasks.functions.LIVE_RATE`` (job
time, joints, TCP position, output bits; :class:`~.tasks.lifecycle.Live` messages); the runner hands them to its
backend's *live hub*, which numbers them from 1 (an event's id: a reconnecting page sends the last it had,
``Last-Event-ID``) and keeps each execution's last :data:`KEEP` samples (a page that connects or reconnects gets the
recent past, then what follows):

- :class:`LiveHub` (the local backend): in the service process that runs the execution (:data:`HUB`);
- :class:`RedisLive` (the celery backend): a Redis stream per execution on the broker's Redis, written by the
  ``planner worker`` that runs it and read by every API replica (a replica restarted mid-run, or another one behind
  the proxy, streams the same samples).

Both answer ``feed(execution_id)`` with an object whose ``after(seq, wait)`` gives the rows numbered above ``seq``
(waiting up to ``wait`` s for one) and whether the execution's feed has ended, or None while there is no feed.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections import OrderedDict, deque

import numpy as np

log = logging.getLogger("planner.frontends.service")

#: Samples kept per execution.
KEEP = 20_000
#: Executions kept (the oldest forgotten first).
EXECUTIONS = 16


#: Columns of a row: seq, t s, q0..q5 rad, x, y, z m, io bits.
COLUMNS = 12


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
                return np.zeros((0, COLUMNS)), self.ended
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


#: Seconds a Redis live stream is kept after its last write (an execution that never ended: its worker lost).
REDIS_TTL = 24 * 3600.0
#: Seconds a Redis live stream is kept after its execution ended.
REDIS_TTL_ENDED = 3600.0


def _stream_key(execution_id: str) -> str:
    return f"planner:live:{execution_id}"


class RedisLive:
    """The live hub of the celery backend: one Redis stream per execution (``planner:live:<id>``) on ``url`` (the
    broker's Redis), an entry per batch of samples (``rows``: float64 little-endian, :data:`COLUMNS` per row) whose
    stream id is ``0-<seq of its last row>`` (a reader resumes after a row number with ``XREAD`` from ``0-<seq>``),
    and an ``end`` entry; trimmed to about :data:`KEEP` entries and expired (:data:`REDIS_TTL`,
    :data:`REDIS_TTL_ENDED`). The writer (a ``planner worker``) never fails a run for it: a sample Redis does not take
    is left out of the live view."""

    def __init__(self, url: str | None) -> None:
        import redis

        from planner.errors import PlannerError

        if not url:
            raise PlannerError("the celery backend needs PLANNER_BROKER (redis://HOST:PORT/0)")
        self.client = redis.Redis.from_url(url, socket_timeout=5.0, socket_connect_timeout=2.0)
        self.seq: dict[str, int] = {}
        self.lock = threading.Lock()

    def add(self, execution_id: str, t, q, xyz, io) -> None:
        n = int(np.asarray(t).size)
        if not n:
            return
        with self.lock:
            first = self.seq.get(execution_id, 0) + 1
            self.seq[execution_id] = first + n - 1
        block = np.column_stack((np.arange(first, first + n), t, q, xyz, io)).astype("<f8")
        key = _stream_key(execution_id)
        try:
            pipe = self.client.pipeline(transaction=False)
            pipe.xadd(key, {"rows": block.tobytes()}, id=f"0-{first + n - 1}", maxlen=KEEP, approximate=True)
            pipe.expire(key, int(REDIS_TTL))
            pipe.execute()
        except Exception as exc:  # the broker away: these samples miss the live view, never the run
            log.debug("live samples of %s not relayed: %s", execution_id, exc)

    def end(self, execution_id: str) -> None:
        key = _stream_key(execution_id)
        with self.lock:
            last = self.seq.pop(execution_id, 0)
        with contextlib.suppress(Exception):
            pipe = self.client.pipeline(transaction=False)
            pipe.xadd(key, {"end": b"1"}, id=f"0-{last + 1}")
            pipe.expire(key, int(REDIS_TTL_ENDED))
            pipe.execute()

    def feed(self, execution_id: str, create: bool = False) -> RedisFeed | None:
        """The execution's stream, or None while it has none (or Redis does not answer)."""
        key = _stream_key(execution_id)
        try:
            if not self.client.exists(key):
                return None
        except Exception:
            return None
        return RedisFeed(self.client, key)


class RedisFeed:
    """One execution's Redis stream, read as :meth:`LiveFeed.after`."""

    def __init__(self, client, key: str) -> None:
        self.client = client
        self.key = key

    def after(self, seq: int, wait: float = 0.0) -> tuple[np.ndarray, bool]:
        try:
            got = self.client.xread({self.key: f"0-{int(seq)}"}, count=KEEP, block=max(int(wait * 1000), 1))
        except Exception:  # Redis away for a moment: nothing now, the next read tries again
            time.sleep(wait)
            return np.zeros((0, COLUMNS)), False
        blocks, ended = [], False
        for _key, entries in got or []:
            for _id, fields in entries:
                if b"end" in fields:
                    ended = True
                elif b"rows" in fields:
                    blocks.append(np.frombuffer(fields[b"rows"], "<f8").reshape(-1, COLUMNS))
        if not blocks:
            return np.zeros((0, COLUMNS)), ended
        rows = np.vstack(blocks)
        return rows[rows[:, 0] > seq], ended
