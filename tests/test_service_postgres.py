"""The job store on a real PostgreSQL server (tests/pg_server.py: initdb + pg_ctl in a temporary folder, psycopg 3):
the migrations, the one-active-execution-per-robot index, and the whole service on it (keys, concurrent jobs in two
workers none lost or run twice, exports equal to the CLI's bytes, cancel, a SIGKILL and restart, an execution)."""

from __future__ import annotations

import concurrent.futures
import json
import time
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import inspect, select, text
from sqlalchemy.exc import IntegrityError

from planner.frontends.service.store import Execution, Job, migrate, now, open_store
from planner.wording import pose_option
from tests import pg_server
from tests.test_service_server import ServiceProcess, wait_state

postgres = pg_server.postgres  # fixtures
pg_url = pg_server.pg_url

ROOT = Path(__file__).resolve().parents[1]
CLSF = ROOT / "examples" / "nx_first_pass.cls"
PART = [0.4, 0.9965, -0.1, 0.0, 0.0, 0.0]


def _execution(robot: str, state: str) -> Execution:
    import uuid

    return Execution(id=uuid.uuid4().hex, job_id="0" * 32, owner="k", robot=robot, mode="stream", state=state,
                     created_at=now(), stage="", done=0, total=0)


def test_migrations_and_the_one_active_execution_per_robot_index(pg_url):
    engine, sessions = open_store(pg_url)
    try:
        assert engine.dialect.name == "postgresql"
        migrate(engine)  # again: nothing to do
        with engine.connect() as conn:
            assert conn.execute(text("SELECT version_num FROM alembic_version")).scalar() == "0005"
        names = set(inspect(engine).get_table_names())
        assert {"jobs", "api_keys", "executions", "job_data", "workers", "job_chunks"} <= names
        with sessions() as s:
            s.add_all([_execution("a", "running"), _execution("b", "starting"), _execution("a", "done"),
                       _execution("a", "failed")])
            s.commit()
        for state in ("starting", "running", "stopping"):
            with sessions() as s:
                s.add(_execution("a", state))
                with pytest.raises(IntegrityError):
                    s.commit()
        with sessions() as s:  # once the robot's execution has ended, the robot takes a new one
            s.execute(text("UPDATE executions SET state = 'cancelled' WHERE robot = 'a' AND state = 'running'"))
            s.add(_execution("a", "starting"))
            s.commit()
            assert s.scalar(select(Execution.state).where(Execution.robot == "a",
                                                          Execution.state == "starting")) == "starting"
        with sessions() as s:  # autoincrement order of jobs (the list's newest first)
            for i in range(3):
                s.add(Job(id=f"{i:032x}", owner="k", state="queued", created_at=now(), input_kind="waypoints",
                          input_name="<waypoints>", input_format="waypoints", input_bytes=0, settings="{}",
                          read_options="{}", stage="", done=0, total=0, attempts=0, job_bytes=0))
                s.commit()
            seqs = list(s.scalars(select(Job.seq).order_by(Job.id)))
        assert seqs == sorted(seqs) and len(set(seqs)) == 3
    finally:
        engine.dispose()




def test_the_service_on_postgresql(postgres, tmp_path):
    url = postgres.create_database()
    robots = json.dumps({"sim": {"sim": True, "sim_speed": 10, "approach_speed": 2.0, "approach_acceleration": 3.0}})
    s = ServiceProcess(tmp_path, workers=2, dev=False, env={"PLANNER_DB": url, "PLANNER_ROBOTS": robots,
                                                            "PLANNER_DATA": str(tmp_path / "data")})
    s.db = url  # `planner keys --db` on the same database
    s.start()
    try:
        s.teams("create", "b")
        a, b = s.key("cam a", "operator"), s.key("cam b", "planner", "b")
        with s.client(a) as ca, s.client(b) as cb:
            rng = np.random.default_rng(7)
            bodies = [{"waypoints": np.cumsum(rng.uniform(0.01, 0.05, (12, 3)), axis=0).round(6).tolist()}
                      for _ in range(24)]
            with concurrent.futures.ThreadPoolExecutor(8) as ex:
                answers = list(ex.map(lambda body: ca.post("/v1/jobs", json=body), bodies))
            assert all(r.status_code == 202 for r in answers)
            ids = [r.json()["id"] for r in answers]
            views = [wait_state(ca, i) for i in ids]
            assert all(v["state"] == "done" and v["attempts"] == 1 for v in views), [v["error"] for v in views]
            # the list: all of them, newest first, in pages; none of them for another team
            listed, cursor = [], None
            while True:
                page = ca.get("/v1/jobs", params={"limit": 10, **({"cursor": cursor} if cursor else {})}).json()
                listed += [j["id"] for j in page["jobs"]]
                cursor = page["next_cursor"]
                if cursor is None:
                    break
            assert sorted(listed) == sorted(ids)  # concurrent submits: listed in the order they were committed
            assert len(listed) == len(set(listed)) == 24
            assert cb.get("/v1/jobs").json()["jobs"] == [] and cb.get(f"/v1/jobs/{ids[0]}").status_code == 404
            # a file job: the exports are the CLI's bytes
            settings = {"robot": "ur5e", "part_frame": PART, "cut_output": ["standard", 0], "feed_override": 4.0}
            with open(CLSF, "rb") as f:
                r = ca.post("/v1/jobs", files={"file": (CLSF.name, f)}, data={"settings": json.dumps(settings)})
            job = wait_state(ca, r.json()["id"])
            assert job["state"] == "done", job["error"]
            from planner.frontends.cli.main import main as cli_main

            out = tmp_path / "cli.csv"
            assert cli_main(["plan", str(CLSF), "--robot", "ur5e", "--part-frame", pose_option(PART),
                             "--cut-output", "standard:0", "--feed-override", "4", "-o", str(out)]) == 0
            assert ca.get(f"/v1/jobs/{job['id']}/trajectory?format=csv").content == out.read_bytes()
            # an execution stored in PostgreSQL, one per robot
            e = ca.post(f"/v1/jobs/{job['id']}/executions", json={"robot": "sim", "mode": "program"})
            assert e.status_code == 202, e.text
            assert ca.post(f"/v1/jobs/{job['id']}/executions", json={"robot": "sim"}).status_code == 409
            # cancel a running job, then kill the service with a job running: after the restart it is run again
            t = np.linspace(0, 200 * np.pi, 15_000)
            spiral = {"waypoints": np.c_[0.1 * np.cos(t) + 1e-4 * t, 0.1 * np.sin(t), 2e-4 * t].round(7).tolist()}
            c1 = ca.post("/v1/jobs", json=spiral).json()["id"]
            wait_state(ca, c1, states=("running",), timeout=60)
            assert ca.delete(f"/v1/jobs/{c1}").json()["state"] == "cancelled"
            run = e.json()["id"]
            while ca.get(f"/v1/executions/{run}").json()["state"] in ("starting", "running", "stopping"):
                time.sleep(0.1)
            ended = ca.get(f"/v1/executions/{run}").json()
            assert ended["state"] == "done" and ended["report"]["ok"], ended
            k1 = ca.post("/v1/jobs", json=spiral).json()["id"]
            wait_state(ca, k1, states=("running",), timeout=60)
        s.kill()
        s.start()
        with s.client(a) as ca:
            again = wait_state(ca, k1, timeout=120)
            assert again["state"] == "done" and again["attempts"] == 2 and "restart" in again["note"]
            assert ca.get(f"/v1/jobs/{c1}").json()["state"] == "cancelled"
            assert ca.get(f"/v1/executions/{run}").json()["report"]["ok"] is True
            metrics = ca.get("/metrics").text
            assert 'planner_jobs{state="done"} 26' in metrics and 'planner_jobs{state="cancelled"} 1' in metrics
    finally:
        s.stop()
