"""New jobs stored by the event loop itself, every row that arrives in one turn of the loop committed in one
transaction (group commit): a burst of submissions costs one commit, not one each.

Why in the loop and not in a thread of its own: Python's sqlite3 releases the GIL around every statement step (one
per row of an executemany), and a thread taking it back waits for the busy event loop to give it up (up to the
interpreter's switch interval each time), so a commit of 20 rows took 7-15 ms in a thread against well under a
millisecond here; the requests waiting for it waited that long. The loop is blocked for the commit itself only
(SQLite in WAL mode with synchronous=NORMAL: no fsync in a commit).
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from sqlalchemy import Table

from planner.frontends.service.store import Job, JobData, now
from planner.frontends.service.tasks.transitions import Transitions

#: The jobs table itself (inserts without the ORM's per-row bookkeeping).
JOBS: Table = Job.__table__  # type: ignore[assignment]
DATA: Table = JobData.__table__  # type: ignore[assignment]
#: Rows inserted by one multi-row INSERT whose compiled form is cached (with RETURNING, SQLAlchemy sends an
#: executemany as "insertmanyvalues" statements of up to 1000 rows each; ``.values(rows)`` compiled the statement
#: again for every batch: a tenth of the API replica's CPU per submit).
_MANY_ROWS = JOBS.insert().returning(JOBS.c.id)
#: Most rows stored by one such statement (SQLAlchemy's insertmanyvalues page size); a larger batch is one transaction.
ONE_STATEMENT_ROWS = 1000


class Inserter:
    """Stores job rows (and an uploaded input's bytes) in group commits; ``submitted`` is told the ids committed.

    SQLite (in the process, no network): the commit runs in the event loop after the turn's requests. A database
    server (PostgreSQL): the commit's round trips run in a thread of their own, one commit at a time, while the loop
    goes on accepting requests; the rows that arrive meanwhile make the next commit."""

    def __init__(self, store: Transitions, submitted: Callable[[list[str]], None]):
        self.store = store
        self.submitted = submitted
        self._pending: list[tuple[dict, bytes | None, asyncio.Future]] = []
        self._threaded = not store.sqlite
        self._in_flight = False
        self._executor = ThreadPoolExecutor(1, thread_name_prefix="planner-commit") if self._threaded else None
        self._conn: Any = None  # the commit thread's own connection (a database server)

    async def store_job(self, row: dict, data: bytes | None = None) -> None:
        """Store a job row (the columns of :class:`Job`) and its input file's bytes; returns once committed (raises
        what the commit raised, e.g. the database is gone)."""
        loop = asyncio.get_running_loop()
        done = loop.create_future()
        self._pending.append((row, data, done))
        if self._threaded:
            if not self._in_flight:
                self._in_flight = True
                loop.call_soon(self._start, loop)
        elif len(self._pending) == 1:  # the first of this turn: the commit runs after the turn's other requests
            loop.call_soon(self._commit)
        await asyncio.shield(done)  # a request cancelled meanwhile (its client went away) is committed all the same

    def _start(self, loop: asyncio.AbstractEventLoop) -> None:
        batch, self._pending = self._pending, []
        future = loop.run_in_executor(self._executor, self._write, batch)
        future.add_done_callback(lambda f: self._landed(loop, batch, f))

    def _landed(self, loop: asyncio.AbstractEventLoop, batch: list, f: asyncio.Future) -> None:
        self._settle(batch, f.exception())
        if self._pending:
            self._start(loop)
        else:
            self._in_flight = False

    def _commit(self) -> None:
        batch, self._pending = self._pending, []
        try:
            self._write(batch)
        except Exception as exc:
            self._settle(batch, exc)
            return
        self._settle(batch, None)

    def _write(self, batch: list) -> None:
        blobs = [{"job_id": row["id"], "name": "input", "data": data, "bytes": len(data), "created_at": now()}
                 for row, data, _ in batch if data is not None]
        if self._threaded and not blobs and len(batch) <= ONE_STATEMENT_ROWS:  # one statement (see _insert_rows)
            self._insert_rows([row for row, _, _ in batch])
            return
        with self.store.write_lock, self.store.engine.begin() as conn:
            conn.execute(JOBS.insert(), [row for row, _, _ in batch])  # one executemany, Core
            if blobs:
                conn.execute(DATA.insert(), blobs)

    def _insert_rows(self, rows: list[dict]) -> None:
        """Rows (at most :data:`ONE_STATEMENT_ROWS`) stored by one multi-row INSERT (:data:`_MANY_ROWS`) on this
        thread's own connection in autocommit (a statement is atomic: all rows or none): one round trip to the
        database server, where a pooled transaction takes four (the pool's liveness ping, BEGIN, INSERT, COMMIT), each
        a wait for the server's process on a loaded machine. A connection that failed is dropped; the next commit
        opens a new one."""
        from sqlalchemy.exc import DBAPIError

        if self._conn is None:
            self._conn = self.store.engine.connect().execution_options(isolation_level="AUTOCOMMIT")
        try:
            self._conn.execute(_MANY_ROWS, rows)
        except DBAPIError:
            conn, self._conn = self._conn, None
            with contextlib.suppress(Exception):
                conn.invalidate()
                conn.close()
            raise

    def _settle(self, batch: list, exc: BaseException | None) -> None:
        for _, _, done in batch:
            if done.done():
                continue
            if exc is not None:  # every waiting request gets the error
                done.set_exception(exc)
                done.exception()  # (retrieved: no 'never retrieved' warning for a request that went away)
            else:
                done.set_result(None)
        if exc is None:
            self.submitted([row["id"] for row, _, _ in batch])

    def close(self) -> None:
        if self._executor is not None:
            self._executor.shutdown(wait=True)
        if self._conn is not None:
            with contextlib.suppress(Exception):
                self._conn.close()
            self._conn = None
