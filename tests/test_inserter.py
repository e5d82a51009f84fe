"""The group commit of new job rows on PostgreSQL (:class:`planner.frontends.service.inserter.Inserter`): a burst of
submissions stored by one statement, or by one transaction above the statement's row limit; all of a batch's rows
stored or none, and every request of a failed batch told (a real PostgreSQL server on loopback)."""

from __future__ import annotations

import asyncio

import pytest
from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError

from planner.frontends.service.inserter import ONE_STATEMENT_ROWS, Inserter
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


@pytest.mark.parametrize("n", [3, ONE_STATEMENT_ROWS, ONE_STATEMENT_ROWS + 1])
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
    finally:
        inserter.close()
        engine.dispose()
