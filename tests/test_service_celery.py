"""The celery backend under faults, on real servers started for the session (PostgreSQL, Redis) and real
``planner worker`` processes: a worker SIGKILLed mid-plan (the job completes once) and mid-execution (the execution
reported interrupted, the robot's lease freed, never run again), Redis restarted mid-run (no job lost), PostgreSQL
restarted (503 with the reason meanwhile, then recovered), two API replicas (executions of one robot never overlap,
a job cancelled through the other replica stops in another process within a second, /metrics counts the
cluster)."""

from __future__ import annotations

import concurrent.futures
import contextlib
import json
import os
import time
from pathlib import Path

import numpy as np

from planner.frontends.service.tasks.functions import VIEW_AT_PLAN_POSES, plain
from planner.frontends.service.tasks.transitions import LEASE_S
from tests import pg_server, redis_server
from tests.celery_cluster import CeleryService, fresh_broker, fresh_database, wait_for
from tests.sim_fixtures import start_sim
from tests.test_service_server import wait_state

postgres, redis = pg_server.postgres, redis_server.redis  # fixtures

DEMO = Path(__file__).resolve().parents[1] / "examples" / "nx_first_pass.cls"
PART = [0.4, 0.9965, -0.1, 0.0, 0.0, 0.0]
SETTINGS = {"robot": "ur5e", "part_frame": PART, "cut_output": ["standard", 0], "feed_override": 4.0}
FAST = {"approach_speed": 2.0, "approach_acceleration": 3.0}
ENDED = ("done", "failed", "cancelled")
SMALL = {"waypoints": [[0, 0, 0], [0.1, 0.03, 0], [0.2, 0, 0.01]]}


def spiral(n: int = 15_000) -> dict:
    t = np.linspace(0, 200 * np.pi, n)  # a few seconds of planning
    return {"waypoints": np.c_[0.1 * np.cos(t) + 1e-4 * t, 0.1 * np.sin(t), 2e-4 * t].round(7).tolist()}


def small(i: int) -> dict:
    rng = np.random.default_rng(i)
    return {"waypoints": np.cumsum(rng.uniform(0.01, 0.05, (8, 3)), axis=0).round(6).tolist()}


def holder_pid(server: CeleryService, table: str, task_id: str) -> int:
    (holder,), = server.sql(f"select holder from {table} where id = :id", id=task_id)
    return int(holder.rsplit(":", 1)[1])


def wait_execution(client, execution_id: str, states=ENDED, timeout: float = 120.0) -> dict:
    deadline = time.monotonic() + timeout
    while True:
        view = client.get(f"/v1/executions/{execution_id}").json()
        if view["state"] in states:
            return view
        if time.monotonic() > deadline:
            raise AssertionError(f"execution {execution_id} still {view['state']} after {timeout} s: {view}")
        time.sleep(0.05)


def metric(text: str, name: str) -> float:
    for line in text.splitlines():
        if line.startswith(name + " "):
            return float(line.split()[-1])
    raise AssertionError(f"{name} not in /metrics")


def test_a_worker_killed_mid_plan_the_job_completes_once(postgres, redis, tmp_path):
    s = CeleryService(tmp_path, db=fresh_database(postgres), broker=fresh_broker(redis), workers=2).start()
    try:
        with s.client() as c:
            big = c.post("/v1/jobs", json=spiral()).json()["id"]
            wait_state(c, big, states=("running",), timeout=60)
            others = [c.post("/v1/jobs", json=small(i)).json()["id"] for i in range(6)]
            victim = next(w for w in s.pool if w.proc.pid == holder_pid(s, "jobs", big))
            time.sleep(0.5)
            victim.kill()
            tic = time.monotonic()
            view = wait_state(c, big, timeout=LEASE_S + 90)
            took = time.monotonic() - tic
            views = [wait_state(c, j, timeout=60) for j in others]
            assert view["state"] == "done" and view["attempts"] == 2, view
            assert "worker stopping to answer" in view["note"]
            assert took > LEASE_S - 1  # re-queued once its heartbeats had stopped, not earlier
            assert all(v["state"] == "done" and v["attempts"] == 1 for v in views)
            # a second delivery of its message (as the broker gives back an unacknowledged one): nothing runs again
            from planner.frontends.service.config import ServiceConfig
            from planner.frontends.service.tasks.celery_backend import make_celery

            app = make_celery(ServiceConfig.from_env({"PLANNER_QUEUE": "celery", "PLANNER_BROKER": s.broker}))
            app.send_task("planner.plan_job", args=[big])
            time.sleep(2.0)
            again = c.get(f"/v1/jobs/{big}").json()
            assert (again["state"], again["attempts"], again["finished_at"]) == ("done", 2, view["finished_at"])
            assert s.sql("select count(*) from job_data where job_id = :id and name = 'plan'", id=big) == [(1,)]
            m = c.get("/metrics").text
            assert 'planner_jobs{state="done"} 7' in m
    finally:
        assert s.stop() == 0, s.log.read_text()


def test_a_worker_killed_mid_execution_is_interrupted_frees_the_robot_and_never_runs_again(postgres, redis, tmp_path):
    cell = start_sim(model="ur5e")
    try:
        robots = json.dumps({"cell": {"host": cell.host, "model": "ur5e", **FAST}})
        s = CeleryService(tmp_path, db=fresh_database(postgres), broker=fresh_broker(redis), workers=1,
                          env={"PLANNER_ROBOTS": robots}).start()
        try:
            with s.client() as c:
                with open(DEMO, "rb") as f:
                    r = c.post("/v1/jobs", files={"file": ("nx_first_pass.cls", f)},
                               data={"settings": json.dumps(SETTINGS)})
                job = wait_state(c, r.json()["id"])
                assert job["state"] == "done", job["error"]
                eid = c.post(f"/v1/jobs/{job['id']}/executions", json={"robot": "cell", "mode": "stream"}).json()["id"]
                assert wait_execution(c, eid, states=("running",) + ENDED, timeout=60)["state"] == "running"
                assert len(s.children("planner-exec")) == 1
                s.pool[0].kill()
                view = wait_execution(c, eid, timeout=LEASE_S + 30)
                assert view["state"] == "failed" and view["error"]["kind"] == "interrupted", view
                assert "not started again" in view["error"]["reason"]
                assert c.get("/v1/robots").json()["robots"][0]["busy"] is False  # the lease freed
                s.pool[0].start()
                wait_for(lambda: c.get("/healthz").json()["workers"] == 1, 60, "a worker again")
                from planner.frontends.service.config import ServiceConfig
                from planner.frontends.service.tasks.celery_backend import make_celery

                app = make_celery(ServiceConfig.from_env({"PLANNER_QUEUE": "celery", "PLANNER_BROKER": s.broker}))
                app.send_task("planner.execute_job", args=[eid])  # delivered again: never run again on the robot
                time.sleep(2.0)
                assert c.get(f"/v1/executions/{eid}").json()["state"] == "failed"
                assert s.sql("select attempts from executions where id = :id", id=eid) == [(1,)]
                again = c.post(f"/v1/jobs/{job['id']}/executions", json={"robot": "cell", "mode": "program"})
                assert again.status_code == 202, again.text
                done = wait_execution(c, again.json()["id"])
                assert done["state"] == "done" and done["report"]["ok"], done
        finally:
            assert s.stop() == 0, s.log.read_text()
    finally:
        cell.stop()


def test_redis_restarted_mid_run_loses_no_job(postgres, tmp_path):
    broker = redis_server.RedisServer().start()  # its own: restarted here
    try:
        s = CeleryService(tmp_path, db=fresh_database(postgres), broker=broker.url, workers=1).start()
        try:
            with s.client() as c:
                before = [c.post("/v1/jobs", json=small(i)).json()["id"] for i in range(20)]
                broker.shutdown()
                during = [c.post("/v1/jobs", json=small(100 + i)) for i in range(5)]  # stored; sent later
                assert all(r.status_code == 202 for r in during), [r.text for r in during]
                time.sleep(1.0)
                broker.start()
                after = [c.post("/v1/jobs", json=small(200 + i)).json()["id"] for i in range(5)]
                ids = before + [r.json()["id"] for r in during] + after
                views = [wait_state(c, j, timeout=120) for j in ids]
            assert all(v["state"] == "done" for v in views), [(v["state"], v["error"]) for v in views]
            assert s.sql("select count(*), count(distinct job_id) from job_data where name = 'plan'") == [(30, 30)]
            assert max(v["attempts"] for v in views) <= 2
        finally:
            assert s.stop() == 0, s.log.read_text()
    finally:
        broker.stop()


def test_postgresql_restarted_the_api_answers_503_with_the_reason_and_recovers(redis, tmp_path):
    pg = pg_server.PostgresServer().start()  # its own: restarted here
    try:
        s = CeleryService(tmp_path, db=fresh_database(pg), broker=fresh_broker(redis), workers=1).start()
        try:
            with s.client() as c:
                first = c.post("/v1/jobs", json=small(1)).json()["id"]
                assert wait_state(c, first)["state"] == "done"
                pg.pause()
                r = c.get(f"/v1/jobs/{first}")
                assert r.status_code == 503 and "the job store (database) does not answer" in r.json()["detail"]
                assert "\n" not in r.json()["detail"] and r.headers["retry-after"]
                r = c.post("/v1/jobs", json=small(2))
                assert r.status_code == 503, r.text
                pg.resume()
                wait_for(lambda: c.get(f"/v1/jobs/{first}").status_code == 200, 30, "the API answers again")
                second = c.post("/v1/jobs", json=small(3))
                assert second.status_code == 202, second.text
                assert wait_state(c, second.json()["id"], timeout=90)["state"] == "done"
        finally:
            assert s.stop() == 0, s.log.read_text()
    finally:
        pg.stop()


def wait_ended(pids, timeout: float, what: str) -> None:
    """Wait until every process of ``pids`` has ended (gone, or a zombie): AssertionError naming ``what`` if not."""
    wait_for(lambda: all(not Path(f"/proc/{p}").exists() or Path(f"/proc/{p}/stat").read_text().split()[2] in "ZX"
                         for p in pids), timeout, what)


def wait_idle(worker, name: str, timeout: float, what: str) -> None:
    """Wait until ``worker`` has a child process ``name`` that has used no CPU for a second (its imports done)."""
    def ticks(pid: int) -> int:
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            return -1
        return int(fields[11]) + int(fields[12])  # utime + stime, clock ticks

    def idle() -> bool:
        pids = worker.children(name)
        if not pids:
            return False
        before = ticks(pids[0])
        time.sleep(1.0)
        return before >= 0 and ticks(pids[0]) == before

    wait_for(idle, timeout, what)


@contextlib.contextmanager
def replicas(postgres, redis, tmp_path, *, sim_speed: float, workers: int):
    """Two API replicas on one database and broker, with a simulated robot "sim" at ``sim_speed``: ``a`` with
    ``workers`` worker slots of its own, ``b`` with none (it only serves); both stopped cleanly after."""
    robots = json.dumps({"sim": {"sim": True, "sim_speed": sim_speed, **FAST}})
    db, broker = fresh_database(postgres), fresh_broker(redis)
    a = CeleryService(tmp_path / "a", db=db, broker=broker, workers=workers, env={"PLANNER_ROBOTS": robots}).start()
    b = CeleryService(tmp_path / "b", db=db, broker=broker, workers=workers, own_workers=False,
                      env={"PLANNER_ROBOTS": robots}).start()
    try:
        yield a, b
    finally:
        assert b.stop() == 0, b.log.read_text()
        assert a.stop() == 0, a.log.read_text()


def demo_planned(submit, read) -> dict:
    """The demo job uploaded through one replica's client (``submit``), its done view read through the other's."""
    with open(DEMO, "rb") as f:
        r = submit.post("/v1/jobs", files={"file": ("nx_first_pass.cls", f)}, data={"settings": json.dumps(SETTINGS)})
    job = wait_state(read, r.json()["id"])
    assert job["state"] == "done", job["error"]
    return job


def test_two_replicas_one_robot_never_two_executions_and_a_cancel_reaches_another_process(postgres, redis, tmp_path):
    with replicas(postgres, redis, tmp_path, sim_speed=10, workers=2) as (a, b):
        with a.client() as ca, b.client() as cb:
            job = demo_planned(ca, cb)  # planned by a worker, read through the other replica
            assert cb.get(f"/v1/jobs/{job['id']}/trajectory?format=script").status_code == 200
            body = {"robot": "sim", "mode": "program"}
            for _ in range(3):  # both replicas at once, several times: one execution holds the robot at a time
                with concurrent.futures.ThreadPoolExecutor(8) as ex:
                    answers = list(ex.map(lambda cl: cl.post(f"/v1/jobs/{job['id']}/executions", json=body),
                                          [ca, cb] * 4))
                accepted = [x for x in answers if x.status_code == 202]
                assert len(accepted) == 1 and all(x.status_code == 409 for x in answers if x.status_code != 202)
                assert wait_execution(cb, accepted[0].json()["id"])["state"] == "done"
            spans = sorted((v["started_at"], v["finished_at"]) for v in ca.get("/v1/executions").json()["executions"])
            assert len(spans) == 3 and all(s1[1] <= s2[0] for s1, s2 in zip(spans, spans[1:], strict=False))
            # a job planning in a worker process, cancelled through the other replica: stopped within a second
            big = ca.post("/v1/jobs", json=spiral(20_000)).json()["id"]
            wait_state(cb, big, states=("running",), timeout=60)
            pid = holder_pid(a, "jobs", big)
            worker = next(w for w in a.pool if w.proc.pid == pid)
            child = worker.children("planner-work")
            time.sleep(0.5)
            tic = time.monotonic()
            assert cb.delete(f"/v1/jobs/{big}").json()["state"] == "cancelled"
            wait_ended(child, 1.0, "the planning process in the worker stopped")
            stopped_in = time.monotonic() - tic
            print(f"cancel reached the worker process in {1e3 * stopped_in:.0f} ms")
            assert ca.get(f"/v1/jobs/{big}").json()["state"] == "cancelled"
            # the figures are the cluster's, whichever replica is asked
            ids = [ca.post("/v1/jobs", json=small(i)).json()["id"] for i in range(4)]
            for j in ids:
                wait_state(cb, j)
            ma, mb = ca.get("/metrics").text, cb.get("/metrics").text
            for m in (ma, mb):
                assert 'planner_jobs{state="done"} 5' in m and 'planner_jobs{state="cancelled"} 1' in m
                assert 'planner_executions{state="done"} 3' in m
                assert metric(m, "planner_workers") == 2 and metric(m, "planner_queue_depth") == 0


# -- one large job split across workers (planner/frontends/service/tasks/split.py) -------------------------------
#: Split from 100 CAM chords of varying tool axis (the rasters' axis is constant: a chord counts 0.115; the default,
#: 4096, would make the test's files, and its time, larger).
SPLIT = {"PLANNER_SPLIT_CHORDS": "100"}
#: The raster's part frame for the UR5e: reachable, its URScript under the controller's 250 kB.
RASTER_PART = [0.4, -0.05, 0.0, 3.14159, 0.0, 0.0]


def raster(rows: int, per: int) -> bytes:
    """A CSV raster (mm): ``rows`` passes of ``per`` points over a gently waved surface, turned at their ends (each
    pass a fit batch of its own in the interpolating path model)."""
    lines = ["x,y,z,i,j,k"]
    for r in range(rows):
        x = np.linspace(0.0, 200.0, per)[:: -1 if r % 2 else 1]
        lines += [f"{a:.4f},{5.0 * r:.4f},{2.0 * np.sin(a / 15.0 + r):.4f},0,0,1" for a in x]
    return ("\n".join(lines) + "\n").encode()


def submit_file(c, name: str, data: bytes, settings: dict) -> str:
    r = c.post("/v1/jobs", files={"file": (name, data)}, data={"settings": json.dumps(settings)})
    assert r.status_code == 202, r.text
    return r.json()["id"]


def piece_elsewhere(s: CeleryService, job_id: str, timeout: float = 120.0):
    """The worker (not the job's own) planning a piece of the job, once one does."""
    found: list = []

    def look() -> bool:
        rows = s.sql("select c.holder from job_chunks c join jobs j on j.id = c.job_id where c.job_id = :id and "
                     "c.state = 'running' and c.holder <> j.holder", id=job_id)
        found[:] = [w for w in s.pool if rows and w.proc.pid == int(rows[0][0].rsplit(":", 1)[1])]
        return bool(found) and bool(found[0].children("planner-work"))

    try:
        wait_for(look, timeout, f"a piece of job {job_id} planned by another worker")
    except AssertionError as exc:  # what the job did instead
        job = s.sql("select state, holder, note, error from jobs where id = :id", id=job_id)
        chunks = s.sql("select first, state, holder, takes from job_chunks where job_id = :id", id=job_id)
        workers = s.sql("select id, concurrency, busy, heartbeat_at from workers")
        raise AssertionError(f"{exc}\njob: {job}\npieces: {chunks}\nworkers: {workers} (now {time.time():.1f})\n"
                             + "\n".join(w.log.read_text()[-3000:] for w in s.pool if w.log.exists())) from None
    return found[0]


def reference(tmp_path: Path, name: str, data: bytes, settings: dict):
    """The job planned in this process, at once (the stored settings, the file under its name)."""
    from planner import PlanSettings, plan

    path = tmp_path / "reference" / name
    path.parent.mkdir(exist_ok=True)
    path.write_bytes(data)
    return plan(path, PlanSettings.from_dict(settings))


def figures(summary: dict) -> str:
    """A job's summary without its timings, as JSON text."""
    return json.dumps({k: v for k, v in summary.items() if k != "planning_s"}, sort_keys=True)


def test_a_large_file_split_across_workers_is_the_job_planned_at_once_and_survives_a_worker_killed(
        postgres, redis, tmp_path):
    import hashlib

    from planner.export import stream

    s = CeleryService(tmp_path, db=fresh_database(postgres), broker=fresh_broker(redis), workers=2, env=SPLIT).start()
    try:
        with s.client() as c:
            for j in [c.post("/v1/jobs", json=small(i)).json()["id"] for i in range(4)]:  # the workers warmed up
                wait_state(c, j, timeout=120)
            data = raster(10, 300)  # 10 passes, 2999 chords, 89 kB
            jid = submit_file(c, "raster.csv", data, {"robot": "ur5e", "part_frame": RASTER_PART})
            view = wait_state(c, jid, timeout=300)
            assert view["state"] == "done" and view["attempts"] == 1, view
            assert view["note"].startswith("split: planned in 2 pieces by 2 workers (CAM chords "), view["note"]
            assert s.sql("select count(*) from job_chunks") == [(0,)]  # its pieces removed with their moves
            assert s.sql("select name from job_data where job_id = :id order by name", id=jid) == [("input",),
                                                                                                   ("plan",)]
            whole = reference(tmp_path, "raster.csv", data, view["settings"])
            for fmt in ("csv", "json", "script"):
                got = c.get(f"/v1/jobs/{jid}/trajectory?format={fmt}")
                assert got.status_code == 200, got.text
                assert got.content == b"".join(stream(whole, fmt, parameters={"input": "raster.csv"})), fmt
            assert figures(view["summary"]) == figures(plain(whole.summary()))  # every figure but the timings
            # a job of more than VIEW_AT_PLAN_POSES poses has its 3D view data made by its worker after its end, split
            # or not (the same job at 10 kHz)
            jid = submit_file(c, "big.csv", raster(28, 600), {"rate": 10000.0})
            view = wait_state(c, jid, timeout=300)
            assert view["state"] == "done" and view["note"].startswith("split: planned in 2 pieces"), view
            assert view["summary"]["duration_s"] * 10000.0 > VIEW_AT_PLAN_POSES
            deadline = time.monotonic() + 120
            while s.sql("select count(*) from job_data where job_id = :id and name = 'view'", id=jid) != [(1,)]:
                assert time.monotonic() < deadline, "the split job's 3D view data were never stored"
                time.sleep(0.5)
            # the worker fitting the other piece killed (SIGKILL, its processes with it): the job's own worker takes
            # the piece over once its heartbeats have stopped; the job is done once, the same plan
            data = raster(28, 600)  # 28 passes, 16799 chords: seconds of fitting per piece
            jid = submit_file(c, "big.csv", data, {})
            victim = piece_elsewhere(s, jid)
            time.sleep(0.3)
            victim.kill()
            view = wait_state(c, jid, timeout=LEASE_S + 300)
            assert view["state"] == "done" and view["attempts"] == 1, view
            assert "1 taken over from a worker that stopped answering" in view["note"], view["note"]
            whole = reference(tmp_path, "big.csv", data, view["settings"])
            assert figures(view["summary"]) == figures(plain(whole.summary()))
            for fmt in ("csv", "json"):
                got = hashlib.sha256()
                with c.stream("GET", f"/v1/jobs/{jid}/trajectory?format={fmt}") as r:
                    for chunk in r.iter_bytes():
                        got.update(chunk)
                want = hashlib.sha256()
                for chunk in stream(whole, fmt, parameters={"input": "big.csv"}):
                    want.update(chunk)
                assert got.hexdigest() == want.hexdigest(), fmt
            assert s.sql("select count(*) from job_data where job_id = :id and name = 'plan'", id=jid) == [(1,)]
    finally:
        assert s.stop() == 0, s.log.read_text()


def test_a_split_job_cancelled_stops_its_pieces_and_a_failed_piece_fails_it(postgres, redis, tmp_path):
    s = CeleryService(tmp_path, db=fresh_database(postgres), broker=fresh_broker(redis), workers=2, env=SPLIT).start()
    data = raster(28, 600)
    try:
        with s.client() as c:
            jid = submit_file(c, "big.csv", data, {})
            worker = piece_elsewhere(s, jid)
            child = worker.children("planner-work")
            time.sleep(0.3)
            tic = time.monotonic()
            assert c.delete(f"/v1/jobs/{jid}").json()["state"] == "cancelled"
            wait_ended(child, 1.0, "the piece's process in the other worker stopped")
            print(f"cancel reached the piece's process in {1e3 * (time.monotonic() - tic):.0f} ms")
            assert s.sql("select count(*) from job_chunks where job_id = :id", id=jid) == [(0,)]  # gone with it
            assert c.get(f"/v1/jobs/{jid}").json()["state"] == "cancelled"
            # (the other worker's fresh process ready: else the job's own worker plans both pieces, as it should)
            wait_idle(worker, "planner-work", 60, "the other worker's fresh process started")
            assert "raised unexpected" not in "".join(w.log.read_text() for w in s.pool)  # (the coordinator's end)
            # a piece's process dies (as an out-of-memory kill would end it): the job fails with its one-line error
            jid = submit_file(c, "big.csv", data, {})
            worker = piece_elsewhere(s, jid)
            time.sleep(0.3)
            for p in worker.children("planner-work"):
                os.kill(p, 9)
            view = wait_state(c, jid, timeout=120)
            assert view["state"] == "failed", view
            assert view["error"]["message"].startswith("the worker process planning this job died (exit code -9)")
            assert "\n" not in view["error"]["message"] and view["error"]["kind"] == "internal"
            wait_for(lambda: s.sql("select count(*) from job_chunks") == [(0,)], 10, "the failed job's pieces removed")
    finally:
        assert s.stop() == 0, s.log.read_text()


def test_planner_worker_refuses_bad_options(tmp_path):
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if not k.startswith("PLANNER_")}
    r = subprocess.run([sys.executable, "-m", "planner.frontends.service", "worker"], env=env, capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 2 and "planner worker needs PLANNER_QUEUE=celery" in r.stderr
    env.update(PLANNER_QUEUE="celery", PLANNER_BROKER="redis://127.0.0.1:1/0", PLANNER_DB=f"sqlite:///{tmp_path}/j")
    r = subprocess.run([sys.executable, "-m", "planner.frontends.service", "worker", "--queues", "plan,cook"], env=env,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "--queues: cook; the queues are plan and execute" in r.stderr



def sse_rows(client, execution_id: str, last: int = 0) -> tuple[list[list[float]], list[int], dict]:
    """The live stream of an execution read to its end: the rows, the events' ids and the end's data."""
    rows: list[list[float]] = []
    ids: list[int] = []
    end: dict = {}
    with client.stream("GET", f"/v1/executions/{execution_id}/live", headers={"Last-Event-ID": str(last)}) as r:
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/event-stream"), r.status_code
        event = ""
        for line in r.iter_lines():
            if line.startswith("event: "):
                event = line[7:]
            elif line.startswith("id: "):
                ids.append(int(line[4:]))
            elif line.startswith("data: ") and event == "end":
                end = json.loads(line[6:])
                break
            elif line.startswith("data: "):
                rows += json.loads(line[6:])
    return rows, ids, end


def test_an_execution_on_a_worker_is_streamed_live_by_any_replica(postgres, redis, tmp_path):
    """The samples stay in no process: the worker running the execution relays them through Redis, and a replica
    that runs nothing streams them (at 30 Hz or more of job time, the actual joints whose forward kinematics is the
    actual TCP); a reader resuming after an event id gets exactly the rows after it. The job's 3D view data, made
    by one replica's first view request, is served by the other from the store."""
    from planner.kinematics import forward

    with replicas(postgres, redis, tmp_path, sim_speed=4, workers=1) as (a, b):
        with a.client() as ca, b.client() as cb:
            job = demo_planned(ca, cb)
            # a job this small (31,000 poses) has its view data made by the first view request (one replica's),
            # stored for every replica
            assert b.sql("select bytes from job_data where job_id = :id and name = 'view'", id=job["id"]) == []
            scene = cb.get(f"/v1/jobs/{job['id']}/view")
            assert scene.status_code == 200 and scene.json()["fine_samples"] > 100, scene.text
            (stored,), = a.sql("select bytes from job_data where job_id = :id and name = 'view'", id=job["id"])
            assert stored > 1000
            assert ca.get(f"/v1/jobs/{job['id']}/view").json() == scene.json()
            eid = cb.post(f"/v1/jobs/{job['id']}/executions", json={"robot": "sim", "mode": "stream"}).json()["id"]
            rows, ids, end = sse_rows(cb, eid)
            assert end == {"state": "done"}, (end, cb.get(f"/v1/executions/{eid}").json())
            done = wait_execution(ca, eid)
            duration = done["report"]["duration_s"]
            t = np.array([r[0] for r in rows])
            assert t.size > 0.9 * 30 * duration and np.all(np.diff(t) > 0), (t.size, duration)
            assert np.median(np.diff(t)) <= 1 / 30 + 1e-9
            q, xyz = np.array([r[1:7] for r in rows]), np.array([r[7:10] for r in rows])
            tcp = np.array([forward("ur5e", qi)[:3] for qi in q[:: max(len(q) // 50, 1)]])
            assert np.abs(tcp - xyz[:: max(len(q) // 50, 1)]).max() < 1e-3  # the joints and the TCP of one sample
            k = ids[len(ids) // 2]
            rest, _, end2 = sse_rows(ca, eid, last=k)  # resumed through the other replica
            assert end2 == {"state": "done"} and rest == rows[k:], (len(rest), len(rows), k)


def test_the_page_survives_the_service_restarting_mid_run(postgres, redis, tmp_path):
    """Headless Chromium watches a run live (program mode, 124 s of job time on a worker: a restart takes tens of
    seconds on a loaded machine); the API process is stopped mid-run and started again on the same port and
    database: the page reconnects by itself, resumes the live view after the last sample it had (every sample of the
    run reaches it exactly once, its actual arm at the recording's joints) and follows the execution to its end."""
    from tests import chromium
    from tests.chromium import wait
    from tests.test_service_view import open_view

    robots = json.dumps({"sim": {"sim": True, "sim_speed": 1, **FAST}})
    s = CeleryService(tmp_path, db=fresh_database(postgres), broker=fresh_broker(redis), workers=1,
                      env={"PLANNER_ROBOTS": robots}).start()
    d = chromium.start("--use-angle=swiftshader", "--enable-unsafe-swiftshader")
    try:
        with s.client() as c:
            with open(DEMO, "rb") as f:
                r = c.post("/v1/jobs", files={"file": ("nx_first_pass.cls", f)},
                           data={"settings": json.dumps({**SETTINGS, "feed_override": 0.5})})
            job = wait_state(c, r.json()["id"])
            assert job["state"] == "done", job["error"]
        open_view(d, s, job["id"])
        wait(d, lambda d: d.find_element("id", "exec-robot").text.strip().startswith("sim"), 30)
        d.execute_script("document.getElementById('exec-mode').value = 'program'")  # (stream mode's real-time loop
        # misses its periods on a loaded machine; the controller runs a program at its own pace)
        d.find_element("id", "execute").click()
        deadline = time.monotonic() + 240  # (the worker starts the execution's process and its controller)
        while (before := d.execute_script("return window.view3d.state"))["liveT"] is None or before["liveT"] < 3.0:
            with s.client() as c:
                runs = c.get("/v1/executions").json()["executions"]
            assert time.monotonic() < deadline, (before, runs, d.find_element("id", "execute-result").text)
            assert not runs or runs[0]["state"] in ("starting", "running"), (runs[0]["state"], runs[0]["error"])
            time.sleep(0.2)
        tic = time.monotonic()
        assert s.restart() == 0, s.log.read_text()[-3000:]
        print(f"the API process restarted in {time.monotonic() - tic:.1f} s, at job time {before['liveT']:.1f} s")
        seen = []
        deadline = time.monotonic() + 180
        while d.find_element("id", "exec-state").text != "done":
            assert time.monotonic() < deadline and d.find_element("id", "exec-state").text != "failed", \
                (d.find_element("id", "execute-result").text, d.execute_script("return window.view3d.state"))
            st = d.execute_script("return window.view3d.state")
            if st["liveT"] is not None and st["liveConnects"] > before["liveConnects"]:
                seen.append((st["liveT"], st["liveQ"]))
            time.sleep(0.25)
        wait(d, lambda d: "execution done" in d.find_element("css selector", "#view3d [data-v=live]").text, 30)
        after = d.execute_script("return window.view3d.state")
        with s.client() as c:
            eid = c.get("/v1/executions").json()["executions"][0]["id"]
            rows, _, end = sse_rows(c, eid)
        assert end == {"state": "done"}
        assert after["liveConnects"] > before["liveConnects"]  # reconnected to the new process
        assert after["liveSamples"] == len(rows), (after["liveSamples"], len(rows))  # each sample once: resumed
        by_t = {round(r[0], 6): np.array(r[1:7]) for r in rows}
        resumed = [(t, q) for t, q in seen if t > before["liveT"] + 1.0]
        assert len(resumed) >= 5, (before["liveT"], seen[:5])
        for t, q in resumed:
            assert np.abs(np.array(q) - by_t[round(t, 6)]).max() < 0.01, t
    finally:
        d.quit()
        assert s.stop() == 0, s.log.read_text()


def test_a_worker_runs_at_the_workers_niceness_its_processes_too_and_the_api_does_not(postgres, redis, tmp_path):
    """``planner worker`` is batch work, the whole process: at PLANNER_WORKER_NICE above where it started (its claims,
    heartbeats and plans stored come after the API replicas' requests on a shared machine), its planning processes
    at the same niceness (inherited, not added twice), the API replica where it started."""
    base = os.getpriority(os.PRIO_PROCESS, 0)
    s = CeleryService(tmp_path, db=fresh_database(postgres), broker=fresh_broker(redis), workers=1,
                      env={"PLANNER_WORKER_NICE": "7"}).start()
    try:
        with s.client() as c:
            view = wait_state(c, c.post("/v1/jobs", json=SMALL).json()["id"], timeout=60)
            assert view["state"] == "done", view
            (worker,) = s.pool
            planning = worker.children("planner-work")
            assert planning, "the worker's planning process is gone"
            assert os.getpriority(os.PRIO_PROCESS, worker.proc.pid) == min(base + 7, 19)
            assert [os.getpriority(os.PRIO_PROCESS, p) for p in planning] == [min(base + 7, 19)] * len(planning)
            assert os.getpriority(os.PRIO_PROCESS, s.proc.pid) == base
    finally:
        assert s.stop() == 0, s.log.read_text()
