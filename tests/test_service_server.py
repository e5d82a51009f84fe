"""The service as a process: a real uvicorn on 127.0.0.1 started by ``python -m planner.frontends.service serve --port 0``;
its health, metrics, OpenAPI schema, request-size limit and refusals at start-up.

:class:`ServiceProcess` is the helper the other ``test_service_*`` files use.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

ROOT = Path(__file__).resolve().parents[1]


class ServiceProcess:
    """``planner serve`` in a subprocess on a free loopback port, with its own database under ``folder``."""

    def __init__(self, folder: Path, *, workers: int = 1, dev: bool = True, env: dict | None = None,
                 host: str = "127.0.0.1"):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.db = f"sqlite:///{self.folder / 'jobs.sqlite'}"
        self.data = self.folder / "jobs.sqlite.data"  # the service's folder (PLANNER_DATA's default)
        self.workers = workers
        self.host = host
        self.env = {**os.environ, "PLANNER_DB": self.db, "PYTHONUNBUFFERED": "1", **(env or {})}
        self.env.pop("PLANNER_DEV_NO_AUTH", None)
        if dev:
            self.env["PLANNER_DEV_NO_AUTH"] = "1"
        self.proc: subprocess.Popen | None = None
        self.url = ""
        self.log = self.folder / "service.log"

    def start(self, timeout: float = 60.0, port: int = 0) -> ServiceProcess:
        """Start (on ``port``, 0: a free one) and wait until healthy; a service that does not come up is killed before
        the error is raised."""
        out = open(self.log, "ab")  # noqa: SIM115 (kept open for the process)
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "planner.frontends.service", "serve", "--host", self.host, "--port", str(port),
             "--workers", str(self.workers)], cwd=self.folder, env=self.env, stdout=subprocess.PIPE, stderr=out)
        out.close()
        try:
            self._wait_healthy(timeout)
        except BaseException:
            self.proc.kill()
            self.proc.wait(10)
            raise
        return self

    def _wait_healthy(self, timeout: float) -> None:
        assert self.proc is not None and self.proc.stdout is not None
        line = self.proc.stdout.readline().decode()
        if "listening on " not in line:
            raise AssertionError(f"the service did not start: {line!r}\n{self.log.read_text()}")
        self.url = line.split("listening on ")[1].split()[0]
        deadline = time.monotonic() + timeout
        while True:  # the lifespan (migrations, workers) runs before the first answer
            try:
                r = httpx.get(self.url + "/healthz", timeout=5)
                if r.status_code == 200 and r.json()["workers"] == self.workers:
                    return
            except httpx.TransportError:
                pass
            if time.monotonic() > deadline or self.proc.poll() is not None:
                raise AssertionError(f"the service is not healthy in {timeout} s:\n{self.log.read_text()}")
            time.sleep(0.1)

    @property
    def port(self) -> int:
        return int(self.url.rsplit(":", 1)[1])

    def restart(self, timeout: float = 60.0) -> int:
        """This service process stopped (SIGTERM) and started again on the same port and database (a celery
        replica's workers go on); the stopped process's exit code."""
        code = ServiceProcess.stop(self)
        ServiceProcess.start(self, timeout, port=self.port)
        return code

    def client(self, key: str | None = None) -> httpx.Client:
        headers = {"X-API-Key": key} if key else {}
        return httpx.Client(base_url=self.url, headers=headers, timeout=60)

    def children(self, name: str | None = None) -> list[int]:
        """The service's child processes (named ``name`` in /proc/PID/comm: planner-work, planner-plot,
        planner-exec)."""
        assert self.proc is not None
        pids: list[int] = []
        for task in Path(f"/proc/{self.proc.pid}/task").iterdir():
            pids += [int(x) for x in (task / "children").read_text().split()]
        out = []
        for p in pids:
            try:
                comm = Path(f"/proc/{p}/comm").read_text().strip()
            except OSError:  # ended meanwhile
                continue
            if name is None or comm == name:
                out.append(p)
        return out

    def worker_pids(self) -> list[int]:
        """The service's planning worker processes."""
        return self.children("planner-work")

    def kill(self) -> None:
        """SIGKILL, as a crash (the workers die with it: PR_SET_PDEATHSIG)."""
        assert self.proc is not None
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(10)
        if self.proc.stdout:
            self.proc.stdout.close()

    def stop(self) -> int:
        """SIGTERM (graceful) and the exit code."""
        if self.proc is None or self.proc.poll() is not None:
            return self.proc.returncode if self.proc else 0
        self.proc.send_signal(signal.SIGTERM)
        try:
            code = self.proc.wait(20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            code = self.proc.wait(10)
        if self.proc.stdout:
            self.proc.stdout.close()
        return code

    def sql(self, query: str, **params) -> list[tuple]:
        """Rows of an SQL query on this service's database (SQLite or PostgreSQL)."""
        from sqlalchemy import create_engine, text

        engine = create_engine(self.db)
        try:
            with engine.connect() as conn:
                return [tuple(r) for r in conn.execute(text(query), params)]
        finally:
            engine.dispose()

    def keys(self, *args: str) -> str:
        """``planner keys ...`` on this service's database (run in this process); its standard output."""
        return self._command("keys", *args)

    def teams(self, *args: str) -> str:
        """``planner teams ...`` on this service's database (run in this process); its standard output."""
        return self._command("teams", *args)

    def key(self, name: str, role: str = "planner", team: str = "default") -> str:
        """A new key (``planner keys create``) of ``role`` in ``team``: the key itself."""
        return self.keys("create", "--name", name, "--role", role, "--team", team).split("key ")[1].split()[0]

    def _command(self, command: str, *args: str) -> str:
        import contextlib
        import io

        from planner.frontends.service.cli import main

        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            code = main([command, "--db", self.db, *args])
        assert code == 0, out.getvalue()
        return out.getvalue()


def sim_service(name: str, sim_speed: float):
    """A module-scoped fixture: a service (development mode, one planning worker) with one simulated robot "sim"
    whose program mode runs ``sim_speed`` times real time (and a quick approach), stopped cleanly after the module
    (the page's and the 3D view's tests)."""

    @pytest.fixture(scope="module")
    def server(tmp_path_factory):
        robots = {"sim": {"sim": True, "sim_speed": sim_speed, "approach_speed": 2.0, "approach_acceleration": 3.0}}
        s = ServiceProcess(tmp_path_factory.mktemp(name), workers=1,
                           env={"PLANNER_ROBOTS": json.dumps(robots)}).start()
        yield s
        assert s.stop() == 0, s.log.read_text()

    return server


def wait_state(client: httpx.Client, job_id: str, states=("done", "failed", "cancelled"), timeout: float = 120.0):
    """Poll a job until it reaches one of ``states``; its view."""
    deadline = time.monotonic() + timeout
    while True:
        r = client.get(f"/v1/jobs/{job_id}")
        assert r.status_code == 200, r.text
        view = r.json()
        if view["state"] in states:
            return view
        if time.monotonic() > deadline:
            raise AssertionError(f"job {job_id} still {view['state']} after {timeout} s: {view['progress']}")
        time.sleep(0.05)


def wait_until(predicate, timeout: float, what: str):
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {timeout} s: {what}")
        time.sleep(0.02)


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    s = ServiceProcess(tmp_path_factory.mktemp("service"), workers=1,
                       env={"PLANNER_MAX_REQUEST_BYTES": "2000000", "PLANNER_JOB_TIMEOUT": "2"}).start()
    yield s
    assert s.stop() == 0, s.log.read_text()


def test_health_and_metrics_count_jobs_by_state(server):
    with server.client() as c:
        h = c.get("/healthz").json()
        assert h == {"status": "ok", "workers": 1, "busy": 0, "dev_no_auth": True}
        r = c.post("/v1/jobs", json={"waypoints": [[0, 0, 0], [0.1, 0.05, 0], [0.2, 0, 0]]})
        assert r.status_code == 202
        wait_state(c, r.json()["id"])
        m = c.get("/metrics")
    assert m.headers["content-type"].startswith("text/plain; version=0.0.4")
    values = {}
    for line in m.text.splitlines():
        if line and not line.startswith("#"):
            name, value = line.rsplit(" ", 1)
            values[name] = float(value)
    assert values['planner_jobs{state="done"}'] == 1, m.text
    assert values['planner_jobs{state="queued"}'] == 0 and values["planner_queue_depth"] == 0
    assert values["planner_planning_seconds_count"] == 1
    assert values['planner_planning_seconds_bucket{le="+Inf"}'] == 1
    assert 0 < values["planner_planning_seconds_sum"] < 60
    buckets = [v for k, v in values.items() if k.startswith("planner_planning_seconds_bucket")]
    assert buckets == sorted(buckets)  # cumulative


def test_openapi_schema_documents_both_bodies_and_the_docs_page(server):
    with server.client() as c:
        spec = c.get("/openapi.json").json()
        docs = c.get("/docs")
    body = spec["paths"]["/v1/jobs"]["post"]["requestBody"]["content"]
    assert set(body) == {"application/json", "multipart/form-data"}
    assert "file" in body["multipart/form-data"]["schema"]["properties"]
    settings = spec["components"]["schemas"]["SettingsModel"]["properties"]
    from planner.settings import PlanSettings

    assert set(settings) == set(PlanSettings().to_dict())
    for path in ("/v1/jobs/{job_id}", "/v1/jobs/{job_id}/trajectory", "/v1/jobs/{job_id}/plot.png", "/healthz",
                 "/metrics", "/v1/jobs/{job_id}/executions"):
        assert path in spec["paths"]
    assert docs.status_code == 200 and "swagger" in docs.text.lower()


def test_the_docs_page_and_its_assets_come_from_the_service_itself(server):
    import re

    with server.client() as c:
        html = c.get("/docs").text
        urls = re.findall(r"""(?:src|href)\s*=\s*["']([^"']+)["']""", html) + re.findall(r"url:\s*'([^']+)'", html)
        assert "/openapi.json" in urls
        assets = [u for u in urls if u != "/openapi.json"]
        assert sorted(assets) == ["/docs/assets/favicon-32x32.png", "/docs/assets/swagger-ui-bundle.js",
                                  "/docs/assets/swagger-ui.css"], urls
        assert "cdn" not in html.lower() and "https://" not in html and "http://" not in html
        got = {u: c.get(u) for u in assets}
        assert c.get("/redoc").status_code == 404  # its page would load its script from a CDN
        assert c.get("/docs/assets/index.html").status_code == 404  # a fixed list of files
        assert c.get("/docs/assets/..%2F..%2F__init__.py").status_code == 404
    js, css = got["/docs/assets/swagger-ui-bundle.js"], got["/docs/assets/swagger-ui.css"]
    assert js.status_code == 200 and js.headers["content-type"].startswith("text/javascript")
    assert len(js.content) > 500_000 and b"SwaggerUIBundle" in js.content
    assert css.status_code == 200 and css.headers["content-type"].startswith("text/css") and b".swagger-ui" in css.content
    assert got["/docs/assets/favicon-32x32.png"].content[:8] == b"\x89PNG\r\n\x1a\n"


def test_request_larger_than_the_limit_is_413(server):
    n = 100_000  # about 2.5 MB of JSON, above this server's 2 MB
    body = json.dumps({"waypoints": [[i * 1e-3, 0.0, 0.0] for i in range(n)]})
    with server.client() as c:
        before = c.get("/v1/jobs").json()["jobs"]
        r = c.post("/v1/jobs", content=body, headers={"content-type": "application/json"})
        assert r.status_code == 413
        assert "2000000 bytes" in r.json()["detail"]

        def chunks():  # no Content-Length: counted as it arrives
            for k in range(0, len(body), 100_000):
                yield body[k:k + 100_000].encode()

        r = c.post("/v1/jobs", content=chunks(), headers={"content-type": "application/json"})
        assert r.status_code == 413
        assert c.get("/v1/jobs").json()["jobs"] == before  # nothing stored from those


def test_dev_mode_refuses_a_non_loopback_address(tmp_path):
    env = {**os.environ, "PLANNER_DEV_NO_AUTH": "1", "PLANNER_DB": f"sqlite:///{tmp_path / 'j.sqlite'}"}
    r = subprocess.run([sys.executable, "-m", "planner.frontends.service", "serve", "--host", "0.0.0.0", "--port", "0"],
                       env=env, capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert r.returncode == 2
    assert "PLANNER_DEV_NO_AUTH=1" in r.stderr and "loopback" in r.stderr and "0.0.0.0" in r.stderr
    assert "listening" not in r.stdout


def test_a_job_over_the_time_limit_fails_with_the_reason(server):
    import numpy as np

    t = np.linspace(0, 200 * np.pi, 40_000)  # about 6 s of planning on an idle machine
    body = json.dumps({"waypoints": np.c_[0.1 * np.cos(t) + 1e-4 * t, 0.1 * np.sin(t), 2e-4 * t].round(7).tolist()})
    with server.client() as c:
        r = c.post("/v1/jobs", content=body, headers={"content-type": "application/json"})
        assert r.status_code == 202, r.text
        tic = time.monotonic()
        view = wait_state(c, r.json()["id"], timeout=30)
        elapsed = time.monotonic() - tic
        assert view["state"] == "failed" and view["error"]["kind"] == "limit", view
        assert view["error"]["message"] == "planning took longer than the service's limit of 2 s"
        assert 2.0 <= elapsed < 10.0
        # a fresh worker takes its place (started as the failure is stored, ready once it has imported the planner)
        deadline = time.monotonic() + 60
        while c.get("/healthz").json()["workers"] != 1:
            assert time.monotonic() < deadline, "no fresh worker process within 60 s"
            time.sleep(0.1)


def test_the_rest_settings_mirror_plan_settings_one_to_one():
    from planner.frontends.service.schemas import SettingsModel
    from planner.settings import PlanSettings

    assert list(SettingsModel.model_fields) == list(PlanSettings().to_dict())
    assert SettingsModel().model_dump() == PlanSettings().to_dict()
    custom = PlanSettings(path="cam", tolerance=2e-5, robot="ur10e", part_frame=(0.5, 0, 0.1, 0, 0, 1.0),
                          cut_output=("tool", 1), passes=(0, 3), feed=0.02).checked()
    assert SettingsModel.model_validate(custom.to_dict()).to_settings().checked() == custom
