"""Teams on a real service (uvicorn on 127.0.0.1, real SQLite, simulated controllers): a team's keys share its jobs,
another team gets 404; a team's operator runs its planner's job on the team's robot, another team's operator gets
404; the robots of a team (``planner teams robots``) without a restart. Also the migration of a database made at the
previous revision (0003: keys and jobs before teams, with real rows) into the default team, on SQLite and
PostgreSQL; list cursors of any size are 4xx; malformed ``PLANNER_*`` settings are one line with exit 2."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import uuid
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import MetaData, insert, text

from planner.frontends.cli.main import main as cli_main
from planner.frontends.service.auth import key_hash
from planner.frontends.service.store import make_engine, migrate
from tests import pg_server
from tests.test_service_executions import FAST, SETTINGS, plan_demo, wait_execution
from tests.test_service_server import ServiceProcess, wait_state

postgres = pg_server.postgres  # fixtures
pg_url = pg_server.pg_url

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "examples" / "nx_first_pass.cls"
PATH = {"waypoints": [[0, 0, 0], [0.1, 0.03, 0], [0.2, 0, 0.01]]}
ROBOTS = json.dumps({"sim": {"sim": True, "sim_speed": 10, **FAST}, "sim2": {"sim": True, "sim_speed": 10, **FAST}})


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """A service with two simulated robots and two teams: east (robot sim) and west (robot sim2), each with a
    planner and an operator key."""
    s = ServiceProcess(tmp_path_factory.mktemp("teams"), workers=1, dev=False, env={"PLANNER_ROBOTS": ROBOTS})
    assert s.teams("create", "east", "--robots", "sim") == "team east  robots sim\n"
    assert s.teams("create", "west", "--robots", "sim2") == "team west  robots sim2\n"
    s.k = {f"{team}-{role}": s.key(f"{team} {role}", role, team) for team in ("east", "west")
           for role in ("planner", "operator")}
    s.start()
    yield s
    assert s.stop() == 0, s.log.read_text()


def test_a_team_shares_its_jobs_and_another_team_gets_404(cell):
    with cell.client(cell.k["east-planner"]) as planner, cell.client(cell.k["east-operator"]) as op, \
            cell.client(cell.k["west-operator"]) as other:
        job = planner.post("/v1/jobs", json=PATH).json()["id"]
        assert wait_state(op, job)["state"] == "done"  # the team's operator watches the planner's job
        assert job in [j["id"] for j in op.get("/v1/jobs").json()["jobs"]]
        assert op.get(f"/v1/jobs/{job}/trajectory").content == planner.get(f"/v1/jobs/{job}/trajectory").content
        for path in ("", "/trajectory", "/trajectory?format=json", "/plot.png"):  # as a job that does not exist
            r = other.get(f"/v1/jobs/{job}{path}")
            assert r.status_code == 404 and r.json() == {"detail": f"no job {job}"}
        assert other.delete(f"/v1/jobs/{job}").status_code == 404
        assert other.post(f"/v1/jobs/{job}/executions", json={"robot": "sim2"}).status_code == 404
        assert job not in [j["id"] for j in other.get("/v1/jobs").json()["jobs"]]
        # the team manages its jobs: the operator cancels a long job the planner submitted (the other team cannot)
        t = np.linspace(0, 60 * np.pi, 20_000)
        helix = np.c_[0.1 * np.cos(t) + 1e-4 * t, 0.1 * np.sin(t), 2e-4 * t].round(7).tolist()
        long = planner.post("/v1/jobs", json={"waypoints": helix, "settings": {"robot": "ur5e"}}).json()["id"]
        assert other.delete(f"/v1/jobs/{long}").status_code == 404
        r = op.delete(f"/v1/jobs/{long}")
        assert r.status_code == 200 and r.json()["state"] == "cancelled"
        assert planner.get(f"/v1/jobs/{long}").json()["state"] == "cancelled"


def test_an_operator_runs_the_team_planners_job_and_another_team_gets_404(cell):
    with cell.client(cell.k["east-planner"]) as planner, cell.client(cell.k["east-operator"]) as op, \
            cell.client(cell.k["west-operator"]) as other, cell.client(cell.k["west-planner"]) as west:
        job = plan_demo(planner)["id"]
        assert planner.post(f"/v1/jobs/{job}/executions", json={"robot": "sim"}).status_code == 403
        assert [r["name"] for r in op.get("/v1/robots").json()["robots"]] == ["sim"]
        assert [r["name"] for r in other.get("/v1/robots").json()["robots"]] == ["sim2"]
        # the other team's robot is refused as a robot that does not exist (nothing started)
        r = op.post(f"/v1/jobs/{job}/executions", json={"robot": "sim2"})
        assert r.status_code == 422
        assert r.json()["detail"][0]["msg"] == "no robot named 'sim2' for team 'east' (its robots: sim)"
        r = op.post(f"/v1/jobs/{job}/executions", json={"robot": "sim", "mode": "program"})
        assert r.status_code == 202, r.text
        eid = r.json()["id"]
        view = wait_execution(op, eid)
        assert view["state"] == "done" and view["report"]["ok"] is True, view
        assert view["job_id"] == job and view["robot"] == "sim"
        assert planner.get(f"/v1/executions/{eid}").json()["state"] == "done"  # the team sees its executions
        assert [e["id"] for e in planner.get("/v1/executions", params={"job_id": job}).json()["executions"]] == [eid]
        for client in (other, west):
            r = client.get(f"/v1/executions/{eid}")
            assert r.status_code == 404 and r.json() == {"detail": f"no execution {eid}"}
            assert client.get("/v1/executions", params={"job_id": job}).json()["executions"] == []
        assert other.delete(f"/v1/executions/{eid}").status_code == 404
        # the west operator, given every robot, still cannot run the east team's job
        cell.teams("robots", "west", "all")
        assert [r["name"] for r in other.get("/v1/robots").json()["robots"]] == ["sim", "sim2"]
        assert other.post(f"/v1/jobs/{job}/executions", json={"robot": "sim"}).status_code == 404
        cell.teams("robots", "west", "sim2")
        listing = cell.teams("list").splitlines()
        rows = {line.split()[0]: line.split() for line in listing[1:]}
        jobs = str(len(op.get("/v1/jobs").json()["jobs"]))
        assert rows["east"][1:3] == ["2", jobs] and rows["east"][-1] == "sim"  # 2 active keys, the team's jobs
        assert rows["west"][1:3] == ["2", "0"] and rows["west"][-1] == "sim2"
        assert rows["default"][-1] == "all"


def test_teams_commands_refuse_with_one_line(cell, capsys):
    def run(*args: str) -> tuple[int, str]:
        code = cli_main(["teams", "--db", cell.db, *args])
        return code, capsys.readouterr().err.strip()

    assert run("create", "east") == (2, "planner: error: team 'east' exists already")
    assert run("create", "two words") == (2, "planner: error: a team's name is 1..32 of A-Z a-z 0-9 _ -, got "
                                             "'two words'")
    assert run("robots", "nobody", "sim") == (2, "planner: error: no team 'nobody' (planner teams list)")
    assert run("robots", "east", "sim;rm") == (2, "planner: error: --robots: 'sim;rm' is not a robot name (1..32 of "
                                                  "A-Z a-z 0-9 _ -); give names separated by commas, 'all' or 'none'")
    with cell.client(cell.k["east-planner"]) as c:
        jobs = len(c.get("/v1/jobs").json()["jobs"])
    assert run("delete", "east") == (2, f"planner: error: team 'east' still has 2 active key(s) and {jobs} job(s); a "
                                        "team is deleted once it has neither (planner keys revoke ID)")
    assert run("delete", "default")[0] == 2
    code = cli_main(["keys", "--db", cell.db, "create", "--name", "x", "--team", "nobody"])
    assert (code, capsys.readouterr().err.strip()) == (2, "planner: error: --team: no team 'nobody' (planner teams "
                                                          "create nobody; planner teams list)")
    assert run("create", "spare") == (0, "")
    assert run("delete", "spare") == (0, "")
    assert "spare" not in cell.teams("list")


# -- the migration of a database made by the previous version (revision 0003) ------------------------------------
def _previous_version_database(url: str) -> dict:
    """A database at revision 0003 (before teams) with the rows the previous version wrote: two keys and a revoked
    one, the demo file planned for the ur5e (its plan in job_data, through the task layer's own claim, plan and
    finish), a queued job and an interrupted execution of the done job. Written through the 0003 tables as reflected from the
    database itself (never this version's models). What was made: keys, job ids, the plan's bytes."""
    from planner.frontends.service.auth import Principal
    from planner.frontends.service.schemas import SettingsModel
    from planner.frontends.service.submit import _checked_settings, _row
    from planner.frontends.service.tasks.functions import plan_job
    from planner.frontends.service.tasks.lifecycle import JOB
    from planner.frontends.service.tasks.transitions import Transitions
    from planner.io import detect_format, read_toolpath

    engine = make_engine(url)
    migrate(engine, "0003")
    old = MetaData()
    old.reflect(engine)
    assert "teams" not in old.tables and "team" not in old.tables["jobs"].c
    keys = {}
    with engine.begin() as conn:
        for key_id, role, revoked in (("aaaa0001", "planner", None), ("bbbb0002", "operator", None),
                                      ("cccc0003", "operator", 1.7e9)):
            keys[key_id] = key = f"pk_{key_id}_{uuid.uuid4().hex}{uuid.uuid4().hex}"
            conn.execute(insert(old.tables["api_keys"]).values(id=key_id, name=f"old {role}", role=role,
                                                               key_hash=key_hash(key), created_at=1.6e9,
                                                               revoked_at=revoked))
        planner_key = Principal("aaaa0001", "planner")
        data = DEMO.read_bytes()
        fmt = detect_format(DEMO)
        axes = read_toolpath(DEMO, format=fmt).axes is not None
        settings = _checked_settings(SettingsModel.model_validate(SETTINGS), fmt, axes, [])
        done = uuid.uuid4().hex
        row = _row(done, planner_key, input_kind="file", input_name=DEMO.name, input_format=fmt,
                   input_bytes=len(data), input_json=None, settings=settings, read_options="{}")
        row.pop("team")  # (the previous version's row had no team)
        conn.execute(insert(old.tables["jobs"]).values(**row))
        conn.execute(insert(old.tables["job_data"]).values(job_id=done, name="input", data=data, bytes=len(data),
                                                           created_at=1.6e9))
        queued = uuid.uuid4().hex
        row = _row(queued, planner_key, input_kind="waypoints", input_name="<waypoints>", input_format="waypoints",
                   input_bytes=0, input_json=json.dumps(PATH), settings="{}", read_options="{}")
        row.pop("team")
        conn.execute(insert(old.tables["jobs"]).values(**row))
    store = Transitions(engine)
    job_id, attempt, spec = store.claim_job(done)
    outcome = plan_job(spec, lambda progress: None)
    assert outcome.state == "done" and store.finish(JOB, job_id, attempt, outcome)
    execution = uuid.uuid4().hex
    with engine.begin() as conn:
        conn.execute(insert(old.tables["executions"]).values(
            id=execution, job_id=done, owner="bbbb0002", robot="sim", mode="program", state="failed", created_at=1.6e9,
            finished_at=1.6e9 + 9, stage="running", done=120, total=800, error_kind="interrupted",
            error="the service stopped during the execution", attempts=1))
        assert conn.execute(text("SELECT version_num FROM alembic_version")).scalar() == "0003"
    engine.dispose()
    return {"keys": keys, "done": done, "queued": queued, "execution": execution, "plan": outcome.plan}


def _check_migrated(s: ServiceProcess, url: str, made: dict) -> None:
    """The service started on the old database: the rows are the default team's, the old keys work and share
    their jobs, a new team sees none of them."""
    engine = make_engine(url)
    try:
        with engine.connect() as conn:
            assert conn.execute(text("SELECT version_num FROM alembic_version")).scalar() == "0005"
            assert conn.execute(text("SELECT name, robots FROM teams")).all() == [("default", None)]
            assert dict(conn.execute(text("SELECT id, team FROM api_keys")).all()) == {
                k: "default" for k in made["keys"]}
            assert set(conn.execute(text("SELECT team FROM jobs")).scalars()) == {"default"}
            assert conn.execute(text("SELECT team FROM executions")).scalars().all() == ["default"]
            plan = conn.execute(text("SELECT data FROM job_data WHERE job_id = :j AND name = 'plan'"),
                                {"j": made["done"]}).scalar()
            assert bytes(plan) == made["plan"]
    finally:
        engine.dispose()
    planner_key, operator_key, revoked = made["keys"].values()
    s.teams("create", "newcomers", "--robots", "all")
    newcomer = s.key("newcomer", "operator", "newcomers")
    with s.client(planner_key) as planner, s.client(operator_key) as op, s.client(newcomer) as new, \
            s.client(revoked) as gone:
        assert gone.get("/v1/jobs").status_code == 401
        done = planner.get(f"/v1/jobs/{made['done']}").json()
        assert done["state"] == "done" and done["summary"]["executable"] is True
        assert wait_state(planner, made["queued"])["state"] == "done"  # queued before: planned after the upgrade
        assert {j["id"] for j in op.get("/v1/jobs").json()["jobs"]} == {made["done"], made["queued"]}
        old = op.get(f"/v1/executions/{made['execution']}").json()
        assert old["state"] == "failed" and old["error"]["kind"] == "interrupted"
        assert new.get("/v1/jobs").json()["jobs"] == [] and new.get("/v1/executions").json()["executions"] == []
        assert new.get(f"/v1/jobs/{made['done']}").status_code == 404
        assert new.get(f"/v1/executions/{made['execution']}").status_code == 404
        # the old operator runs the old planner's job on a robot of the default team (every configured one)
        r = op.post(f"/v1/jobs/{made['done']}/executions", json={"robot": "sim", "mode": "program"})
        assert r.status_code == 202, r.text
        view = wait_execution(op, r.json()["id"])
        assert view["state"] == "done" and view["report"]["ok"] is True, view
        assert planner.get(f"/v1/jobs/{made['done']}/trajectory?format=script").status_code == 200


def test_a_database_of_the_previous_version_migrates_into_the_default_team(tmp_path):
    url = f"sqlite:///{tmp_path / 'jobs.sqlite'}"
    made = _previous_version_database(url)
    s = ServiceProcess(tmp_path, workers=1, dev=False, env={"PLANNER_ROBOTS": ROBOTS}).start()
    try:
        _check_migrated(s, url, made)
    finally:
        assert s.stop() == 0, s.log.read_text()


def test_a_postgresql_database_of_the_previous_version_migrates_into_the_default_team(pg_url, tmp_path):
    made = _previous_version_database(pg_url)
    s = ServiceProcess(tmp_path, workers=1, dev=False, env={"PLANNER_DB": pg_url, "PLANNER_ROBOTS": ROBOTS,
                                                            "PLANNER_DATA": str(tmp_path / "data")})
    s.db = pg_url
    s.start()
    try:
        _check_migrated(s, pg_url, made)
    finally:
        assert s.stop() == 0, s.log.read_text()


# -- cursors, limits and ids of any size or shape -----------------------------------------------------------------
@pytest.mark.parametrize("params", [
    {"cursor": str(2**63)}, {"cursor": str(2**64)}, {"cursor": "9" * 5000}, {"cursor": "-1"}, {"cursor": "1.5"},
    {"cursor": "0x10"}, {"cursor": "nan"}, {"cursor": ""}, {"limit": str(2**63)}, {"limit": "0"}, {"limit": "-5"},
    {"limit": "9" * 5000}])
def test_a_list_answers_absurd_cursors_and_limits_with_422(cell, params):
    with cell.client(cell.k["east-planner"]) as c:
        r = c.get("/v1/jobs", params=params)
        assert r.status_code == 422, (params, r.status_code, r.text)
        name = next(iter(params))
        assert r.json()["detail"][0]["loc"] == ["query", name]
        if "limit" in params:
            r = c.get("/v1/executions", params=params)
            assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["query", "limit"]


def test_the_largest_cursor_and_ids_of_any_shape_answer_without_a_500(cell):
    with cell.client(cell.k["east-planner"]) as c:
        job = c.post("/v1/jobs", json=PATH).json()["id"]  # (the module's other tests may run in another process)
        page = c.get("/v1/jobs", params={"cursor": str(2**63 - 1), "limit": "500"})
        assert page.status_code == 200 and job in [j["id"] for j in page.json()["jobs"]]
        assert c.get("/v1/jobs", params={"cursor": "0"}).json()["jobs"] == []
        for bad in ("9" * 5000, str(2**64), "-1", "%00", "0" * 32 + "0", "A" * 32, "..%2f..%2fetc"):
            assert c.get(f"/v1/jobs/{bad}").status_code == 404, bad
            assert c.get(f"/v1/executions/{bad}").status_code == 404, bad
        assert c.get("/v1/executions", params={"job_id": "9" * 5000}).status_code == 422
        assert c.get("/v1/executions", params={"job_id": "9" * 32}).json()["executions"] == []


def test_the_largest_cursor_on_postgresql(postgres, tmp_path):
    url = postgres.create_database()
    s = ServiceProcess(tmp_path, workers=1, dev=False, env={"PLANNER_DB": url, "PLANNER_DATA": str(tmp_path / "d")})
    s.db = url
    s.start()
    try:
        with s.client(s.key("pg")) as c:
            job = c.post("/v1/jobs", json=PATH).json()["id"]
            page = c.get("/v1/jobs", params={"cursor": str(2**63 - 1)})
            assert page.status_code == 200 and [j["id"] for j in page.json()["jobs"]] == [job]
            for cursor in (str(2**63), str(2**31), "9" * 400):
                r = c.get("/v1/jobs", params={"cursor": cursor})
                assert r.status_code in ((200,) if cursor == str(2**31) else (422,)), (cursor, r.text)
            wait_state(c, job)
    finally:
        assert s.stop() == 0, s.log.read_text()


# -- malformed settings of the environment ------------------------------------------------------------------------
def _planner(args: list[str], env: dict[str, str], cwd: Path) -> subprocess.CompletedProcess:
    clean = {k: v for k, v in os.environ.items() if not k.startswith("PLANNER_")}
    return subprocess.run([sys.executable, "-c", "import sys; from planner.frontends.cli.main import main; "
                                                 "sys.exit(main())", *args],
                          env={**clean, **env}, capture_output=True, text=True, timeout=120, cwd=cwd)


def test_a_path_in_planner_db_is_one_line_with_exit_2_for_keys_serve_and_worker(tmp_path):
    path = tmp_path / "file.sqlite"
    expected = (f"planner: error: PLANNER_DB must be a database URL, sqlite:///PATH (a file) or "
                f"postgresql+psycopg://USER@HOST:PORT/DB, got '{path}' (for a file: sqlite:///{path})")
    for args in (["keys", "create", "--name", "x"], ["serve", "--port", "0"], ["worker"], ["teams", "list"]):
        r = _planner(args, {"PLANNER_DB": str(path)}, tmp_path)
        assert (r.returncode, r.stderr.strip(), r.stdout) == (2, expected, ""), args
    assert not path.exists() and list(tmp_path.iterdir()) == []  # nothing made


@pytest.mark.parametrize("variable, value, message", [
    ("PLANNER_DB", "mysql://u@h/db", "PLANNER_DB must be a SQLite or PostgreSQL URL, sqlite:///PATH (a file) or "
                                     "postgresql+psycopg://USER@HOST:PORT/DB, got 'mysql' in 'mysql://u@h/db'"),
    ("PLANNER_DB", "postgresql+psycopg://u@127.0.0.1:99999/db", "PLANNER_DB has the port 99999, not one of 1..65535: "
                                                                "'postgresql+psycopg://u@127.0.0.1:99999/db'"),
    ("PLANNER_DB", "sqlite:///{readme}", "PLANNER_DB sqlite:///{readme}: the database cannot be opened: file is not "
                                         "a database"),
    ("PLANNER_DB", "postgresql+psycopg://planner@127.0.0.1:1/db", "PLANNER_DB "
     "postgresql+psycopg://planner@127.0.0.1:1/db: the database cannot be opened: connection failed: *"),
    ("PLANNER_DATA", "{readme}", "PLANNER_DATA must be a folder (the service's own), got the file '{readme}'"),
    ("PLANNER_WORKERS", "two", "PLANNER_WORKERS: input should be a valid integer, unable to parse string as an "
                               "integer, got 'two'"),
    ("PLANNER_WORKERS", "9" * 5000, "PLANNER_WORKERS: unable to parse input string as an integer, exceeded maximum "
                                    "size, got '" + "9" * 59 + "... (5000 characters)"),
    ("PLANNER_DEV_NO_AUTH", "yes", "PLANNER_DEV_NO_AUTH must be 1 (serve without API keys, loopback only) or 0 (keys "
                                   "needed, the default), got 'yes'"),
    ("PLANNER_MAX_REQUEST_BYTES", "0", "PLANNER_MAX_REQUEST_BYTES must be at least 1, got '0'"),
    ("PLANNER_MAX_WAYPOINTS", "1e6", "PLANNER_MAX_WAYPOINTS: input should be a valid integer, unable to parse string "
                                     "as an integer, got '1e6'"),
    ("PLANNER_JOB_TIMEOUT", "1e308", "PLANNER_JOB_TIMEOUT must be at most 2592000.0, got '1e308'"),
    ("PLANNER_JOB_TIMEOUT", "nan", "PLANNER_JOB_TIMEOUT: input should be a finite number, got 'nan'"),
    ("PLANNER_MAX_ATTEMPTS", str(2**63), f"PLANNER_MAX_ATTEMPTS must be at most 1000, got '{2**63}'"),
    ("PLANNER_ROBOTS", "{", "PLANNER_ROBOTS: not JSON (Expecting property name enclosed in double quotes: line 1 "
                            "column 2 (char 1))"),
    ("PLANNER_QUEUE", "rabbit", "PLANNER_QUEUE must be 'local' or 'celery', got 'rabbit'"),
    ("PLANNER_BROKER", "redis://broker:99999/0", "PLANNER_BROKER must be redis://HOST:PORT/DB (or rediss://): Port "
                                                 "out of range 0-65535, got 'redis://broker:99999/0'"),
    ("PLANNER_BROKER", "amqp://broker", "PLANNER_BROKER must be redis://HOST:PORT/DB (or rediss://), got "
                                        "'amqp://broker'"),
    ("PLANNER_WORKER_NICE", "-5", "PLANNER_WORKER_NICE must be at least 0, got '-5'"),
])
@pytest.mark.parametrize("command", [["keys", "list"], ["serve", "--port", "0"], ["worker"]])
def test_a_malformed_setting_is_one_line_naming_it(tmp_path, capsys, monkeypatch, variable, value, message, command):
    readme = tmp_path / "notes.txt"  # a file that is not a database
    readme.write_text("not a database\n" * 100)
    for k in [k for k in os.environ if k.startswith("PLANNER_")]:
        monkeypatch.delenv(k)
    monkeypatch.setenv("PLANNER_DB", f"sqlite:///{tmp_path / 'j.sqlite'}")
    if command == ["worker"]:  # (a worker of the local backend is refused before its store is opened)
        monkeypatch.setenv("PLANNER_QUEUE", "celery")
        monkeypatch.setenv("PLANNER_BROKER", "redis://127.0.0.1:1/0")
    monkeypatch.setenv(variable, value.replace("{readme}", str(readme)))
    monkeypatch.chdir(tmp_path)
    code = cli_main(command)
    out = capsys.readouterr()
    expected = "planner: error: " + message.replace("{readme}", str(readme))
    assert (code, out.out, "\n" in out.err.strip()) == (2, "", False), out.err
    if expected.endswith("*"):  # (the driver's own words follow)
        assert out.err.startswith(expected[:-1]), out.err
    else:
        assert out.err.strip() == expected
    assert readme.read_text() == "not a database\n" * 100 and sorted(p.name for p in tmp_path.iterdir()) in (
        ["notes.txt"], ["j.sqlite", "notes.txt"])  # nothing else made
