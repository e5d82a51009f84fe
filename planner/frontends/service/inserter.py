"""New jobs stored by the event loop itself, every row that arrives in one turn of the loop (or while the previous
commit is on its way) committed in one transaction (group commit): a burst of submissions costs one commit, not one
each.

Why in the loop and not in a thread of its own: a thread that takes the interpreter's lock back from the busy event
loop waits for it (up to the switch interval, then for the operating system to run it, each time it has waited for
the database). With SQLite (Python's sqlite3 releases the lock around every statement step) a commit of 20 rows took
7-15 ms in a thread against well under a millisecond in the loop; with PostgreSQL, 2 API replicas and 2 planning
workers on 2 cores, a commit took 12 ms from its rows' arrival to their requests' answer in a thread (1.4 ms to the
thread, 8 ms of writing for 2 ms of CPU, 2 ms back to the loop), and the requests waited 1.5 commits on average.
SQLite (WAL mode, synchronous=NORMAL: no fsync in a commit) blocks the loop for the commit itself only; PostgreSQL is
written through psycopg's asyncio connection (:data:`JOB_INSERT`, pipelined: one round trip), the loop serving other
requests while the server works.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from typing import Any

from sqlalchemy import Table
from sqlalchemy.exc import DBAPIError

from planner.frontends.service.store import Job, JobData, now
from planner.frontends.service.tasks.transitions import Transitions

#: The jobs table itself (inserts without the ORM's per-row bookkeeping).
JOBS: Table = Job.__table__  # type: ignore[assignment]
DATA: Table = JobData.__table__  # type: ignore[assignment]


def _insert_sql(table: Table, columns: list[str], binary: tuple[str, ...] = ()) -> str:
    """``INSERT INTO table (columns) VALUES (%(column)s, ...)``: psycopg's named parameters (``binary``: those sent
    as they are, ``%(column)b``, not escaped as text)."""
    return (f"INSERT INTO {table.name} ({', '.join(columns)}) "
            f"VALUES ({', '.join(f'%({c})' + ('b' if c in binary else 's') for c in columns)})")


#: The columns of a new job's row (:func:`.submit._row`) and of its input file's bytes, as inserted on PostgreSQL
#: (psycopg, not SQLAlchemy: the statement's Python-side work per row was 0.19 ms through SQLAlchemy's executemany,
#: 0.07 ms through psycopg's; a column's Python-side default is filled in by :func:`_with_defaults`).
JOB_COLUMNS = ["id", "owner", "team", "state", "created_at", "stage", "done", "total", "attempts", "job_bytes",
               "input_kind", "input_name", "input_format", "input_bytes", "input_json", "settings", "read_options"]
DATA_COLUMNS = ["job_id", "name", "data", "bytes", "created_at"]
JOB_INSERT = _insert_sql(JOBS, JOB_COLUMNS)
DATA_INSERT = _insert_sql(DATA, DATA_COLUMNS, binary=("data",))  # an upload's bytes: no hex escaping in the loop


def _with_defaults(table: Table, columns: list[str]) -> Callable[[dict], dict]:
    """A function giving a row of ``table`` the scalar Python-side default of each of ``columns`` it lacks (what
    SQLAlchemy's insert fills in; a lacking column without one is psycopg's error at the insert). KeyError at once
    if ``table`` has no such column."""
    defaults = {c.name: c.default.arg for c in table.columns  # type: ignore[attr-defined]
                if c.name in columns and c.default is not None and c.default.is_scalar}
    unknown = set(columns) - {c.name for c in table.columns}
    if unknown:
        raise KeyError(f"{table.name} has no column {sorted(unknown)[0]!r}")
    return lambda row: {**defaults, **row} if len(row) < len(columns) else row


_job_row = _with_defaults(JOBS, JOB_COLUMNS)


def _blobs(batch: list) -> list[dict]:
    """The ``job_data`` rows of a batch's uploaded input files."""
    return [{"job_id": row["id"], "name": "input", "data": data, "bytes": len(data), "created_at": now()}
            for row, data, _ in batch if data is not None]


#: Seconds the first commit (or the first after the database server went away) waits for a connection.
CONNECT_S = 5


class Inserter:
    """Stores job rows (and an uploaded input's bytes) in group commits; ``submitted`` is told the ids committed.

    SQLite (in the process, no network): the commit runs in the event loop after the turn's requests. A database
    server (PostgreSQL): one commit at a time on the loop's own asyncio connection, the loop accepting requests while
    it is on its way; the rows that arrive meanwhile make the next commit."""

    def __init__(self, store: Transitions, submitted: Callable[[list[str]], None]):
        self.store = store
        self.submitted = submitted
        self._pending: list[tuple[dict, bytes | None, asyncio.Future]] = []
        self._server = not store.sqlite
        self._in_flight = False
        self._conn: Any = None  # the loop's own connection to a database server (psycopg.AsyncConnection)

    async def store_job(self, row: dict, data: bytes | None = None) -> None:
        """Store a job row (the columns of :class:`Job`) and its input file's bytes; returns once committed (raises
        what the commit raised as SQLAlchemy's exception, e.g. OperationalError: the database is gone)."""
        loop = asyncio.get_running_loop()
        done = loop.create_future()
        self._pending.append((row, data, done))
        if self._server:
            if not self._in_flight:
                self._in_flight = True
                loop.call_soon(self._start, loop)  # after the turn's other requests
        elif len(self._pending) == 1:  # the first of this turn: the commit runs after the turn's other requests
            loop.call_soon(self._commit)
        await asyncio.shield(done)  # a request cancelled meanwhile (its client went away) is committed all the same

    # -- a database server: one commit on its way at a time; the rows that arrive meanwhile make the next -------------
    def _start(self, loop: asyncio.AbstractEventLoop) -> None:
        batch, self._pending = self._pending, []
        task = loop.create_task(self._write_server(batch))
        task.add_done_callback(lambda t: self._landed(loop, batch, t))

    def _landed(self, loop: asyncio.AbstractEventLoop, batch: list, task: asyncio.Task) -> None:
        self._settle(batch, None if task.cancelled() else task.exception())
        if self._pending:
            self._start(loop)
        else:
            self._in_flight = False

    async def _write_server(self, batch: list) -> None:
        """The batch's rows (and input files) in one transaction, pipelined (BEGIN, the INSERTs, COMMIT: one round
        trip), on this loop's connection; a connection that broke is dropped (the next commit opens one). A failure
        raised as SQLAlchemy's exception of its kind (IntegrityError, OperationalError, ...), as the route's error
        handling and the fast path know them."""
        import psycopg

        jobs = [_job_row(row) for row, _, _ in batch]
        blobs = _blobs(batch)
        try:
            if self._conn is None:
                url = self.store.engine.url.set(drivername="postgresql").render_as_string(hide_password=False)
                self._conn = await psycopg.AsyncConnection.connect(url, autocommit=True, connect_timeout=CONNECT_S)
            conn = self._conn
            async with conn.pipeline(), conn.transaction(), conn.cursor() as cur:
                await cur.executemany(JOB_INSERT, jobs)
                if blobs:
                    await cur.executemany(DATA_INSERT, blobs)
        except psycopg.Error as exc:
            if self._conn is not None and (self._conn.broken or self._conn.closed):
                with contextlib.suppress(Exception):
                    await self._conn.close()
                self._conn = None
            raise DBAPIError.instance(JOB_INSERT, None, exc, psycopg.Error) from exc

    # -- SQLite: the commit in the loop, after the turn's requests ----------------------------------------------------
    def _commit(self) -> None:
        batch, self._pending = self._pending, []
        blobs = _blobs(batch)
        try:
            with self.store.write_lock, self.store.engine.begin() as conn:
                conn.execute(JOBS.insert(), [row for row, _, _ in batch])  # one executemany, Core
                if blobs:
                    conn.execute(DATA.insert(), blobs)
        except Exception as exc:
            self._settle(batch, exc)
            return
        self._settle(batch, None)

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
        """Close the connection to a database server (from any thread, the loop ended or idle)."""
        conn, self._conn = self._conn, None
        if conn is not None:
            with contextlib.suppress(Exception):
                conn.pgconn.finish()
