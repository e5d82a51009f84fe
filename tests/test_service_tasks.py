"""The task layer's transitions on a real SQLite store: a job's end stored once (a second delivery or a stale attempt
changes nothing), recovery by heartbeats, the robot's lease (held, expired and taken over, an execution taken only
once), and the migration to the shared task columns keeping the one-active-execution-per-robot index."""

from __future__ import annotations

import json
import sqlite3
import uuid

import numpy as np
import pytest
from sqlalchemy import select, update

from planner.frontends.service.config import RobotConfig
from planner.frontends.service.store import Execution, Job, JobData, migrate, now, open_store
from planner.frontends.service.tasks.lifecycle import EXECUTION, JOB, Outcome
from planner.frontends.service.tasks.transitions import LEASE_S, RobotBusy, Transitions


@pytest.fixture
def store(tmp_path):
    engine, _ = open_store(f"sqlite:///{tmp_path / 'jobs.sqlite'}")
    yield Transitions(engine, holder="test:1")
    engine.dispose()


def _job(store: Transitions, waypoints: list | None = None) -> str:
    job_id = uuid.uuid4().hex
    waypoints = [[0, 0, 0], [1, 0, 0]] if waypoints is None else waypoints
    with store.engine.begin() as conn:
        conn.execute(Job.__table__.insert(), [dict(
            id=job_id, owner="k", state="queued", created_at=now(), input_kind="waypoints", input_name="<waypoints>",
            input_format="waypoints", input_bytes=10, input_json=json.dumps({"waypoints": waypoints}),
            settings="{}", read_options="{}", stage="", done=0, total=0, attempts=0, job_bytes=0)])
    return job_id


def _plans(store: Transitions, job_id: str) -> list[bytes]:
    with store.engine.connect() as conn:
        return [bytes(r[0]) for r in conn.execute(select(JobData.data).where(JobData.job_id == job_id,
                                                                             JobData.name == "plan"))]


def test_a_job_ends_once_and_a_stale_attempt_stores_nothing(store):
    job_id = _job(store)
    assert store.claim_job(job_id + "0") is None  # no such job
    got = store.claim_job(job_id)
    assert got is not None and got[:2] == (job_id, 1) and got[2].input_kind == "waypoints"
    assert store.claim_job(job_id) is None  # a second delivery of its message: it is running already
    # its worker stops beating: queued again, and the next claim is attempt 2
    assert store.recover(now() + 1, 3, "a test", "tests")["requeued_ids"] == [job_id]
    assert store.claim_job()[:2] == (job_id, 2)
    done = Outcome("done", values={"summary": "{}"}, plan=b"PLAN-1", planning_s=0.5)
    assert store.finish(JOB, job_id, 1, done) is False  # the first attempt, come back to life: refused
    assert _plans(store, job_id) == []
    assert store.finish(JOB, job_id, 2, Outcome("done", plan=b"PLAN-2", planning_s=0.5)) is True
    assert store.finish(JOB, job_id, 2, Outcome("done", plan=b"PLAN-3", planning_s=0.5)) is False  # ran twice
    assert _plans(store, job_id) == [b"PLAN-2"]
    with store.engine.connect() as conn:
        row = conn.execute(select(Job.state, Job.attempts, Job.job_file, Job.job_bytes, Job.note)
                           .where(Job.id == job_id)).one()
    assert tuple(row[:4]) == ("done", 2, "plan.2.job", 6) and "interrupted by a test" in row[4]
    assert store.counts(JOB) == {"queued": 0, "running": 0, "done": 1, "failed": 0, "cancelled": 0}
    assert store.cancel_job(job_id) is None  # ended


def test_recovery_fails_a_job_after_max_attempts_and_spares_live_holders(store):
    live, dead = _job(store), _job(store)
    store.claim_job(live)
    store.claim_job(dead)
    assert not store.any_stale(now() - LEASE_S)  # (the keeper's read: nothing to recover, nothing written)
    with store.engine.begin() as conn:
        conn.execute(update(Job).where(Job.id == dead).values(heartbeat_at=now() - 2 * LEASE_S))
    assert store.any_stale(now() - LEASE_S)
    got = store.recover(now() - LEASE_S, 1, "a test", "tests")
    assert got["requeued_ids"] == [] and got["failed"] == 1
    assert store.state(JOB, dead) == "failed" and store.state(JOB, live) == "running"
    assert not store.any_stale(now() - LEASE_S)


def _execution(robot: str = "cell") -> dict:
    return dict(id=uuid.uuid4().hex, job_id="0" * 32, owner="k", robot=robot, mode="stream", state="starting",
                created_at=now(), stage="starting", done=0, total=0)


def test_the_robot_lease_is_held_expires_and_is_taken_over(store):
    with store.engine.begin() as conn:
        conn.execute(JobData.__table__.insert(), [dict(job_id="0" * 32, name="plan", data=b"P", bytes=1,
                                                       created_at=now())])
    first = _execution()
    store.create_execution(first)
    with pytest.raises(RobotBusy):
        store.create_execution(_execution())
    store.create_execution(_execution("other"))  # another robot is free
    robots = (RobotConfig("cell", "127.0.0.9", "ur5e"),)
    got = store.claim_execution(first["id"], robots)
    assert got is not None and got[2].robot["host"] == "127.0.0.9" and got[2].plan == b"P"
    assert store.claim_execution(first["id"], robots) is None  # an execution is taken once, ever
    with store.engine.begin() as conn:  # its holder stops beating
        conn.execute(update(Execution).where(Execution.id == first["id"]).values(heartbeat_at=now() - LEASE_S - 1))
    assert store.any_stale(now() - LEASE_S)
    second = _execution()
    store.create_execution(second)  # the expired lease is taken over
    assert store.state(EXECUTION, first["id"]) == "failed"
    assert store.finish(EXECUTION, first["id"], 1, Outcome("done")) is False  # the old holder cannot end it now
    unknown = _execution("nowhere")
    store.create_execution(unknown)
    assert store.claim_execution(unknown["id"], robots) is None  # not configured in this worker: failed, with why
    with store.engine.connect() as conn:
        error = conn.scalar(select(Execution.error).where(Execution.id == unknown["id"]))
    assert error == "no robot named 'nowhere' in the configuration of the worker test:1"


def test_the_migration_to_the_task_columns_keeps_one_active_execution_per_robot(tmp_path):
    from alembic import command
    from alembic.config import Config

    from planner.frontends.service.store import make_engine

    url = f"sqlite:///{tmp_path / 'old.sqlite'}"
    engine = make_engine(url)
    cfg = Config()
    from pathlib import Path

    import planner.frontends.service.store as store_module

    cfg.set_main_option("script_location", str(Path(store_module.__file__).resolve().parent / "migrations"))
    with engine.begin() as conn:
        cfg.attributes["connection"] = conn
        command.upgrade(cfg, "0002")
    with sqlite3.connect(tmp_path / "old.sqlite") as db:
        db.execute("insert into executions (id, job_id, owner, robot, mode, state, created_at, stage, done, total) "
                   "values ('e1', 'j', 'k', 'cell', 'stream', 'running', 1.0, '', 0, 0)")
    migrate(engine)
    with sqlite3.connect(tmp_path / "old.sqlite") as db:
        assert db.execute("select attempts, holder from executions where id = 'e1'").fetchone() == (0, None)
        with pytest.raises(sqlite3.IntegrityError):
            db.execute("insert into executions (id, job_id, owner, robot, mode, state, created_at, stage, done, "
                       "total, attempts) values ('e2', 'j', 'k', 'cell', 'stream', 'starting', 1.0, '', 0, 0, 0)")
    engine.dispose()


def test_files_of_jobs_stored_before_the_move_into_the_database_are_imported_once(tmp_path):
    from planner import plan
    from planner.frontends.service.store import import_legacy_files

    engine, _ = open_store(f"sqlite:///{tmp_path / 'jobs.sqlite'}")
    store = Transitions(engine)
    job_id = _job(store)
    blob = plan([[0, 0, 0], [0.1, 0.02, 0], [0.2, 0, 0]]).to_bytes()
    with engine.begin() as conn:
        conn.execute(update(Job).where(Job.id == job_id).values(
            state="done", attempts=1, job_file="plan.1.job", input_kind="file", input_name="a.csv"))
    folder = tmp_path / "data" / "jobs" / job_id
    (folder / "input").mkdir(parents=True)
    (folder / "input" / "a.csv").write_bytes(b"0,0,0\n1,0,0\n")
    (folder / "plan.1.job").write_bytes(blob)
    assert import_legacy_files(engine, tmp_path / "data") == 2
    assert import_legacy_files(engine, tmp_path / "data") == 0  # once
    assert _plans(store, job_id) == [blob]
    assert (folder / "plan.1.job").read_bytes() == blob  # the files left where they are
    engine.dispose()


def test_a_large_jobs_view_data_are_made_after_its_end_is_stored(store):
    """A job of more than VIEW_AT_PLAN_POSES poses (0.42 m at 0.2 mm/s: 2086 s, 1.04 million poses) planned by a real
    worker process: its end (plan, summary) is stored first, its exports waiting for nothing, and the worker then
    makes its 3D view data and the runner stores them under its id, readable by the view."""
    import threading

    from planner.frontends.service.tasks.functions import VIEW_AT_PLAN_POSES
    from planner.frontends.service.tasks.runner import Slot
    from planner.frontends.service.view_data import ViewPath

    job_id = uuid.uuid4().hex
    with store.engine.begin() as conn:
        conn.execute(Job.__table__.insert(), [dict(
            id=job_id, owner="k", state="queued", created_at=now(), input_kind="waypoints", input_name="<waypoints>",
            input_format="waypoints", input_bytes=10, settings=json.dumps({"feed": 0.0002}), read_options="{}",
            input_json=json.dumps({"waypoints": [[0, 0, 0], [0.2, 0.05, 0], [0.4, 0, 0.02]]}),
            stage="", done=0, total=0, attempts=0, job_bytes=0)])
    slot = Slot(store, 300.0, threading.Event())
    slot.start_process()
    try:
        slot.run(JOB, *store.claim_job(job_id))
    finally:
        slot.stop_process()
    with store.engine.connect() as conn:
        state, finished, summary = conn.execute(select(Job.state, Job.finished_at, Job.summary)
                                                .where(Job.id == job_id)).one()
        data = {r.name: (r.created_at, bytes(r.data)) for r in conn.execute(
            select(JobData.name, JobData.created_at, JobData.data).where(JobData.job_id == job_id))}
    assert state == "done" and json.loads(summary)["duration_s"] * 500 > VIEW_AT_PLAN_POSES
    assert sorted(data) == ["plan", "view"]
    assert data["view"][0] > finished  # stored after the job's end
    fine = ViewPath.from_bytes(data["view"][1])
    assert fine.t[0] == 0.0 and fine.t[-1] == pytest.approx(json.loads(summary)["duration_s"], abs=0.01)
    assert 2 < fine.t.size < 10_000  # a smooth path thinned within 10 um


def test_a_cancelled_jobs_runner_does_not_wait_for_the_fresh_process(store):
    """A job cancelled while it plans: the runner returns as soon as the process is killed, a fresh process importing
    meanwhile, which the next job waits for and runs in."""
    import threading
    import time

    from planner.frontends.service.tasks.runner import Slot

    t = np.linspace(0.0, 60.0 * np.pi, 20_000)  # seconds of planning
    job_id = _job(store, np.c_[0.1 * np.cos(t), 0.1 * np.sin(t), 1e-4 * t].round(7).tolist())
    slot = Slot(store, 300.0, threading.Event())
    slot.start_process()
    try:
        first = slot.process.pid
        runner = threading.Thread(target=slot.run, args=(JOB, *store.claim_job(job_id)))
        runner.start()
        time.sleep(1.0)
        assert runner.is_alive()  # still planning
        assert store.cancel_job(job_id) == "running"
        runner.join(30.0)
        assert not runner.is_alive()
        assert slot.process.pid != first and slot.process.is_alive() and not slot.ready  # started, not waited for
        job_id = _job(store)
        slot.run(JOB, *store.claim_job(job_id))
        assert store.state(JOB, job_id) == "done" and len(_plans(store, job_id)) == 1
    finally:
        slot.stop_process()
