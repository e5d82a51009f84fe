"""Executions through a real service (uvicorn on 127.0.0.1, API keys) into real simulated controllers: the
configured "sim" robot (a SimController started per execution, program mode in fast-forward) and "cell", a
SimController this module starts on its own loopback address (the service knows it only by name). The report's
figures, one execution per robot, refusals, a stop that brings the arm to rest within a second, and an execution
interrupted by a crash of the service."""

from __future__ import annotations

import json
import threading
import time

import numpy as np
import pytest
import rtde_receive

from tests.sim_fixtures import start_sim
from tests.test_service_server import ServiceProcess, wait_state, wait_until

DEMO = "examples/nx_first_pass.cls"
PART = [0.4, 0.9965, -0.1, 0.0, 0.0, 0.0]
#: The demo pass at 4x its feed (16 s of motion), outputs on standard[0] while cutting.
SETTINGS = {"robot": "ur5e", "part_frame": PART, "cut_output": ["standard", 0], "feed_override": 4.0}
FAST = {"approach_speed": 2.0, "approach_acceleration": 3.0}
ENDED = ("done", "failed", "cancelled")


@pytest.fixture(scope="module")
def cell():
    sim = start_sim(model="ur5e")
    yield sim
    sim.stop()


@pytest.fixture(scope="module")
def slow_cell():
    """A second controller, configured with the driver's careful approach speed (0.3 rad/s)."""
    sim = start_sim(model="ur5e")
    yield sim
    sim.stop()


@pytest.fixture(scope="module")
def stop_cell():
    """A third controller, whose emergency stop a test presses during an execution."""
    sim = start_sim(model="ur5e")
    yield sim
    sim.stop()


def _robots(cell, slow_cell=None, stop_cell=None) -> str:
    robots = {"sim": {"sim": True, "sim_speed": 10, **FAST}, "cell": {"host": cell.host, "model": "ur5e", **FAST},
              "big": {"host": "127.0.0.1", "model": "ur10e"}}
    if slow_cell is not None:
        robots["slow"] = {"host": slow_cell.host, "model": "ur5e", "approach_speed": 0.3, "approach_acceleration": 0.5}
    if stop_cell is not None:
        robots["estop"] = {"host": stop_cell.host, "model": "ur5e", **FAST}
    return json.dumps(robots)


@pytest.fixture(scope="module")
def server(tmp_path_factory, cell, slow_cell, stop_cell):
    s = ServiceProcess(tmp_path_factory.mktemp("executions"), workers=1, dev=False,
                       env={"PLANNER_ROBOTS": _robots(cell, slow_cell, stop_cell)}).start()
    s.operator = s.keys("create", "--name", "cell operator", "--role", "operator").split("key ")[1].split()[0]
    s.teams("create", "other-cell", "--robots", "all")
    s.other = s.key("other operator", "operator", "other-cell")  # another team's operator, allowed every robot
    s.planner = s.keys("create", "--name", "cam station", "--role", "planner").split("key ")[1].split()[0]
    yield s
    assert s.stop() == 0, s.log.read_text()


@pytest.fixture(scope="module")
def op(server):
    with server.client(server.operator) as c:
        yield c


def plan_demo(client) -> dict:
    """The demo pass for the ur5e submitted as a file and planned: the done job's view."""
    with open(DEMO, "rb") as f:
        r = client.post("/v1/jobs", files={"file": ("nx_first_pass.cls", f)}, data={"settings": json.dumps(SETTINGS)})
    assert r.status_code == 202, r.text
    view = wait_state(client, r.json()["id"])
    assert view["state"] == "done", view["error"]
    return view


def start_running(client, job_id: str, **request) -> str:
    """An execution of the job started on a robot (``request``: robot, mode) and seen running: its id."""
    eid = client.post(f"/v1/jobs/{job_id}/executions", json=request).json()["id"]
    assert wait_execution(client, eid, states=("running",) + ENDED, timeout=60)["state"] == "running"
    return eid


@pytest.fixture(scope="module")
def demo_job(op):
    """A done job of the demo pass for the ur5e (its view)."""
    return plan_demo(op)


def wait_execution(client, execution_id: str, states=ENDED, timeout: float = 120.0) -> dict:
    deadline = time.monotonic() + timeout
    while True:
        r = client.get(f"/v1/executions/{execution_id}")
        assert r.status_code == 200, r.text
        view = r.json()
        if view["state"] in states:
            return view
        if time.monotonic() > deadline:
            raise AssertionError(f"execution {execution_id} still {view['state']} after {timeout} s: {view}")
        time.sleep(0.05)


def _busy(client) -> dict[str, bool]:
    return {r["name"]: r["busy"] for r in client.get("/v1/robots").json()["robots"]}


def test_program_on_the_simulated_robot_follows_the_plan_and_holds_the_robot(server, op, demo_job):
    job_id = demo_job["id"]
    r = op.post(f"/v1/jobs/{job_id}/executions", json={"robot": "sim", "mode": "program"})
    assert r.status_code == 202, r.text
    eid = r.json()["id"]
    assert r.headers["location"] == f"/v1/executions/{eid}"
    # one execution per robot: a second one is refused while the first runs; another robot is free
    again = op.post(f"/v1/jobs/{job_id}/executions", json={"robot": "sim", "mode": "program"})
    assert again.status_code == 409 and "busy" in again.json()["detail"]
    assert _busy(op) == {"sim": True, "cell": False, "big": False, "slow": False, "estop": False}
    wait_until(lambda: len(server.children("planner-exec")) == 1, 10, "the execution's own process")
    seen, progress = [], []
    while (v := op.get(f"/v1/executions/{eid}").json())["state"] not in ENDED:
        seen.append((v["state"], v["progress"]["done"], v["progress"]["total"]))
        progress.append(v["progress"])
        time.sleep(0.05)
    assert v["state"] == "done", v
    assert v["robot"] == "sim" and v["mode"] == "program" and v["job_id"] == job_id and v["error"] is None
    running = [(d, t) for s, d, t in seen if s == "running" and t > 0]
    assert running and all(0 <= d <= t for d, t in running), seen  # progress shown while it ran
    assert v["progress"]["done"] == v["progress"]["total"] > 0
    # progress in job time (s) of the job's, with the pass and source line being carried out
    job_view = op.get(f"/v1/jobs/{job_id}").json()
    assert v["progress"]["unit"] == "s" and v["progress"]["stage"] == "done"
    assert v["progress"]["total"] == pytest.approx(job_view["summary"]["duration_s"], abs=0.05)
    assert v["progress"]["text"] == f"executed: {v['progress']['total']:.1f} of {v['progress']['total']:.1f} s of job time"
    cutting = [p for p in progress if p["unit"] == "s" and p["pass"] is not None]
    assert cutting, progress
    for p in cutting:
        assert p["stage"] == f"cut pass {p['pass']} line {p['line']}" and p["line"] > 0
        assert p["text"] == (f"executing: {p['done']:.1f} of {p['total']:.1f} s of job time, pass {p['pass']}, "
                             f"source line {p['line']}")
    times = [p["done"] for p in progress if p["unit"] == "s"]
    assert times == sorted(times), times
    # the run's plot (actual over planned), as planner run --plot draws it
    assert v["links"]["plot"] == f"/v1/executions/{eid}/plot.png"
    r = op.get(v["links"]["plot"])
    assert r.status_code == 200 and r.headers["content-type"] == "image/png" and r.content[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = int.from_bytes(r.content[16:20], "big"), int.from_bytes(r.content[20:24], "big")
    assert width > 1000 and height > 700, (width, height)
    assert v["created_at"] <= v["started_at"] <= v["finished_at"]
    rep = v["report"]
    assert rep["ok"] and rep["failure"] is None and rep["mode"] == "program"
    # followed within the program's blend tolerance, measured (not zero), outputs at their stations
    assert 0.0 < rep["max_path_error_m"] < 0.2e-3, rep["describe"]
    assert rep["io_switches_planned"] == rep["io_switches_made"] == 2
    assert [e["value"] for e in rep["io_events"]] == [True, False]
    assert all(e["output"] == "standard[0]" and e["distance_mm"] < 1.0 for e in rep["io_events"])
    assert rep["max_io_distance_mm"] == max(e["distance_mm"] for e in rep["io_events"])
    assert rep["planned_duration_s"] == pytest.approx(demo_job["summary"]["duration_s"], abs=0.01)
    assert 0.95 * rep["planned_duration_s"] <= rep["duration_s"] <= 1.1 * rep["planned_duration_s"]
    assert rep["samples"] > 100 and rep["joint_limit_margin_rad"] > 0
    # the recording's sampling and its gaps, as the report's text gives them
    assert 0 < rep["recorded_every_s"] < 0.1 and rep["recording_gaps"] >= 0
    assert (rep["recording_samples_missed"] == 0) == (rep["recording_gaps"] == 0) == (rep["recording_longest_gap_s"] == 0)
    assert any(line.strip().startswith("recording: ") for line in rep["describe"]), rep["describe"]
    assert rep["path_length_m"] == pytest.approx(0.318, abs=0.01)
    assert rep["describe"][0] == "execution (program): ok"
    # the robot is free again, its process (and the simulated controller it started) gone; the execution is listed
    assert _busy(op)["sim"] is False
    assert server.children("planner-exec") == []
    assert [e["id"] for e in op.get("/v1/executions", params={"job_id": job_id}).json()["executions"]][0] == eid


def metrics(client) -> dict[str, float]:
    """The execution series of ``/metrics``: {'name{labels}': value}."""
    out = {}
    for line in client.get("/metrics").text.splitlines():
        if line.startswith(("planner_execution", "planner_executions")):
            name, value = line.rsplit(" ", 1)
            out[name] = float(value)
    return out


def test_metrics_count_executions_by_state_robot_time_and_failure(server, op, demo_job, stop_cell):
    before = metrics(op)
    assert before["planner_executions_running{robot=\"sim\"}"] == 0
    assert {k for k in before if k.startswith("planner_executions_running")} == {
        f'planner_executions_running{{robot="{r}"}}' for r in ("sim", "cell", "big", "slow", "estop")}
    assert {k for k in before if k.startswith("planner_executions{")} == {
        f'planner_executions{{state="{s}"}}' for s in ("starting", "running", "stopping", "done", "failed",
                                                       "cancelled")}
    count0 = before["planner_execution_seconds_count"]
    done0 = before.get('planner_executions_finished_total{state="done"}', 0)
    # a run to its end on the simulated robot: running while it runs, then done with its time in the histogram
    eid = op.post(f"/v1/jobs/{demo_job['id']}/executions", json={"robot": "sim", "mode": "program"}).json()["id"]
    wait_execution(op, eid, states=("running",) + ENDED)
    during = metrics(op)
    assert during["planner_executions_running{robot=\"sim\"}"] == 1
    assert during["planner_executions_running{robot=\"cell\"}"] == 0
    assert sum(during[f'planner_executions{{state="{s}"}}'] for s in ("starting", "running", "stopping")) == 1
    view = wait_execution(op, eid)
    assert view["state"] == "done", view
    after = metrics(op)
    took = view["finished_at"] - view["created_at"]
    assert after["planner_executions_running{robot=\"sim\"}"] == 0
    assert after['planner_executions_finished_total{state="done"}'] == done0 + 1
    assert after['planner_executions{state="done"}'] == before['planner_executions{state="done"}'] + 1
    assert after["planner_execution_seconds_count"] == count0 + 1
    assert after["planner_execution_seconds_sum"] - before["planner_execution_seconds_sum"] == pytest.approx(took,
                                                                                                             abs=0.05)
    bucket = next(b for b in (1, 5, 10, 30, 60, 120) if took <= b)  # the first bucket holding it counts it
    assert after[f'planner_execution_seconds_bucket{{le="{bucket}"}}'] == (
        before[f'planner_execution_seconds_bucket{{le="{bucket}"}}'] + 1)
    assert after['planner_execution_seconds_bucket{le="+Inf"}'] == count0 + 1
    # a failure: the cell's emergency stop pressed during the run, counted by its kind
    eid = op.post(f"/v1/jobs/{demo_job['id']}/executions", json={"robot": "estop", "mode": "program"}).json()["id"]
    try:
        wait_execution(op, eid, states=("running",) + ENDED)
        wait_until(lambda: op.get(f"/v1/executions/{eid}").json()["progress"]["done"] > 0, 30, "the run's progress")
        stop_cell.press_emergency_stop()
        view = wait_execution(op, eid, timeout=30)
    finally:
        stop_cell.release_emergency_stop()
    assert view["state"] == "failed" and view["error"]["kind"] == "emergency stop", view
    # its progress says where it stopped: job time, and the move carried out then
    assert view["progress"]["unit"] == "s" and 0 < view["progress"]["done"] < view["progress"]["total"], view
    assert view["progress"]["text"].startswith("failed while executing: "), view
    assert op.get(view["links"]["plot"]).headers["content-type"] == "image/png"  # the run up to the stop, drawn
    last = metrics(op)
    assert last['planner_execution_failures_total{kind="emergency stop"}'] == (
        after.get('planner_execution_failures_total{kind="emergency stop"}', 0) + 1)
    assert last['planner_executions_finished_total{state="failed"}'] == (
        after.get('planner_executions_finished_total{state="failed"}', 0) + 1)
    assert last["planner_execution_seconds_count"] == count0 + 2
    assert last['planner_executions_running{robot="estop"}'] == 0


def test_refusals_name_the_problem(server, op, demo_job):
    job_id = demo_job["id"]
    url = f"/v1/jobs/{job_id}/executions"
    with server.client(server.planner) as planner:
        r = planner.post(url, json={"robot": "sim"})
        assert r.status_code == 403 and "operator" in r.json()["detail"]
        assert planner.get("/v1/robots").status_code == 200
    with server.client(server.other) as other:  # another team: neither the job nor its executions exist for it
        assert other.post(url, json={"robot": "sim"}).status_code == 404
        mine = op.get("/v1/executions").json()["executions"]
        if mine:
            assert other.get(f"/v1/executions/{mine[0]['id']}").status_code == 404
            assert other.delete(f"/v1/executions/{mine[0]['id']}").status_code == 404
        assert other.get("/v1/executions").json()["executions"] == []
    r = op.post(url, json={"robot": "lab"})
    assert r.status_code == 422
    assert r.json()["detail"] == [{"loc": ["body", "robot"], "type": "value_error",
                                   "msg": "no robot named 'lab' for team 'default' (its robots: sim, cell, big, "
                                          "slow, estop)"}]
    r = op.post(url, json={"robot": "cell", "host": "10.0.0.9"})  # a request never carries a host
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "host"]
    r = op.post(url, json={"robot": "cell", "mode": "teach"})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "mode"]
    r = op.post(url, json={"robot": "big"})
    assert r.status_code == 422
    assert r.json()["detail"][0]["msg"] == f"robot 'big' is a ur10e; job {job_id} is planned for a ur5e"
    # a job planned without a robot, and a job that is not done
    r = op.post("/v1/jobs", json={"waypoints": [[0, 0, 0], [0.1, 0.05, 0], [0.2, 0, 0]]})
    bare = wait_state(op, r.json()["id"])
    r = op.post(f"/v1/jobs/{bare['id']}/executions", json={"robot": "sim"})
    assert r.status_code == 409 and "planned without a robot model" in r.json()["detail"]
    t = np.linspace(0, 60 * np.pi, 20_000)
    r = op.post("/v1/jobs", json={"waypoints": np.c_[0.1 * np.cos(t) + 1e-4 * t, 0.1 * np.sin(t),
                                                     2e-4 * t].round(7).tolist(), "settings": {"robot": "ur5e"}})
    slow = r.json()["id"]
    r = op.post(f"/v1/jobs/{slow}/executions", json={"robot": "sim"})
    assert r.status_code == 409 and r.json()["detail"].startswith(f"job {slow} is ")
    op.delete(f"/v1/jobs/{slow}")
    # a job its robot cannot make (issue 27: the README's example without a part frame): done, marked not
    # executable with the reason counted in moves, and its execution refused with that reason, nothing started
    r = op.post("/v1/jobs", json={"waypoints": [[0, 0, 0], [0.1, 0.05, 0], [0.2, 0, 0]], "settings": {"robot": "ur5e"}})
    far = wait_state(op, r.json()["id"])
    assert far["state"] == "done" and far["summary"]["executable"] is False
    assert far["summary"]["not_executable"].startswith("the robot cannot make ")
    r = op.post(f"/v1/jobs/{far['id']}/executions", json={"robot": "sim"})
    assert r.status_code == 409
    assert r.json()["detail"] == f"job {far['id']} cannot run on its robot: {far['summary']['not_executable']}"
    assert op.get("/v1/executions/0123").status_code == 404
    assert not any(_busy(op).values())  # nothing refused was started


def test_one_default_mode_for_the_api_its_robots_listing_and_the_command_line(op, demo_job):
    """An execution asked for without a mode runs in the drivers' DEFAULT_MODE (program: chosen by
    bench/bench_modes.py), the mode the schema documents, the robots listing offers (the page selects it) and
    ``planner run`` takes without --mode."""
    from drivers.base import DEFAULT_MODE
    from planner.frontends.cli.main import build_parser

    assert DEFAULT_MODE == "program"
    assert {r["mode_default"] for r in op.get("/v1/robots").json()["robots"]} == {DEFAULT_MODE}
    schema = op.get("/openapi.json").json()["components"]["schemas"]
    assert schema["ExecutionRequest"]["properties"]["mode"]["default"] == DEFAULT_MODE
    assert build_parser().parse_args(["run", DEMO, "--sim"]).mode == DEFAULT_MODE
    r = op.post(f"/v1/jobs/{demo_job['id']}/executions", json={"robot": "sim"})
    assert r.status_code == 202, r.text
    view = wait_execution(op, r.json()["id"])
    assert view["state"] == "done" and view["mode"] == DEFAULT_MODE, view
    assert view["report"]["describe"][0].startswith(f"execution ({DEFAULT_MODE}): ok"), view["report"]["describe"]


@pytest.mark.realtime
def test_stop_brings_the_arm_to_rest_within_a_second(op, demo_job, cell):
    r = op.post(f"/v1/jobs/{demo_job['id']}/executions", json={"robot": "cell", "mode": "stream"})
    assert r.status_code == 202, r.text
    eid = r.json()["id"]
    view = wait_execution(op, eid, states=("running",) + ENDED, timeout=60)
    assert view["state"] == "running", view
    watch = rtde_receive.RTDEReceiveInterface(cell.host)
    try:
        deadline = time.monotonic() + 30
        while op.get(f"/v1/executions/{eid}").json()["progress"]["done"] < 3.0:  # 3 s of job time into the pass
            assert time.monotonic() < deadline
            time.sleep(0.05)
        assert np.abs(watch.getActualQd()).max() > 0.01  # moving
        rest: dict = {}

        def watch_rest() -> None:
            t_end = time.monotonic() + 10
            while time.monotonic() < t_end:
                if np.abs(watch.getActualQd()).max() < 1e-3:
                    rest["t"] = time.monotonic()
                    return
                time.sleep(0.002)

        asked = time.monotonic()
        th = threading.Thread(target=watch_rest)
        th.start()
        r = op.delete(f"/v1/executions/{eid}")
        th.join(15)
        assert r.status_code == 200, r.text
        assert "t" in rest and rest["t"] - asked < 1.0, f"arm at rest {rest.get('t', np.inf) - asked:.3f} s after"
        time.sleep(0.3)
        assert np.abs(watch.getActualQd()).max() < 1e-3  # and stays there
        assert watch.getActualDigitalOutputBits() & 1 == 0  # the job's output off
    finally:
        watch.disconnect()
    view = r.json()
    assert view["state"] == "cancelled", view
    assert view["note"] == "stopped by the operator"
    err = view["error"]
    assert err["kind"] == "cancelled" and "cancelled by the caller" in err["reason"]
    assert 2.5 < err["t"] < view["report"]["planned_duration_s"]
    assert len(err["pose"]) == 6 and all(np.isfinite(err["pose"])) and isinstance(err["line"], int)
    rep = view["report"]
    assert rep["ok"] is False and rep["failure"] == err and rep["mode"] == "stream"
    assert rep["max_path_error_m"] < 0.2e-3  # what it did, it did on the path
    assert op.delete(f"/v1/executions/{eid}").status_code == 409  # it has ended
    assert _busy(op)["cell"] is False


@pytest.mark.realtime
def test_stop_during_the_approach_move_halts_the_arm_at_once(op, demo_job, slow_cell):
    """The approach onto the job's start is one blocking joint move the driver's cancel does not reach: a stop then
    halts the controller's program (dashboard "stop"); the execution ends cancelled with the driver's reason."""
    eid = op.post(f"/v1/jobs/{demo_job['id']}/executions", json={"robot": "slow"}).json()["id"]
    watch = rtde_receive.RTDEReceiveInterface(slow_cell.host)
    try:
        deadline = time.monotonic() + 30
        while np.abs(watch.getActualQd()).max() < 0.05:  # the approach has begun (several seconds at 0.3 rad/s)
            assert time.monotonic() < deadline, op.get(f"/v1/executions/{eid}").json()
            time.sleep(0.01)
        assert op.get(f"/v1/executions/{eid}").json()["state"] == "starting"
        asked = time.monotonic()
        out: dict = {}
        th = threading.Thread(target=lambda: out.update(r=op.delete(f"/v1/executions/{eid}")))
        th.start()
        while np.abs(watch.getActualQd()).max() >= 1e-3:
            assert time.monotonic() - asked < 1.0, "the arm still moves a second after the stop"
            time.sleep(0.002)
        th.join(15)
    finally:
        watch.disconnect()
    view = out["r"].json()
    assert view["state"] == "cancelled" and view["note"] == "stopped by the operator", view
    assert view["error"]["reason"].startswith("move to the start") and view["error"]["t"] == 0.0
    assert view["report"] is None and _busy(op)["slow"] is False


@pytest.mark.realtime
def test_a_crash_of_the_service_fails_the_execution_it_interrupted(tmp_path, cell):
    s = ServiceProcess(tmp_path, workers=1, env={"PLANNER_ROBOTS": _robots(cell)}).start()
    try:
        with s.client() as c:
            job = plan_demo(c)
            eid = start_running(c, job["id"], robot="cell")
        s.kill()
        s.start()
        with s.client() as c:
            view = c.get(f"/v1/executions/{eid}").json()
            assert view["state"] == "failed" and view["error"]["kind"] == "interrupted", view
            assert "not started again" in view["error"]["reason"]
            assert _busy(c)["cell"] is False
            # the robot can be used again: the next execution runs to its end
            again = c.post(f"/v1/jobs/{job['id']}/executions", json={"robot": "cell", "mode": "program"})
            assert again.status_code == 202, again.text
            done = wait_execution(c, again.json()["id"])
            assert done["state"] == "done" and done["report"]["ok"], done
    finally:
        s.stop()


@pytest.mark.realtime
def test_sigterm_during_a_streamed_execution_stops_the_arm_and_the_restart_shows_it_cancelled(tmp_path, cell):
    """SIGTERM (graceful shutdown) while the arm follows a streamed job: the arm is at rest within a second of the
    signal (seen through a real rtde_receive client), the job's output off, the service exits 0; started again, the
    service shows the execution cancelled with the reason and the robot free."""
    import signal

    s = ServiceProcess(tmp_path, workers=1, env={"PLANNER_ROBOTS": _robots(cell)}).start()
    watch = rtde_receive.RTDEReceiveInterface(cell.host)
    try:
        with s.client() as c:
            job = plan_demo(c)
            eid = start_running(c, job["id"], robot="cell", mode="stream")
            deadline = time.monotonic() + 30
            while c.get(f"/v1/executions/{eid}").json()["progress"]["done"] < 3.0:  # 3 s of job time into the pass
                assert time.monotonic() < deadline
                time.sleep(0.05)
        assert np.abs(watch.getActualQd()).max() > 0.01  # moving
        assert watch.getActualDigitalOutputBits() & 1 == 1  # cutting
        asked = time.monotonic()
        s.proc.send_signal(signal.SIGTERM)
        rest = None
        while time.monotonic() - asked < 5.0:
            if np.abs(watch.getActualQd()).max() < 1e-3:
                rest = time.monotonic() - asked
                break
            time.sleep(0.002)
        assert rest is not None and rest < 1.0, f"the arm still moves {time.monotonic() - asked:.2f} s after SIGTERM"
        print(f"arm at rest {rest:.3f} s after SIGTERM")
        assert s.proc.wait(30) == 0, s.log.read_text()
        s.proc.stdout.close()
        time.sleep(0.3)
        assert np.abs(watch.getActualQd()).max() < 1e-3  # and stays there
        assert watch.getActualDigitalOutputBits() & 1 == 0  # the job's output off
        s.start()
        with s.client() as c:
            view = c.get(f"/v1/executions/{eid}").json()
            assert view["state"] == "cancelled" and view["note"] == "the service is shutting down", view
            err = view["error"]
            assert err["kind"] == "cancelled" and "cancelled by the caller" in err["reason"]
            assert 2.5 < err["t"] < view["report"]["planned_duration_s"] and len(err["pose"]) == 6
            assert view["report"]["ok"] is False and view["report"]["max_path_error_m"] < 0.2e-3
            assert _busy(c)["cell"] is False
    finally:
        watch.disconnect()
        s.stop()


@pytest.mark.parametrize("text, message", [
    ('{"cell": {"host": "cell.local", "model": "ur5e"}}', "robot 'cell': host must be an IP address, got 'cell.local'"),
    ('{"cell": {"model": "ur5e"}}', "robot 'cell': give either host (the controller's IP address) or \"sim\": true"),
    ('{"cell": {"host": "10.0.0.2"}}', "robot 'cell': model is needed for a real controller"),
    ('{"cell": {"sim": true, "model": "ur7"}}', "robot 'cell': model: unknown robot model 'ur7'"),
    ('{"cell": {"sim": true, "port": 1}}', "robot 'cell': unknown field 'port'"),
    ('{"cell": {"host": "10.0.0.2", "model": "ur5e", "sim_speed": 2}}', "sim_speed applies to simulated robots only"),
    ('{"cell": {"sim": true, "io": "profinet"}}', "robot 'cell': io must be 'rtde' or 'modbus'"),
    ('{"a b": {"sim": true}}', "robot 'a b': a name is 1..32 of A-Z a-z 0-9 _ -"),
    ('{}', "at least one robot"),
    ('{"a": {"host": "10.0.0.2", "model": "ur5e"}, "b": {"host": "10.0.0.2", "model": "ur5e"}}',
     "robot 'b': host 10.0.0.2 is robot 'a''s already (one name per controller)"),
    ('{"cell": ', "PLANNER_ROBOTS: not JSON"),
    ('{"cell": {"sim": true, "lookahead": 0.5}}', "robot 'cell': lookahead must be at most 0.2, got 0.5"),
    ('{"cell": {"sim": true, "gain": 50}}', "robot 'cell': gain must be at least 100"),
    ('{"cell": {"sim": true, "path_tolerance_mm": 0}}', "robot 'cell': path_tolerance_mm must be > 0"),
    ('{"cell": {"sim": true, "fail_on_deviation": true}}', "robot 'cell': fail_on_deviation needs path_tolerance_mm"),
    ('{"cell": {"sim": true, "max_program_bytes": 100}}', "robot 'cell': max_program_bytes must be at least 4096"),
])
def test_robot_configuration_refusals_name_the_robot_and_field(text, message):
    from planner.errors import PlannerError
    from planner.frontends.service.config import ServiceConfig

    with pytest.raises(PlannerError) as err:
        ServiceConfig.from_env({"PLANNER_ROBOTS": text})
    assert message in str(err.value)


def test_robots_from_a_file_and_the_default(tmp_path):
    from planner.frontends.service.config import RobotConfig, ServiceConfig

    assert ServiceConfig.from_env({}).robots == (RobotConfig("sim"),)
    f = tmp_path / "robots.json"
    f.write_text('{"cell": {"host": "10.0.0.2", "model": "UR10e", "io": "modbus", "modbus_port": 5020}}')
    cfg = ServiceConfig.from_env({"PLANNER_ROBOTS": str(f)})
    assert cfg.robots == (RobotConfig("cell", "10.0.0.2", "ur10e", "modbus", 5020),)
    assert cfg.robot("cell").simulated is False and cfg.robot("sim") is None


def test_a_robots_servo_and_deviation_settings_reach_the_driver(tmp_path):
    """PLANNER_ROBOTS' driver options (the ranges and defaults of planner run's) are what the execution process
    gives the driver: a tolerance below program mode's blending fails the run on deviation."""
    from drivers.servo import DEFAULT_GAIN, DEFAULT_LOOKAHEAD
    from planner import PlanSettings, plan
    from planner.export import MAX_PROGRAM_BYTES
    from planner.frontends.service.config import ServiceConfig
    from planner.frontends.service.tasks.functions import ExecuteSpec, execute_job

    cfg = ServiceConfig.from_env({"PLANNER_ROBOTS": json.dumps({
        "strict": {"sim": True, "sim_speed": 10, "path_tolerance_mm": 0.0001, "fail_on_deviation": True,
                   "lookahead": 0.1, "gain": 300, "compensate": False},
        "small": {"sim": True, "sim_speed": 10, "max_program_bytes": 8192},
        "plain": {"sim": True, "sim_speed": 10}})})
    strict, plain, small = cfg.robot("strict"), cfg.robot("plain"), cfg.robot("small")
    assert plain.driver_options() == {"approach_speed": 0.5, "approach_acceleration": 0.5,
                                      "lookahead": DEFAULT_LOOKAHEAD, "gain": DEFAULT_GAIN, "compensate": True,
                                      "path_tolerance": None, "fail_on_deviation": False,
                                      "max_program_bytes": MAX_PROGRAM_BYTES}
    assert strict.driver_options() == {**plain.driver_options(), "lookahead": 0.1, "gain": 300.0, "compensate": False,
                                       "path_tolerance": pytest.approx(1e-7), "fail_on_deviation": True}
    assert small.driver_options() == {**plain.driver_options(), "max_program_bytes": 8192}
    t = np.linspace(0.0, 1.0, 9)
    bead = np.c_[0.2 * t, 0.03 * np.sin(2 * np.pi * t), np.zeros_like(t)]
    job = plan(bead, PlanSettings(feed=0.02, robot="ur5e", part_frame=(0.4, -0.1, 0.2, 0, 0, 0)))
    for robot, ok in ((plain, True), (strict, False), (small, None)):
        fields = {"name": robot.name, "host": robot.host, "model": robot.model, "io": robot.io,
                  "modbus_port": robot.modbus_port, "sim_speed": robot.sim_speed, "driver": robot.driver_options()}
        end = execute_job(ExecuteSpec("x", job.to_bytes(), "program", fields), lambda p: None, threading.Event())
        if ok is None:  # the robot's program size limit: the bead's one pass needs a larger program, refused
            assert end.state == "failed" and "over the limit of 8192 bytes per program" in (end.error or ""), end
            continue
        figures = json.loads(end.values["report"])
        assert figures["ok"] is ok, figures
        if not ok:  # the run made to fail on the robot's tolerance (0.1 um, below program mode's blending)
            assert "beyond the path tolerance 0.000 mm" in str(figures), figures


def test_serve_refuses_a_bad_robots_option_with_its_message(tmp_path):
    import os
    import subprocess
    import sys

    env = {**os.environ, "PLANNER_DB": f"sqlite:///{tmp_path / 'j.sqlite'}"}
    r = subprocess.run([sys.executable, "-m", "planner.frontends.service", "serve", "--port", "0", "--robots",
                        '{"cell": {"host": "cell.local", "model": "ur5e"}}'], env=env, capture_output=True, text=True,
                       timeout=60, cwd=tmp_path)
    assert r.returncode == 2 and "listening" not in r.stdout
    assert r.stderr.strip() == "planner: error: --robots: robot 'cell': host must be an IP address, got 'cell.local'"
