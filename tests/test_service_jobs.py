"""Jobs through a real service (uvicorn on 127.0.0.1, one worker process): every input type's whole flow, exports
byte-identical to ``planner plan -o`` / ``--plot``, bad inputs with their 4xx and messages, cancellation."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest

from planner.frontends.cli.main import DEMO_PART_FRAME, build_parser
from planner.frontends.cli.main import main as cli_main
from planner.frontends.cli.options import parse_pose, settings_from_args
from tests import pg_server, redis_server
from tests.celery_cluster import CeleryService, fresh_broker, fresh_database
from tests.test_service_server import ServiceProcess, wait_state, wait_until

postgres, redis = pg_server.postgres, redis_server.redis  # fixtures (the celery backend's servers)

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
DATA = ROOT / "tests" / "data"


@pytest.fixture(scope="module", params=["local", "celery"])
def server(request, tmp_path_factory):
    """The service on each backend: local worker processes (SQLite), and an API replica with a ``planner worker``
    (Celery on Redis, PostgreSQL)."""
    env = {"PLANNER_MAX_WAYPOINTS": "30000"}
    if request.param == "local":
        s = ServiceProcess(tmp_path_factory.mktemp("jobs"), workers=1, env=env).start()
    else:
        pg, redis = request.getfixturevalue("postgres"), request.getfixturevalue("redis")
        s = CeleryService(tmp_path_factory.mktemp("jobs-celery"), db=fresh_database(pg), broker=fresh_broker(redis),
                          workers=1, env=env).start()
    yield s
    assert s.stop() == 0, s.log.read_text()


@pytest.fixture(scope="module")
def client(server):
    with server.client() as c:
        yield c


def cli_settings(*options: str) -> dict:
    """The PlanSettings ``planner plan FILE OPTIONS`` uses, as REST JSON."""
    return settings_from_args(build_parser().parse_args(["plan", "x", *options])).to_dict()


def submit_file(client, path: Path, settings: dict | None = None, read_options: dict | None = None, name=None):
    data = {}
    if settings is not None:
        data["settings"] = json.dumps(settings)
    if read_options is not None:
        data["read_options"] = json.dumps(read_options)
    with open(path, "rb") as f:
        return client.post("/v1/jobs", files={"file": (name or path.name, f)}, data=data)


def cli_outputs(tmp: Path, path: Path, options: list[str], outputs: list[str]) -> dict[str, bytes]:
    """What ``planner plan PATH OPTIONS -o out.EXT`` writes, per extension (``png`` via --plot)."""
    out = {}
    for ext in outputs:
        target = tmp / f"cli.{ext}"
        args = ["plan", str(path), *options, *(["--plot", str(target)] if ext == "png" else ["-o", str(target)])]
        assert cli_main(args) == 0
        out[ext] = target.read_bytes()
    return out


CASES = {  # file, CLI options, exports compared
    "csv": (EXAMPLES / "nx_first_pass.csv", [], ["csv", "json"]),
    "clsf-robot": (EXAMPLES / "nx_first_pass.cls", ["--robot", "ur5e", "--part-frame", DEMO_PART_FRAME],
                   ["csv", "script", "png"]),
    "apt": (DATA / "solidworks_cam_apt_boss_excerpt.apt", ["--pass", "0,1"], ["csv"]),
    "gcode": (DATA / "nx2022_haas_umc750_excerpt.txt", ["--machine", "haas-umc-750", "--pass", "2"], ["csv"]),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_file_job_exports_are_the_cli_bytes(client, tmp_path, case):
    path, options, outputs = CASES[case]
    read_options = {"machine": options[options.index("--machine") + 1]} if "--machine" in options else None
    r = submit_file(client, path, cli_settings(*options), read_options)
    assert r.status_code == 202, r.text
    job_id = r.json()["id"]
    assert r.headers["location"] == f"/v1/jobs/{job_id}"
    view = wait_state(client, job_id)
    assert view["state"] == "done", view["error"]
    assert view["input"]["name"] == path.name and view["input"]["bytes"] == path.stat().st_size
    assert view["summary"]["source"] == path.name and view["summary"]["passes"] >= 1
    assert view["describe"][0].startswith(f"{path.name}: ")
    assert view["progress"]["stage"] == "done" and view["attempts"] == 1
    assert 0 < view["timings"]["planning_s"] < view["timings"]["running_s"]
    expected = cli_outputs(tmp_path, path, options, outputs)
    for ext in outputs:
        url = f"/v1/jobs/{job_id}/plot.png" if ext == "png" else f"/v1/jobs/{job_id}/trajectory?format={ext}"
        got = client.get(url)
        assert got.status_code == 200, got.text
        assert got.content == expected[ext], f"{case}: {ext} differs from the CLI's ({len(got.content)} vs " \
                                             f"{len(expected[ext])} bytes)"
    if "script" not in outputs:  # a program needs a robot: refused with the CLI's reason
        r = client.get(f"/v1/jobs/{job_id}/trajectory?format=script")
        assert r.status_code == 422 and "robot" in r.json()["detail"][0]["msg"]


def test_json_file_and_json_waypoints_give_the_same_trajectory(client, tmp_path):
    from planner.io import read_toolpath

    pts = read_toolpath(EXAMPLES / "nx_first_pass.csv", units="mm").points  # m
    (tmp_path / "pass.json").write_text(json.dumps({"units": "m", "points": pts.tolist()}))
    r = submit_file(client, tmp_path / "pass.json")
    assert r.status_code == 202, r.text
    view = wait_state(client, r.json()["id"])
    assert view["state"] == "done", view["error"]
    assert view["input"]["format"] == "json"
    csv_file = client.get(f"/v1/jobs/{view['id']}/trajectory").text
    assert csv_file.encode() == cli_outputs(tmp_path, tmp_path / "pass.json", [], ["csv"])["csv"]
    r = client.post("/v1/jobs", json={"waypoints": pts.tolist()})
    assert r.status_code == 202, r.text
    wp = wait_state(client, r.json()["id"])
    assert wp["state"] == "done" and wp["input"]["kind"] == "waypoints"
    assert wp["summary"]["cut_length_mm"] == pytest.approx(view["summary"]["cut_length_mm"], rel=1e-9)
    rows_file = [line.rsplit(",", 1)[0] for line in csv_file.splitlines() if not line.startswith("#")]
    rows_wp = [line.rsplit(",", 1)[0] for line in client.get(f"/v1/jobs/{wp['id']}/trajectory").text.splitlines()
               if not line.startswith("#")]
    assert rows_wp == rows_file  # same samples; the header and the line column (file line or index) differ


def test_waypoints_with_axes_feeds_and_settings(client):
    t = np.linspace(0, np.pi, 12)
    pts = np.c_[0.2 * np.cos(t), 0.2 * np.sin(t), np.zeros_like(t)]
    axes = np.c_[np.zeros_like(t), 0.2 * np.ones_like(t), np.ones_like(t)].tolist()
    feeds = [None] + [0.02] * 11
    body = {"waypoints": pts.tolist(), "axes": axes, "feeds": feeds,
            "settings": {"rate": 125.0, "cut_output": ["tool", 1], "feed": 0.03}}
    r = client.post("/v1/jobs", json=body)
    assert r.status_code == 202, r.text
    view = wait_state(client, r.json()["id"])
    assert view["state"] == "done", view["error"]
    assert view["summary"]["axes"] == "file"
    assert view["settings"]["rate"] == 125.0 and view["settings"]["cut_output"] == ["tool", 1]
    doc = client.get(f"/v1/jobs/{view['id']}/trajectory?format=json").json()
    assert doc["columns"][-1] == "io" and doc["parameters"]["rate_hz"] == 125.0
    times = np.array([row[0] for row in doc["samples"]])
    assert np.allclose(np.diff(times), 1 / 125.0, atol=2e-6)
    # the arc (pi * 0.2 m) at 20 mm/s takes at least its length over the feed
    assert times[-1] >= np.pi * 0.2 / 0.02


def test_part_frame_auto_is_placed_and_returned_for_reuse(client):
    """``part_frame: "auto"`` over REST: the worker places the part; the job shows the frame found, the same
    one ``planner plan --part-frame auto`` prints, and the settings it was planned with hold it."""
    r = submit_file(client, EXAMPLES / "nx_first_pass.cls", {"robot": "ur5e", "part_frame": "auto"})
    assert r.status_code == 202, r.text
    view = wait_state(client, r.json()["id"])
    assert view["state"] == "done", view["error"]
    auto = view["summary"]["part_frame_auto"]
    frame = auto["part_frame"]
    assert len(frame) == 6 and frame[3] == 0 and frame[4] == 0  # a turn about the base z only
    assert np.allclose(parse_pose(auto["option"]), frame, atol=1e-6)
    assert auto["singularity_margin"] > 0 and auto["joint_margin_deg"] > 0
    bad = client.post("/v1/jobs", json={"waypoints": [[0, 0, 0], [0.1, 0, 0]], "settings": {"part_frame": "autox"}})
    assert bad.status_code == 422 and "part_frame" in bad.text


def test_list_is_newest_first_and_paginated(client):
    ids = []
    for k in range(3):
        r = client.post("/v1/jobs", json={"waypoints": [[0, 0, 0], [0.1, 0.01 * (k + 1), 0], [0.2, 0, 0]]})
        ids.append(r.json()["id"])
    page = client.get("/v1/jobs?limit=2").json()
    assert [j["id"] for j in page["jobs"]] == ids[::-1][:2]
    rest = client.get(f"/v1/jobs?limit=2&cursor={page['next_cursor']}").json()
    assert rest["jobs"][0]["id"] == ids[0]
    for i in ids:
        wait_state(client, i)


BAD_JSON = [  # body, status, loc, words in the message
    ('{"waypoints": [[0, 0, NaN], [1, 0, 0]]}', 422, ["body", "waypoints", 0, 2], "finite"),
    ('{"waypoints": [[0, 0, 0], [1, 0, Infinity]]}', 422, ["body", "waypoints", 1, 2], "finite"),
    ('{"waypoints": [[0, 0], [1, 0, 0]]}', 422, ["body", "waypoints", 0, 2], "required"),
    ('{"waypoints": [[0, 0, 0]]}', 422, ["body", "waypoints"], "at least 2"),
    ('{"waypoints": [[0, 0, 0], [1, 0, 0]], "speed": 3}', 422, ["body", "speed"], "Extra inputs"),
    ('{"waypoints": [[0, 0, 0], [1, 0, 0]], "settings": {"tolerence": 1e-5}}', 422,
     ["body", "settings", "tolerence"], "Extra inputs"),
    ('{"waypoints": [[0, 0, 0], [1, 0, 0]], "settings": {"limits": {"speed": 1, "acceleration": 1}}}', 422,
     ["body", "settings", "limits", "jerk"], "Field required"),
    ('{"waypoints": [[0, 0, 0], [1, 0, 0]], "settings": {"tolerance": -1}}', 422, ["body", "settings", "tolerance"],
     "tolerance must be in (0, 1]"),
    ('{"waypoints": [[0, 0, 0], [1, 0, 0]], "settings": {"robot": "ur99"}}', 422, ["body", "settings", "robot"],
     "ur5e"),
    ('{"waypoints": [[0, 0, 0], [1, 0, 0]], "settings": {"part_frame": [0, 0, 0, 0, 0]}}', 422,
     ["body", "settings", "part_frame"], "required"),  # six numbers or "auto": item 5 is missing
    ('{"waypoints": [[0, 0, 0], [1, 0, 0]], "settings": {"frame": "grm", "axes": "fixed"}}', 422,
     ["body", "settings", "frame"], "axes='path'"),
    ('{"waypoints": [[0, 0, 0], [0, 0, 0], [1, 0, 0]]}', 422, ["body", "waypoints"], "waypoint 1"),
    ('{"waypoints": [[0, 0, 0], [1, 0, 0]], "axes": [[0, 0, 1]]}', 422, ["body", "axes"], "(2, 3)"),
    ('{"waypoints": [[0, 0, 0], [1, 0, 0]], "axes": [[0, 0, 1], [0, 0, 0]]}', 422, ["body", "axes"], "axes[1]"),
    ('{"waypoints": [[0, 0, 0], [1, 0, 0]], "feeds": [null, -1]}', 422, ["body", "feeds"], "feeds[1]"),
    ('{"waypoints": [[0, 0, 0], [1, 0, 0]], "feeds": [null]}', 422, ["body", "feeds"], "one feed per waypoint"),
    ('{"waypoints": [[0, 0, 0], [1, 0, 0]', 422, ["body"], "JSON"),
    ('[1, 2]', 422, ["body"], "object"),
]


@pytest.mark.parametrize("k", range(len(BAD_JSON)))
def test_bad_json_is_422_naming_the_field(client, k):
    body, status, loc, words = BAD_JSON[k]
    before = client.get("/v1/jobs?limit=1").json()["jobs"][:1]
    r = client.post("/v1/jobs", content=body, headers={"content-type": "application/json"})
    assert r.status_code == status, r.text
    detail = r.json()["detail"]
    assert any(d["loc"][:len(loc)] == loc and words.lower() in d["msg"].lower() for d in detail), detail
    assert client.get("/v1/jobs?limit=1").json()["jobs"][:1] == before  # nothing stored


def test_too_many_waypoints_and_wrong_content_type(client):
    r = client.post("/v1/jobs", json={"waypoints": [[i * 1e-3, 0, 0] for i in range(30_001)]})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "waypoints"]
    assert "at most 30000" in r.json()["detail"][0]["msg"]
    r = client.post("/v1/jobs", content=b"GOTO/1,2,3", headers={"content-type": "text/plain"})
    assert r.status_code == 415


def test_bad_files_are_422_with_the_readers_message(client, tmp_path):
    bad = tmp_path / "bad.apt"
    bad.write_text("FROM/0,0,10\nGOTO/1,2,x\n")
    r = submit_file(client, bad)
    assert r.status_code == 422
    d = r.json()["detail"][0]
    assert d["loc"] == ["body", "file"] and d["msg"].startswith("bad.apt line 2") and "'x'" in d["msg"]
    csv = tmp_path / "pts.csv"
    csv.write_text("x,y,z\n0,0,0\n1,2\n")
    r = submit_file(client, csv)
    assert r.status_code == 422 and "pts.csv line 3" in r.json()["detail"][0]["msg"]
    r = submit_file(client, EXAMPLES / "nx_first_pass.csv", read_options={"units": "furlong"})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "read_options", "units"]
    r = submit_file(client, EXAMPLES / "nx_first_pass.csv", read_options={"machine": "haas-umc-750"})
    d = r.json()["detail"][0]  # an option this reader does not take: named as a read option, not a bad file
    assert r.status_code == 422 and d["loc"] == ["body", "read_options", "machine"] and "machine" in d["msg"]
    r = submit_file(client, EXAMPLES / "nx_first_pass.csv", settings={"frame": "er", "axes": "path"},
                    read_options={"units": "mm"})
    assert r.status_code == 202, r.text  # the tool normal to the path: any frame method
    r = submit_file(client, EXAMPLES / "nx_first_pass.cls", settings={"frame": "er"})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "settings", "frame"]
    r = client.post("/v1/jobs", files={"file": ("a.csv", b"0,0,0\n1,0,0\n")}, data={"path": "/etc/passwd"})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "path"]
    r = client.post("/v1/jobs", data={"settings": "{}"}, files={"other": ("a.csv", b"0,0,0\n")})
    assert r.status_code == 422
    r = client.post("/v1/jobs", files={"file": ("a.csv", b"0,0,0\n1,0,0\n")}, data={"settings": '{"rate": NaN}'})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "settings", "rate"]


def test_a_request_path_never_reaches_the_file_system(server, client):
    outside = server.folder.parent / "escaped.csv"
    r = client.post("/v1/jobs", files={"file": ("../../escaped.csv", b"0,0,0\n10,0,0\n20,5,0\n")})
    assert r.status_code == 202, r.text
    view = wait_state(client, r.json()["id"])
    assert view["state"] == "done" and view["input"]["name"] == "escaped.csv"
    assert not outside.exists()
    assert not any(p.name == "escaped.csv" for p in server.folder.rglob("*"))  # the input is in the database
    stored = server.sql("select name, data from job_data where job_id = :id", id=view["id"])
    assert sorted(name for name, _ in stored) == ["input", "plan"]  # (a small job's 3D view: made when first asked)
    assert dict(stored)["input"] == b"0,0,0\n10,0,0\n20,5,0\n"
    assert client.get("/v1/jobs/..%2F..%2Fetc").status_code == 404
    assert client.get("/v1/jobs/" + "0" * 32).status_code == 404


def test_a_planning_failure_is_the_planners_message(client):
    r = client.post("/v1/jobs", files={"file": ("pass.cls", (EXAMPLES / "nx_first_pass.cls").read_bytes())},
                    data={"settings": json.dumps({"passes": [7]})})
    assert r.status_code == 202
    view = wait_state(client, r.json()["id"])
    assert view["state"] == "failed"
    assert view["error"]["kind"] == "input" and view["error"]["message"].startswith("passes: pass.cls has passes 0..")
    assert client.get(f"/v1/jobs/{view['id']}/trajectory").status_code == 409


def big_spiral(n: int) -> list:
    t = np.linspace(0, 200 * np.pi, n)
    return np.c_[0.1 * np.cos(t) + 1e-4 * t, 0.1 * np.sin(t), 2e-4 * t].tolist()


def test_cancel_a_running_job_stops_its_worker_within_a_second(server, client):
    r = client.post("/v1/jobs", json={"waypoints": big_spiral(20_000)})  # about 3 s of planning
    job_id = r.json()["id"]
    queued = client.post("/v1/jobs", json={"waypoints": [[0, 0, 0], [0.1, 0.02, 0], [0.2, 0, 0]]}).json()["id"]
    wait_state(client, job_id, states=("running",), timeout=30)
    pids = server.worker_pids()
    assert len(pids) == 1
    time.sleep(0.5)  # well into the planning
    tic = time.monotonic()
    r = client.delete(f"/v1/jobs/{job_id}")
    assert r.status_code == 200 and r.json()["state"] == "cancelled"
    wait_until(lambda: not Path(f"/proc/{pids[0]}").exists() or "Z" in
               Path(f"/proc/{pids[0]}/stat").read_text().split()[2], 1.0, "the worker process stopped")
    assert time.monotonic() - tic < 1.0
    view = wait_state(client, queued, timeout=60)  # the next job runs on a fresh worker
    assert view["state"] == "done"
    assert server.worker_pids() != pids
    final = client.get(f"/v1/jobs/{job_id}").json()
    assert final["state"] == "cancelled" and final["summary"] is None
    assert client.delete(f"/v1/jobs/{job_id}").status_code == 409
    assert client.get(f"/v1/jobs/{job_id}/trajectory").status_code == 409


def test_cancel_a_queued_job(server, client):
    first = client.post("/v1/jobs", json={"waypoints": big_spiral(20_000)}).json()["id"]
    second = client.post("/v1/jobs", json={"waypoints": [[0, 0, 0], [0.1, 0.02, 0], [0.2, 0, 0]]}).json()["id"]
    assert client.delete(f"/v1/jobs/{second}").json()["state"] == "cancelled"
    assert client.delete(f"/v1/jobs/{first}").json()["state"] == "cancelled"
    view = client.get(f"/v1/jobs/{second}").json()
    assert view["state"] == "cancelled" and view["attempts"] == 0 and view["started_at"] is None


def _maps(pid: int) -> str:
    return Path(f"/proc/{pid}/maps").read_text()


def test_plots_are_drawn_outside_the_service_process(server, client):
    """The picture is drawn by the service's drawing process: matplotlib is never loaded into the process that
    answers requests; requests that arrive while it is drawn share one drawing and get the same bytes."""
    import concurrent.futures

    r = client.post("/v1/jobs", json={"waypoints": [[0, 0, 0], [0.1, 0.05, 0], [0.2, 0, 0.01], [0.3, 0.02, 0]]})
    job_id = wait_state(client, r.json()["id"])["id"]

    def get(_):
        with server.client() as c:
            return c.get(f"/v1/jobs/{job_id}/plot.png")

    with concurrent.futures.ThreadPoolExecutor(4) as ex:
        answers = list(ex.map(get, range(4)))
    assert all(a.status_code == 200 and a.headers["content-type"] == "image/png" for a in answers)
    assert answers[0].content[:8] == b"\x89PNG\r\n\x1a\n" and len(answers[0].content) > 20_000
    assert len({a.content for a in answers}) == 1
    assert "matplotlib" not in _maps(server.proc.pid)  # no matplotlib extension module mapped in the service
    drawers = server.children("planner-plot")
    assert len(drawers) == 1 and "matplotlib" in _maps(drawers[0])  # the drawing process
    assert all("matplotlib" not in _maps(p) for p in server.worker_pids())  # planning workers do not plot
    assert client.get(f"/v1/jobs/{job_id}/plot.png").content == answers[0].content  # kept, not drawn again


def test_a_picture_target_that_is_not_a_regular_file_is_one_line_and_a_link_is_written_through(server, client):
    """The service stores its pictures through the one writer: a FIFO where the picture goes (the service's own
    folder, changed under it) is a 500 whose detail is one line naming it, never a hang or a traceback, and the FIFO
    stays; a symbolic link there is written through and stays a link."""
    import os
    import stat

    r = client.post("/v1/jobs", json={"waypoints": [[0, 0, 0], [0.1, 0.05, 0], [0.2, 0, 0.01]]})
    view = wait_state(client, r.json()["id"])
    assert view["state"] == "done", view["error"]
    folder = server.data / "plots"
    target = folder / f"{view['id']}.{view['attempts']}.png"
    os.mkfifo(target)
    r = client.get(f"/v1/jobs/{view['id']}/plot.png")
    assert r.status_code == 500, r.text
    detail = r.json()["detail"]
    assert isinstance(detail, str) and "\n" not in detail and "Traceback" not in r.text
    assert detail == (f"job {view['id']}: the picture cannot be stored: {target}: is a FIFO (named pipe), not a "
                      "regular file; refusing to write to it")
    assert stat.S_ISFIFO(os.lstat(target).st_mode)
    assert client.get("/healthz").json()["status"] == "ok"
    target.unlink()
    (folder / "pictures").mkdir()
    target.symlink_to("pictures/kept.png")  # dangling until the picture is drawn
    r = client.get(f"/v1/jobs/{view['id']}/plot.png")
    assert r.status_code == 200 and r.content[:8] == b"\x89PNG\r\n\x1a\n"
    assert target.is_symlink() and (folder / "pictures" / "kept.png").read_bytes() == r.content
    assert sorted(p.name for p in (folder / "pictures").iterdir()) == ["kept.png"]
