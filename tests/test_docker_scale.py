"""docker/compose.scale.yaml run on a real Docker engine (marker ``docker``, run last by ``./run test``): the celery
backend's topology in containers, from the stand-in images of tests/docker_images.py (no registry is reachable here).

Two API replicas behind nginx on one port of the host's loopback, two worker containers (two task processes each),
Redis, PostgreSQL and the simulated controller on the cell network. 200 small jobs (100-waypoint CSV files) are
submitted alternately to the two replicas, each addressed directly at its container's address on the stack's
network (past the proxy, so that both surely take half); the proxy's published port answers the reads. A worker
container is SIGKILLed (``docker kill``) while it holds running jobs: every job ends done exactly once (one stored
plan, one attempt, two for the jobs the killed container held: the replicas' keeper queued them again once their
heartbeats had stopped), exports are the same bytes from either replica. The demo job, submitted to one replica, is
executed on the simulated "cell" robot through the other. ``down -v`` leaves no container, network or volume.
"""

from __future__ import annotations

import concurrent.futures
import json
import time

import httpx
import numpy as np
import pytest

from planner.frontends.service.tasks.transitions import LEASE_S
from tests.compose_stack import DOCKER, ComposeStack, free_port, free_subnet, planner_image, print_times
from tests.docker_images import NGINX, POSTGRES, PYTHON, REDIS, docker, ensure_test_images
from tests.test_docker import DEMO, OPTIONS, _execute_on_the_cell
from tests.test_service_jobs import cli_settings
from tests.test_service_server import wait_state

pytestmark = pytest.mark.docker

JOBS = 200
WAYPOINTS = 100
#: Seconds each step took (printed at the end of the module, for the README's figures).
TIMES: dict[str, float] = {}
NOTES: list[str] = []


@pytest.fixture(scope="module", autouse=True)
def report_times(request):
    yield
    print_times(request.config, "docker scale", TIMES, NOTES)


@pytest.fixture(scope="module")
def image() -> str:
    for tag, seconds in ensure_test_images((REDIS, POSTGRES, NGINX)).items():
        TIMES[f"stand-in {tag}"] = seconds
    return planner_image(TIMES)


def waypoints_csv(i: int) -> bytes:
    """Job ``i``'s file: 100 waypoints (mm) along a helix of its own, a CSV with a header."""
    t = np.linspace(0.0, 2.0 * np.pi, WAYPOINTS)
    rng = np.random.default_rng(i)
    p = np.c_[60.0 * np.cos(t), 60.0 * np.sin(t) + 0.1 * i, 8.0 * t] + rng.uniform(-0.05, 0.05, (WAYPOINTS, 3))
    return ("x,y,z\n" + "".join(f"{x:.4f},{y:.4f},{z:.4f}\n" for x, y, z in p)).encode()


class Database:
    """SQL on the stack's PostgreSQL (psql in its container): rows of text fields."""

    def __init__(self, stack: ComposeStack):
        self.container = stack.container("postgres")

    def rows(self, sql: str) -> list[list[str]]:
        out = docker("exec", self.container, "psql", "-U", "planner", "-d", "planner", "-AtF", "\t", "-c", sql,
                     timeout=60, what="psql in the stack's postgres")
        return [line.split("\t") for line in out.splitlines() if line]


def test_scaled_stack_200_jobs_through_two_replicas_a_worker_killed_each_job_done_once(image):
    port = free_port()
    subnet, robot = free_subnet()
    stack = ComposeStack(DOCKER / "compose.scale.yaml", {
        "PLANNER_IMAGE": image, "PLANNER_BASE_IMAGE": PYTHON, "PLANNER_REDIS_IMAGE": REDIS,
        "PLANNER_POSTGRES_IMAGE": POSTGRES, "PLANNER_PROXY_IMAGE": NGINX, "PLANNER_PORT": str(port),
        "PLANNER_CELL_SUBNET": subnet, "PLANNER_CELL_ROBOT": robot, "PLANNER_WORKER_CONTAINERS": "2",
        "PLANNER_WORKERS": "2"})
    proxy = f"http://127.0.0.1:{port}"
    try:
        t0 = time.monotonic()
        # Compose starts each service once those it depends on are healthy: Redis and PostgreSQL, then api-1 (it
        # migrates the database), then api-2, the workers and the simulated controller, then the proxy
        stack.compose("up", "--detach", "--no-build", timeout=600)
        for service in ("api-1", "api-2"):
            stack.wait_healthy(service, 180)
        workers = stack.containers("worker")
        assert len(workers) == 2, stack.logs()
        TIMES["scaled stack up to healthy"] = time.monotonic() - t0
        bindings = stack.inspect("proxy")["NetworkSettings"]["Ports"]["8000/tcp"]
        assert bindings == [{"HostIp": "127.0.0.1", "HostPort": str(port)}]  # the host's loopback only
        assert httpx.get(proxy + "/v1/jobs", timeout=30).status_code == 401
        out = stack.exec("api-1", "python", "-m", "planner.frontends.service", "keys", "create", "--name",
                         "docker scale test", "--role", "operator")
        key = out.split("key ")[1].split()[0]  # in the shared database: both replicas know it
        auth = {"Authorization": f"Bearer {key}"}
        db = Database(stack)
        replicas = [httpx.Client(base_url=f"http://{stack.address(s)}:8000", headers=auth, timeout=60)
                    for s in ("api-1", "api-2")]
        front = httpx.Client(base_url=proxy, headers=auth, timeout=60)
        try:
            # the demo job, planned first (a worker ahead of the small ones), executed at the end through api-2
            with open(DEMO, "rb") as f:
                r = replicas[0].post("/v1/jobs", files={"file": (DEMO.name, f)},
                                     data={"settings": json.dumps(cli_settings(*OPTIONS))})
            assert r.status_code == 202, r.text
            demo = r.json()["id"]

            def submit(i: int) -> tuple[str, float]:
                tic = time.monotonic()
                r = replicas[i % 2].post("/v1/jobs", files={"file": (f"helix-{i}.csv", waypoints_csv(i))})
                assert r.status_code == 202, (i, r.text)
                return r.json()["id"], time.monotonic() - tic

            t0 = time.monotonic()
            # alternately to api-1 and api-2, each at its own address, four requests at a time
            with concurrent.futures.ThreadPoolExecutor(4) as pool:
                submitted = list(pool.map(submit, range(JOBS)))
            ids, latencies = [s[0] for s in submitted], [s[1] for s in submitted]
            TIMES[f"{JOBS} jobs submitted"] = time.monotonic() - t0
            p50, p99 = np.percentile(latencies, [50, 99]) * 1e3
            NOTES.append(f"{JOBS} submissions, 4 at a time while the workers plan: p50 {p50:.0f} ms, p99 {p99:.0f} ms")
            assert len(set(ids)) == JOBS

            # a worker container killed while it holds running jobs (a third of the jobs done, most still to run)
            hosts = {json.loads(docker("inspect", w))[0]["Config"]["Hostname"]: w for w in workers}
            deadline = time.monotonic() + 300
            while True:
                counts = dict(db.rows("select state, count(*) from jobs group by state"))
                holders = [h.rsplit(":", 1)[0] for h, in db.rows("select holder from jobs where state = 'running'")]
                held = [h for h in holders if h in hosts]
                if int(counts.get("done", 0)) >= JOBS // 3 and held:
                    break
                assert int(counts.get("done", 0)) < JOBS, f"every job done before the kill: {counts}"
                assert time.monotonic() < deadline, f"no third of the jobs done in 300 s: {counts}\n{stack.logs()}"
                time.sleep(0.2)
            victim = held[0]
            docker("kill", hosts[victim])  # SIGKILL: the container's worker and its task processes at once
            t_kill = time.monotonic()
            TIMES["submission to the kill"] = t_kill - t0
            interrupted = {jid for jid, in db.rows(
                f"select id from jobs where state = 'running' and holder like '{victim}:%'")}
            done_at_kill = int(counts.get("done", 0))
            assert interrupted, "the killed container held no running job"

            # every job done, once
            deadline = time.monotonic() + LEASE_S + 240
            while (counts := dict(db.rows("select state, count(*) from jobs group by state"))) != {
                    "done": str(JOBS + 1)}:
                assert not {"failed", "cancelled"} & set(counts), counts
                assert time.monotonic() < deadline, f"not all done {deadline - t_kill:.0f} s after the kill: " \
                                                    f"{counts}\n{stack.logs()}"
                time.sleep(0.5)
            TIMES["kill to every job done"] = time.monotonic() - t_kill
            TIMES["submission to every job done"] = time.monotonic() - t0
            views = {jid: front.get(f"/v1/jobs/{jid}").json() for jid in ids}
            assert all(v["state"] == "done" and v["error"] is None for v in views.values())
            rerun = {jid for jid, v in views.items() if v["attempts"] == 2}
            assert rerun == interrupted - {demo}, (rerun, interrupted)
            assert all(v["attempts"] == 1 for jid, v in views.items() if jid not in rerun)
            assert all("worker stopping to answer" in views[jid]["note"] for jid in rerun)
            # one plan stored per job (a completion that ran twice stored once)
            plans = dict(db.rows("select job_id, count(*) from job_data where name = 'plan' group by job_id"))
            assert {jid: plans.get(jid) for jid in ids} == dict.fromkeys(ids, "1")
            # both replicas planned on the workers: the surviving one and the killed one both ended jobs
            planners = {h.rsplit(":", 1)[0] for h, in db.rows("select holder from jobs where holder is not null")}
            assert planners <= set(hosts) and victim in planners and len(planners) == 2, planners
            m = front.get("/metrics").text
            assert f'planner_jobs{{state="done"}} {JOBS + 1}' in m, m
            # an export is the same bytes from either replica and from the proxy (the plan is in the database)
            some = ids[1]
            exports = [c.get(f"/v1/jobs/{some}/trajectory").content for c in (*replicas, front)]
            assert exports[0].startswith(b"#") and len(exports[0]) > 10_000 and len(set(exports)) == 1

            # the demo job, submitted to api-1, executed on the simulated cell through api-2
            t1 = time.monotonic()
            view = wait_state(replicas[1], demo, timeout=60)
            assert view["state"] == "done", view["error"]
            _execute_on_the_cell(replicas[1], view, stack)
            TIMES["execution on the cell through api-2"] = time.monotonic() - t1
            killed = json.loads(docker("inspect", hosts[victim]))[0]
            NOTES.append(f"{JOBS} jobs, {done_at_kill} done at the kill, {len(rerun)} run again (held by the killed "
                         f"worker container; it is {killed['State']['Status']} now, {killed['RestartCount']} "
                         f"restarts)")
        finally:
            for c in (*replicas, front):
                c.close()
    finally:
        t0 = time.monotonic()
        stack.down()
        TIMES["scaled stack down"] = time.monotonic() - t0
    assert stack.resources() == {"containers": [], "networks": [], "volumes": []}
