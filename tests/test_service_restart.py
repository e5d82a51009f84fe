"""A service killed (SIGKILL) or stopped (SIGTERM) mid-job and started again on the same database: nothing is
lost, nothing runs twice to completion, a job interrupted too often fails with the reason."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np

from tests.test_service_server import ServiceProcess, wait_state, wait_until

SMALL = {"waypoints": [[0, 0, 0], [0.1, 0.03, 0], [0.2, 0, 0.01]]}


def big() -> dict:
    t = np.linspace(0, 200 * np.pi, 15_000)  # a few seconds of planning
    return {"waypoints": np.c_[0.1 * np.cos(t) + 1e-4 * t, 0.1 * np.sin(t), 2e-4 * t].tolist()}


def gone(pid: int) -> bool:
    stat = Path(f"/proc/{pid}/stat")
    try:
        return stat.read_text().split()[2] in ("Z", "X")
    except OSError:
        return True


def saved_files(folder: Path, job_id: str) -> list[str]:
    """The saved plans of a job in the store (the attempt that completed it, by name), and that no plan lies in the
    service's folder."""
    assert not list(folder.rglob("*.job"))
    with sqlite3.connect(folder / "jobs.sqlite") as conn:
        return [name for (name,) in conn.execute(
            "select jobs.job_file from jobs join job_data on job_data.job_id = jobs.id and job_data.name = 'plan' "
            "where jobs.id = ?", (job_id,))]


def test_kill_and_restart_loses_nothing_and_runs_nothing_twice(tmp_path):
    s1 = ServiceProcess(tmp_path, workers=1).start()
    try:
        with s1.client() as c:
            a = c.post("/v1/jobs", json=big()).json()["id"]
            b = c.post("/v1/jobs", json=SMALL).json()["id"]
            wait_state(c, a, states=("running",), timeout=60)
            workers = s1.worker_pids()
    finally:
        s1.kill()
    wait_until(lambda: all(gone(p) for p in workers), 2.0, "the workers die with the killed service")

    s2 = ServiceProcess(tmp_path, workers=1).start()
    try:
        with s2.client() as c:
            va, vb = wait_state(c, a), wait_state(c, b)
            assert va["state"] == vb["state"] == "done", (va["error"], vb["error"])
            assert va["attempts"] == 2 and "restart" in va["note"]
            assert vb["attempts"] == 1 and vb["note"] is None
            assert saved_files(tmp_path, a) == ["plan.2.job"] and saved_files(tmp_path, b) == ["plan.1.job"]
            assert c.get(f"/v1/jobs/{a}/trajectory").status_code == 200
            metrics = c.get("/metrics").text
            assert 'planner_jobs_finished_total{state="done"} 2' in metrics  # each completed once, here
            d = c.post("/v1/jobs", json=big()).json()["id"]
            wait_state(c, d, states=("running",), timeout=60)
    finally:
        s2.kill()

    s3 = ServiceProcess(tmp_path, workers=1, env={"PLANNER_MAX_ATTEMPTS": "1"}).start()
    try:
        with s3.client() as c:
            vd = c.get(f"/v1/jobs/{d}").json()
            assert vd["state"] == "failed" and vd["error"]["kind"] == "interrupted"
            assert "interrupted by restarts of the service 1 times while running" in vd["error"]["message"]
            e = c.post("/v1/jobs", json=big()).json()["id"]
            wait_state(c, e, states=("running",), timeout=60)
            workers = s3.worker_pids()
    finally:
        assert s3.stop() == 0  # graceful: the running job goes back to the queue, its start not counted
    assert all(gone(p) for p in workers)

    s4 = ServiceProcess(tmp_path, workers=1).start()
    try:
        with s4.client() as c:
            ve = wait_state(c, e)
            assert ve["state"] == "done" and ve["attempts"] == 1
            jobs = c.get("/v1/jobs").json()["jobs"]
    finally:
        assert s4.stop() == 0
    assert sorted(j["id"] for j in jobs) == sorted([a, b, d, e])
    with sqlite3.connect(tmp_path / "jobs.sqlite") as conn:
        states = dict(conn.execute("select id, state from jobs").fetchall())
    assert states == {a: "done", b: "done", d: "failed", e: "done"}


def test_sigterm_while_jobs_plan_requeues_them_and_each_runs_once_after_restart(tmp_path):
    s1 = ServiceProcess(tmp_path, workers=2).start()
    try:
        with s1.client() as c:
            planning = [c.post("/v1/jobs", json=big()).json()["id"] for _ in range(2)]
            queued = [c.post("/v1/jobs", json=SMALL).json()["id"] for _ in range(3)]
            for j in planning:
                wait_state(c, j, states=("running",), timeout=60)
            assert [c.get(f"/v1/jobs/{j}").json()["state"] for j in queued] == ["queued"] * 3
            workers = s1.worker_pids()
            assert len(workers) == 2
    finally:
        assert s1.stop() == 0  # graceful
    assert all(gone(p) for p in workers)
    with sqlite3.connect(tmp_path / "jobs.sqlite") as conn:
        rows = {j: (state, attempts, started) for j, state, attempts, started in
                conn.execute("select id, state, attempts, started_at from jobs")}
    # back in the queue as they were: no start counted, no saved plan left behind
    assert {j: r[:2] for j, r in rows.items()} == {j: ("queued", 0) for j in planning + queued}
    assert all(saved_files(tmp_path, j) == [] for j in planning + queued)

    s2 = ServiceProcess(tmp_path, workers=2).start()
    try:
        with s2.client() as c:
            views = {j: wait_state(c, j) for j in planning + queued}
            metrics = c.get("/metrics").text
    finally:
        assert s2.stop() == 0
    assert all(v["state"] == "done" and v["attempts"] == 1 for v in views.values()), views
    assert all(saved_files(tmp_path, j) == ["plan.1.job"] for j in views)  # each planned to its end once
    assert all(views[j]["started_at"] > rows[j][2] for j in planning)  # started again, after the restart
    assert 'planner_jobs_finished_total{state="done"} 5' in metrics
    with sqlite3.connect(tmp_path / "jobs.sqlite") as conn:
        assert conn.execute("select count(*), count(distinct id) from jobs").fetchone() == (5, 5)
