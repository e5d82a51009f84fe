"""The page at ``GET /`` in headless Chromium (Debian's chromium and chromium-driver, driven by selenium) against a
real service: paste waypoints, upload a CLSF file for a robot, watch the job to done, see the summary and the plot,
the downloads, a refused input's message; the screenshot is checked to show the plot."""

from __future__ import annotations

import io
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests.test_service_server import ServiceProcess

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMEDRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    robots = {"sim": {"sim": True, "sim_speed": 20, "approach_speed": 2.0, "approach_acceleration": 3.0}}
    s = ServiceProcess(tmp_path_factory.mktemp("page"), workers=1, env={"PLANNER_ROBOTS": json.dumps(robots)}).start()
    yield s
    assert s.stop() == 0, s.log.read_text()


@pytest.fixture(scope="module")
def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    assert Path(CHROMIUM).exists() and Path(CHROMEDRIVER).exists(), \
        "needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)"
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--window-size=1400,1100",
                "--disable-gpu"):
        options.add_argument(arg)
    driver = webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=options)
    yield driver
    driver.quit()


def _executions(client):
    r = client.get("/v1/executions")
    assert r.status_code == 200, r.text
    return r.json()["executions"]


def wait(driver, condition, timeout: float = 90.0):
    from selenium.webdriver.support.ui import WebDriverWait

    return WebDriverWait(driver, timeout, poll_frequency=0.1).until(condition)


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
    d.find_element("id", "execute").click()  # planned without a robot: the API's refusal on the page
    wait(d, lambda d: "planned without a robot model" in d.find_element("id", "execute-result").text)


def test_upload_a_clsf_file_for_a_robot_and_a_refused_input(server, browser):
    d = browser
    d.get(server.url + "/")
    d.find_element("id", "file").send_keys(str(ROOT / "examples" / "nx_first_pass.cls"))
    from selenium.webdriver.support.ui import Select

    Select(d.find_element("id", "robot")).select_by_visible_text("ur5e")
    d.find_element("id", "partframe").send_keys("0.4,0.9965,-0.1,0,0,0")
    d.find_element("id", "submit").click()
    assert until_done(d) == "done", d.find_element("id", "job-error").text
    assert "ur5e: every move reachable" in d.find_element("id", "summary").text
    wait(d, lambda d: len(d.find_elements("id", "download-script")) == 1)
    # run it on the simulated robot (program mode, fast-forward): progress, then the execution report
    wait(d, lambda d: d.find_element("id", "exec-robot").text.strip() == "sim (simulated)", 30)  # from /v1/robots
    d.find_element("id", "execute").click()
    wait(d, lambda d: d.find_element("id", "exec-state").text in ("starting", "running", "done"), 30)
    seen = set()
    wait(d, lambda d: seen.add((d.find_element("id", "exec-state").text,
                                d.find_element("id", "exec-stage").text)) or
         d.find_element("id", "exec-state").text in ("done", "failed", "cancelled"), 120)
    assert d.find_element("id", "exec-state").text == "done", d.find_element("id", "execute-result").text
    assert any(state == "running" and "execute" in stage for state, stage in seen), seen
    report = d.find_element("id", "exec-report").text
    job_id = d.find_element("id", "job-id").text
    with server.client() as c:
        runs = [e for e in _executions(c) if e["job_id"] == job_id]
    assert len(runs) == 1 and runs[0]["state"] == "done"
    assert report.splitlines() == runs[0]["report"]["describe"]
    assert report.startswith("execution (program): ok")
    assert float(d.find_element("id", "exec-progress").get_attribute("value")) == 1.0
    # a refused input: the API's 422 message, naming the field, on the page
    d.find_element("id", "tab-points").click()
    d.find_element("id", "points").send_keys("0, 0, 0\n0, 0, 0\n100, 0, 0")
    d.find_element("id", "submit").click()
    wait(d, lambda d: d.find_element("id", "error").text != "")
    assert d.find_element("id", "error").text == "waypoints: waypoint 1: duplicates waypoint 0 (consecutive points " \
                                                  "must differ)"


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
