"""API keys on a real service: ``planner keys create|list|revoke``, only hashes stored, roles, isolation of teams
(404; teams themselves: tests/test_service_teams.py)."""

from __future__ import annotations

import sqlite3

import pytest

from tests.test_service_server import ServiceProcess, wait_state

PATH = {"waypoints": [[0, 0, 0], [0.1, 0.03, 0], [0.2, 0, 0.01]]}


def created(out: str) -> tuple[str, str]:
    """(id, key) from ``planner keys create`` output."""
    lines = dict(line.split(" ", 1) for line in out.splitlines())
    return lines["id"].split()[0], lines["key"].strip()


@pytest.fixture(scope="module")
def keyed(tmp_path_factory):
    s = ServiceProcess(tmp_path_factory.mktemp("keys"), workers=1, dev=False)
    s.teams("create", "b")
    keys = {name: created(s.keys("create", "--name", name, "--role", role, "--team", team))
            for name, role, team in (("cam-a", "planner", "default"), ("cam-b", "planner", "b"),
                                     ("cell", "operator", "default"))}
    s.start()
    yield s, keys
    assert s.stop() == 0, s.log.read_text()


def test_keys_are_stored_as_hashes_and_listed_without_secrets(keyed):
    s, keys = keyed
    listing = s.keys("list")
    for name, (key_id, key) in keys.items():
        assert key.startswith(f"pk_{key_id}_") and len(key) > 40
        row = next(line for line in listing.splitlines() if line.startswith(key_id))
        assert name in row and key not in listing
    db = s.folder / "jobs.sqlite"
    with sqlite3.connect(db) as conn:
        stored = conn.execute("select id, role, key_hash from api_keys").fetchall()
    assert {r[0] for r in stored} == {k for k, _ in keys.values()}
    blob = b"".join(p.read_bytes() for p in s.folder.glob("jobs.sqlite*") if p.is_file())
    for _, key in keys.values():
        assert key.encode() not in blob and key.split("_", 2)[2].encode() not in blob


def test_no_key_or_a_wrong_key_is_401(keyed):
    s, keys = keyed
    with s.client() as c:
        assert c.post("/v1/jobs", json=PATH).status_code == 401
        r = c.get("/v1/jobs")  # the header the README and /docs teach, named by the 401
        assert r.headers["www-authenticate"] == 'APIKey header="X-API-Key"'
        assert r.json()["detail"].startswith("a valid API key is needed in the X-API-Key header")
    with s.client(keys["cam-a"][1] + "x") as c:
        assert c.get("/v1/jobs").status_code == 401
    with s.client("pk_" + keys["cam-a"][0]) as c:
        assert c.get("/v1/jobs").status_code == 401
    with s.client() as c:  # health and metrics carry no job data
        assert c.get("/healthz").status_code == 200 and c.get("/metrics").status_code == 200


def test_a_key_never_sees_another_teams_jobs(keyed):
    s, keys = keyed
    with s.client(keys["cam-a"][1]) as a, s.client(keys["cam-b"][1]) as b:
        job_a = a.post("/v1/jobs", json=PATH).json()["id"]
        assert wait_state(a, job_a)["state"] == "done"
        job_b = b.post("/v1/jobs", headers={"X-API-Key": keys["cam-b"][1]}, json=PATH).json()["id"]
        for path in ("", "/trajectory", "/trajectory?format=json", "/plot.png"):
            r = b.get(f"/v1/jobs/{job_a}{path}")
            assert r.status_code == 404 and r.json() == {"detail": f"no job {job_a}"}
        assert b.delete(f"/v1/jobs/{job_a}").status_code == 404
        assert [j["id"] for j in b.get("/v1/jobs").json()["jobs"]] == [job_b]
        assert [j["id"] for j in a.get("/v1/jobs").json()["jobs"]] == [job_a]
        assert a.get(f"/v1/jobs/{job_a}/trajectory").status_code == 200
        wait_state(b, job_b)


def test_executions_need_the_operator_role(keyed):
    s, keys = keyed
    with s.client(keys["cam-a"][1]) as a, s.client(keys["cell"][1]) as op:
        job_a = a.post("/v1/jobs", json=PATH).json()["id"]
        assert a.post(f"/v1/jobs/{job_a}/executions", json={"robot": "sim"}).status_code == 403
        job_op = op.post("/v1/jobs", json=PATH).json()["id"]
        wait_state(op, job_op)
        r = op.post(f"/v1/jobs/{job_op}/executions", json={"robot": "sim"})  # past the role check: the job's own
        assert r.status_code == 409 and "planned without a robot model" in r.json()["detail"]
        wait_state(a, job_a)
        r = op.post(f"/v1/jobs/{job_a}/executions", json={"robot": "sim"})  # the team's planner's job: seen too
        assert r.status_code == 409 and "planned without a robot model" in r.json()["detail"]
        wait_state(op, job_op)


def test_a_revoked_key_is_refused_at_once(keyed):
    s, keys = keyed
    key_id, key = created(s.keys("create", "--name", "temp"))
    with s.client(key) as c:
        assert c.get("/v1/jobs").status_code == 200
        assert f"revoked {key_id}" in s.keys("revoke", key_id)
        assert c.get("/v1/jobs").status_code == 401
    row = next(line for line in s.keys("list").splitlines() if line.startswith(key_id))
    assert row.split()[1:3] == ["planner", "default"] and "-" != row.split()[5]
