"""The page at ``GET /`` in headless Chromium (Debian's chromium and chromium-driver, driven by selenium) against a
real service: paste waypoints, upload a CLSF file for a robot, watch the job to done, see the summary and the plot,
the downloads, a refused input's message; the screenshot is checked to show the plot."""

from __future__ import annotations

import io
import json
import re
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests import chromium
from tests.chromium import wait
from tests.test_service_server import ServiceProcess, sim_service

ROOT = Path(__file__).resolve().parents[1]


server = sim_service("page", sim_speed=20)


@pytest.fixture(scope="module")
def browser():
    driver = chromium.start("--disable-gpu")
    yield driver
    driver.quit()


def _executions(client):
    r = client.get("/v1/executions")
    assert r.status_code == 200, r.text
    return r.json()["executions"]


def until_done(driver):
    wait(driver, lambda d: d.find_element("id", "job-state").text in ("done", "failed", "cancelled"))
    return driver.find_element("id", "job-state").text


def test_paste_waypoints_watch_the_job_and_see_the_plot(server, browser, tmp_path):
    d = browser
    d.get(server.url + "/")
    assert d.title == "planner: path jobs"
    wait(d, lambda d: d.find_element("id", "mode").text == "development mode (no keys)")
    d.find_element("id", "tab-points").click()
    d.find_element("id", "points").send_keys("0, 0, 0\n100, 20, 0\n200, 0, 10\n300, 40, 0")
    rate = d.find_element("id", "rate")
    rate.clear()
    rate.send_keys("250")
    d.find_element("id", "submit").click()
    assert until_done(d) == "done", d.find_element("id", "job-error").text
    summary = d.find_element("id", "summary").text
    assert summary.startswith("<waypoints>: 4 points -> 1 pass, 0 rapids")
    wait(d, lambda d: d.execute_script("const p = document.getElementById('plot'); "
                                       "return p.complete && p.naturalWidth > 1000;"))
    job_id = d.find_element("id", "job-id").text
    with server.client() as c:
        view = c.get(f"/v1/jobs/{job_id}").json()
    assert view["settings"]["rate"] == 250.0  # what the page sent, in SI
    assert summary.splitlines() == view["describe"]
    assert [a.text for a in d.find_elements("css selector", "#downloads a")] == ["trajectory CSV", "trajectory JSON"]
    assert d.find_element("css selector", "#jobs tr.job td:last-child").text == "done"
    # the screenshot shows the plot: a large, detailed region where the plot is
    shot = Image.open(io.BytesIO(d.get_screenshot_as_png())).convert("RGB")
    shot.save(tmp_path / "page.png")
    rect = d.find_element("id", "plot").rect
    assert rect["width"] > 600 and rect["height"] > 300
    scale = shot.width / d.execute_script("return window.innerWidth")
    box = [int(v * scale) for v in (rect["x"], rect["y"], rect["x"] + rect["width"],
                                    min(rect["y"] + rect["height"], d.execute_script("return window.innerHeight")))]
    region = np.asarray(shot.crop(box))
    assert region.shape[0] > 100
    colours = len(np.unique(region.reshape(-1, 3), axis=0))
    assert colours > 200, f"the plot region has only {colours} colours"
    assert (region.min(axis=2) < 128).mean() > 0.005  # lines and text drawn on it
    # planned without a robot: Run is disabled, saying why
    wait(d, lambda d: d.find_element("id", "run-reason").text != "")
    assert not d.find_element("id", "execute").is_enabled()
    assert d.find_element("id", "run-reason").text == ("Run is disabled: the job was planned without a robot model; "
                                                       "plan it for a robot to run it")


def test_upload_a_clsf_file_for_a_robot_and_a_refused_input(server, browser):
    d = browser
    d.get(server.url + "/")
    d.find_element("id", "file").send_keys(str(ROOT / "examples" / "nx_first_pass.cls"))
    from selenium.webdriver.support.ui import Select

    Select(d.find_element("id", "robot")).select_by_visible_text("ur5e")
    d.find_element("id", "partframe").send_keys("400, 996.5, -100, 0, 0, 0")  # mm and deg, as the label says
    d.find_element("id", "submit").click()
    assert until_done(d) == "done", d.find_element("id", "job-error").text
    assert "ur5e: every move reachable" in d.find_element("id", "summary").text
    wait(d, lambda d: len(d.find_elements("id", "download-script")) == 1)
    # the page sent the API's metres: the same job as the API planned from the part frame in SI
    page_job = d.find_element("id", "job-id").text
    with server.client() as c:
        seen = c.get(f"/v1/jobs/{page_job}").json()
        np.testing.assert_allclose(seen["settings"]["part_frame"], [0.4, 0.9965, -0.1, 0, 0, 0], rtol=0, atol=1e-12)
        with open(ROOT / "examples" / "nx_first_pass.cls", "rb") as f:
            r = c.post("/v1/jobs", files={"file": ("nx_first_pass.cls", f)},
                       data={"settings": json.dumps({"robot": "ur5e", "part_frame": [0.4, 0.9965, -0.1, 0, 0, 0]})})
        assert r.status_code == 202, r.text
        api_job = wait_job(c, r.json()["id"])
        untimed = lambda lines: [re.sub(r"planned in [\d.]+ m?s", "", ln) for ln in lines]  # noqa: E731
        assert api_job["state"] == "done" and untimed(api_job["describe"]) == untimed(seen["describe"])
        assert api_job["settings"] == seen["settings"]
    # the execution mode the page offers is the service's default (the robots listing's)
    from drivers.base import DEFAULT_MODE

    wait(d, lambda d: d.find_element("id", "exec-mode").get_attribute("value") == DEFAULT_MODE, 30)
    # run it on the simulated robot (program mode, fast-forward): progress, then the execution report
    wait(d, lambda d: d.find_element("id", "exec-robot").text.strip() == "sim (simulated)", 30)  # from /v1/robots
    d.find_element("id", "execute").click()
    wait(d, lambda d: d.find_element("id", "exec-state").text in ("starting", "running", "done"), 30)
    seen = set()
    wait(d, lambda d: seen.add((d.find_element("id", "exec-state").text,
                                d.find_element("id", "exec-stage").text)) or
         d.find_element("id", "exec-state").text in ("done", "failed", "cancelled"), 120)
    assert d.find_element("id", "exec-state").text == "done", d.find_element("id", "execute-result").text
    # progress in job time with the pass and source line being cut
    assert any(state == "running" and re.fullmatch(r"\(executing: [\d.]+ of [\d.]+ s of job time, pass \d+, source "
                                                   r"line \d+\)", stage) for state, stage in seen), seen
    report = d.find_element("id", "exec-report").text
    job_id = d.find_element("id", "job-id").text
    with server.client() as c:
        runs = [e for e in _executions(c) if e["job_id"] == job_id]
    assert len(runs) == 1 and runs[0]["state"] == "done"
    assert report.splitlines() == runs[0]["report"]["describe"]
    assert report.startswith("execution (program): ok")
    assert float(d.find_element("id", "exec-progress").get_attribute("value")) == 1.0
    # the run's plot (actual over planned) under the report, as planner run --plot draws it
    wait(d, lambda d: d.execute_script("const p = document.getElementById('exec-plot'); "
                                       "return p.complete && p.naturalWidth > 1000 && p.offsetWidth > 300;"), 120)
    # a refused input: the API's 422 message, naming the field, on the page
    d.find_element("id", "tab-points").click()
    d.find_element("id", "points").send_keys("0, 0, 0\n0, 0, 0\n100, 0, 0")
    d.find_element("id", "submit").click()
    wait(d, lambda d: d.find_element("id", "error").text != "")
    assert d.find_element("id", "error").text == "waypoints: waypoint 1: duplicates waypoint 0 (consecutive points " \
                                                  "must differ)"


def wait_job(client, job_id: str, timeout: float = 90.0) -> dict:
    end = time.monotonic() + timeout
    while True:
        view = client.get(f"/v1/jobs/{job_id}").json()
        if view["state"] not in ("queued", "running") or time.monotonic() > end:
            return view
        time.sleep(0.2)


def test_the_part_frame_is_typed_in_mm_and_deg_and_metres_typed_there_are_refused(server, browser):
    """The part frame field takes mm and deg (each value may carry its unit, as on the command line) and sends the
    API's metres and radians; a position typed in metres (every value under 5 mm) is refused on the page with the
    likely mistake named, and nothing is submitted."""
    d = browser
    d.get(server.url + "/")
    label = d.find_element("css selector", "label[for=partframe]").text
    assert label == "part frame x,y,z (mm), rx,ry,rz (deg), or auto"
    convert = lambda text: d.execute_script("return partFrame(arguments[0]);", text)  # noqa: E731
    np.testing.assert_allclose(convert("400, 996.5, -100, 0, 0, 90"), [0.4, 0.9965, -0.1, 0, 0, np.pi / 2],
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(convert("0.4m 99.65cm -100mm 0 1.5708rad 0deg"), [0.4, 0.9965, -0.1, 0, 1.5708, 0],
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(convert("2mm, 0, 0, 0, 0, 0"), [0.002, 0, 0, 0, 0, 0], rtol=0, atol=1e-15)  # meant
    assert convert("AUTO") == "auto"
    with server.client() as c:
        before = [j["id"] for j in c.get("/v1/jobs").json()["jobs"]]
    d.find_element("id", "tab-points").click()
    d.find_element("id", "points").send_keys("0, 0, 0\n100, 20, 0\n200, 0, 10")
    refusals = {
        "0.4,0.9965,-0.1,0,0,0": "part frame 0.4,0.9965,-0.1,0,0,0: x, y, z are in mm and all under 5 mm: did you "
                                 "type m where mm is expected? In mm that is 400, 996.5, -100; give a value its unit "
                                 "(0.4mm) if millimetres are meant",
        "400,0,0,0,0": "part frame 400,0,0,0,0: must be six values x, y, z in mm and rx, ry, rz in deg (or each with "
                       "its unit: 0.4m, 1.5708rad), or auto, got 5 values",
        "400,0,0,0,0,90grad": 'part frame 400,0,0,0,0,90grad: rz = 90grad: unknown unit "grad" (an angle takes deg, '
                              'rad)',
        "400,1e999,0,0,0,0": "part frame 400,1e999,0,0,0,0: y = 1e999 is not a finite number",
        "400,nan,0,0,0,0": "part frame 400,nan,0,0,0,0: y = nan is not a number (must be six values x, y, z in mm "
                           "and rx, ry, rz in deg (or each with its unit: 0.4m, 1.5708rad), or auto)",
    }
    for typed, message in refusals.items():
        field = d.find_element("id", "partframe")
        field.clear()
        field.send_keys(typed)
        d.find_element("id", "submit").click()
        wait(d, lambda d: d.find_element("id", "error").text != "", 10)
        assert d.find_element("id", "error").text == message
    with server.client() as c:
        assert [j["id"] for j in c.get("/v1/jobs").json()["jobs"]] == before  # nothing submitted


def test_the_docs_page_renders_from_the_service_alone(server, browser):
    """Swagger UI draws the API (OpenAPI 3.1) with every resource loaded from the service: no CDN needed."""
    d = browser
    d.get(server.url + "/docs")
    wait(d, lambda d: "planner service" in d.find_element("css selector", ".swagger-ui .info .title").text, 60)
    wait(d, lambda d: len(d.find_elements("css selector", ".opblock-summary-path")) >= 8, 30)
    paths = {e.get_attribute("data-path") for e in d.find_elements("css selector", ".opblock-summary-path")}
    assert {"/v1/jobs", "/v1/jobs/{job_id}/executions", "/v1/executions/{execution_id}"} <= paths
    loaded = d.execute_script("return performance.getEntriesByType('resource').map(e => e.name)")
    assert loaded and all(u.startswith(server.url + "/") for u in loaded), loaded
    assert not d.find_elements("css selector", ".swagger-ui .errors-wrapper")


def test_a_job_the_robot_cannot_reach_has_run_disabled_with_its_reason(server, browser):
    """The README's REST example (no part frame: the part at the robot's base) planned from the page: done, but Run
    is disabled with the summary's reason, and the API refuses its execution with nothing started."""
    d = browser
    d.get(server.url + "/")
    d.find_element("id", "file").send_keys(str(ROOT / "examples" / "nx_first_pass.cls"))
    from selenium.webdriver.support.ui import Select

    Select(d.find_element("id", "robot")).select_by_visible_text("ur5e")
    d.find_element("id", "submit").click()
    assert until_done(d) == "done", d.find_element("id", "job-error").text
    job_id = d.find_element("id", "job-id").text
    with server.client() as c:
        summary = c.get(f"/v1/jobs/{job_id}").json()["summary"]
        assert summary["executable"] is False and summary["not_executable"]
        wait(d, lambda d: d.find_element("id", "run-reason").text != "", 30)
        assert d.find_element("id", "run-reason").text == "Run is disabled: " + summary["not_executable"]
        assert not d.find_element("id", "execute").is_enabled()
        d.find_element("id", "execute").click()  # a click on the disabled button does nothing
        time.sleep(0.5)
        assert d.find_element("id", "exec-state").text == "" and d.find_element("id", "execute-result").text == ""
        before = _executions(c)
        r = c.post(f"/v1/jobs/{job_id}/executions", json={"robot": "sim", "mode": "program"})
        assert r.status_code == 409 and r.json()["detail"] == f"job {job_id} cannot run on its robot: " \
                                                             f"{summary['not_executable']}"
        assert _executions(c) == before and server.children("planner-exec") == []  # nothing started


@pytest.fixture(scope="module")
def keyed_server(tmp_path_factory):
    from tests.test_service_keys import created

    s = ServiceProcess(tmp_path_factory.mktemp("docs"), workers=1, dev=False)
    key = created(s.keys("create", "--name", "docs", "--role", "planner"))[1]
    s.start()
    yield s, key
    assert s.stop() == 0, s.log.read_text()


def _try_list_jobs(d, previous: str = "") -> tuple[str, str]:
    """Execute GET /v1/jobs from its "Try it out" panel: the (status, body) Swagger UI shows (a body other than
    ``previous``: this call's)."""
    block = d.find_element("id", "operations-jobs-list_jobs")
    block.find_element("css selector", "button.execute").click()
    status = ".live-responses-table tbody tr.response .response-col_status"
    body = ".live-responses-table tbody tr.response .response-col_description pre"

    def answered(_d):
        got = block.find_elements("css selector", body)
        return bool(got) and got[0].text.strip() not in ("", previous)

    wait(d, answered, 30)
    return (block.find_element("css selector", status).text.strip(),
            block.find_element("css selector", body).text)


def test_the_docs_page_authorizes_with_a_key_and_try_it_out_answers_200(keyed_server, browser):
    """/docs with keys required: Authorize takes the key (the schema's X-API-Key scheme) and a "Try it out" call of
    GET /v1/jobs answers 200 with the key's job; without the key the same call is the 401 naming the header."""
    s, key = keyed_server
    with s.client(key) as c:
        job = c.post("/v1/jobs", json={"waypoints": [[0, 0, 0], [0.1, 0, 0], [0.2, 0.05, 0]]}).json()["id"]
    d = browser
    d.get(s.url + "/docs")
    wait(d, lambda d: d.find_elements("id", "operations-jobs-list_jobs"), 60)
    d.find_element("css selector", "#operations-jobs-list_jobs .opblock-summary").click()
    wait(d, lambda d: d.find_elements("css selector", "#operations-jobs-list_jobs .try-out__btn"), 30)
    d.find_element("css selector", "#operations-jobs-list_jobs .try-out__btn").click()
    status, body = _try_list_jobs(d)  # not authorized yet
    assert status == "401" and "X-API-Key" in body, (status, body)
    d.find_element("css selector", ".scheme-container button.authorize").click()
    wait(d, lambda d: d.find_elements("css selector", ".modal-ux .auth-container input"), 30)
    modal = d.find_element("css selector", ".modal-ux")
    assert "X-API-Key" in modal.text and "header" in modal.text
    modal.find_element("css selector", ".auth-container input").send_keys(key)
    modal.find_element("css selector", ".auth-btn-wrapper button.authorize").click()
    wait(d, lambda d: d.find_elements("css selector", ".modal-ux .auth-btn-wrapper button.btn-done"), 30)
    d.find_element("css selector", ".modal-ux .auth-btn-wrapper button.btn-done").click()
    wait(d, lambda d: not d.find_elements("css selector", ".modal-ux"), 30)
    status, body = _try_list_jobs(d, previous=body)
    assert status == "200", (status, body)
    assert [j["id"] for j in json.loads(body)["jobs"]] == [job]
