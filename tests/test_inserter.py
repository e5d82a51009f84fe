"""The group commit of new job rows on PostgreSQL (:class:`planner.frontends.service.inserter.Inserter`, the event
loop's own asyncio connection): a burst of submissions stored by one transaction; all of a batch's rows stored or
none, every request of a failed batch told, with SQLAlchemy's exception of its kind; the rows as SQLAlchemy's insert
stores them (a real PostgreSQL server on loopback)."""

from __future__ import annotations

import asyncio

import pytest
from sqlalchemy import func, select, text
from sqlalchemy.exc import IntegrityError, OperationalError

from planner.frontends.service.inserter import Inserter
from planner.frontends.service.store import Job, now, open_store
from planner.frontends.service.tasks.transitions import Transitions
from tests import pg_server

postgres, pg_url = pg_server.postgres, pg_server.pg_url  # fixtures


def _row(k: int) -> dict:
    return dict(id=f"job{k:06d}", owner="k", team="t", state="queued", created_at=now(), stage="", done=0, total=0,
                attempts=0, job_bytes=0, input_kind="waypoints", input_name="<waypoints>", input_format="waypoints",
                input_bytes=2, input_json="{}", settings="{}", read_options="{}")


async def _burst(inserter: Inserter, rows: list[dict]) -> list:
    """The rows submitted in one turn of the event loop (one batch): each request's outcome."""
    return await asyncio.gather(*(inserter.store_job(r) for r in rows), return_exceptions=True)


@pytest.mark.parametrize("n", [3, 1000, 2500])
def test_a_burst_is_stored_whole_and_a_bad_row_stores_none_of_its_batch(pg_url, n):
    engine, _ = open_store(pg_url)
    told: list[str] = []
    inserter = Inserter(Transitions(engine), told.extend)
    try:
        rows = [_row(k) for k in range(n)]
        assert asyncio.run(_burst(inserter, rows)) == [None] * n
        assert sorted(told) == sorted(r["id"] for r in rows)  # the backend told every id once
        # a batch with a row whose id is taken: none of its rows stored, every request gets the error
        again = [_row(k) for k in range(n, 2 * n - 1)] + [_row(0)]
        outcomes = asyncio.run(_burst(inserter, again))
        assert all(isinstance(o, IntegrityError) for o in outcomes), outcomes[:3]
        with engine.connect() as conn:
            assert conn.scalar(select(func.count()).select_from(Job)) == n
        assert len(told) == n
        # the same connection stores the next batch
        assert asyncio.run(_burst(inserter, [_row(k) for k in range(2 * n, 2 * n + 3)])) == [None] * 3
        assert len(told) == n + 3
    finally:
        inserter.close()
        engine.dispose()


def test_a_row_is_stored_as_sqlalchemys_insert_stores_it(pg_url):
    """Python-side column defaults filled in (a row without ``read_options`` gets "{}"), floats and text unchanged,
    an uploaded file's bytes stored with its row; the connection opened again after the server dropped it."""
    from planner.frontends.service.store import JobData

    engine, _ = open_store(pg_url)
    inserter = Inserter(Transitions(engine), lambda ids: None)
    try:
        bare = _row(1)
        del bare["read_options"], bare["stage"]
        created = bare["created_at"]

        async def run() -> None:
            await inserter.store_job(bare)
            await inserter.store_job(_row(2), b"GOTO/1,2,3\n")
            with engine.connect() as other:  # the server ends the inserter's connection: the next commit fails
                other.execute(text(f"SELECT pg_terminate_backend({inserter._conn.info.backend_pid})"))
            with pytest.raises(OperationalError):
                await inserter.store_job(_row(9))
            await inserter.store_job(_row(3))  # on a new connection

        asyncio.run(run())
        with engine.connect() as conn:
            job = conn.execute(select(Job).where(Job.id == "job000001")).one()
            assert (job.read_options, job.stage, job.created_at, job.input_json) == ("{}", "", created, "{}")
            assert conn.scalar(select(JobData.data).where(JobData.job_id == "job000002")) == b"GOTO/1,2,3\n"
            assert conn.scalar(select(func.count()).select_from(Job)) == 3
    finally:
        inserter.close()
        engine.dispose()
