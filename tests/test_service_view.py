"""The page's 3D view in headless Chromium (Debian's chromium and chromium-driver, WebGL by SwiftShader, driven by
selenium) against a real service: the demo job (the NX pass for a UR5e) is drawn, and the screenshot is checked
against the planner's own geometry projected with the page's camera matrices (read from the page): the arm's TCP
within a few pixels of the planned TCP at three times, the path's pixels where the planned path is, the arm's where
its joints are; the slider poses the arm at the planned joints of its time; the view's data route refuses bad
windows with a one-line error."""

from __future__ import annotations

import io
import json
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests import chromium
from tests.chromium import wait
from tests.test_service_server import sim_service

ROOT = Path(__file__).resolve().parents[1]
DEMO = {"robot": "ur5e", "part_frame": [0.4, 0.9965, -0.1, 0.0, 0.0, 0.0], "cut_output": ["standard", 0]}
BACKGROUND = np.array([0xF4, 0xF6, 0xF9])


server = sim_service("view", sim_speed=5)


@pytest.fixture(scope="module")
def browser():
    driver = chromium.start("--use-angle=swiftshader", "--enable-unsafe-swiftshader")
    yield driver
    driver.quit()


@pytest.fixture(scope="module")
def demo(server):
    """The demo job, planned by the service, and the planner's own trajectory of it (planned here alike)."""
    from planner import PlanSettings, plan

    data = (ROOT / "examples" / "nx_first_pass.cls").read_bytes()
    with server.client() as c:
        r = c.post("/v1/jobs", files={"file": ("nx_first_pass.cls", data)}, data={"settings": json.dumps(DEMO)})
        assert r.status_code == 202, r.text
        job_id = r.json()["id"]
        deadline = time.monotonic() + 120
        while (v := c.get(f"/v1/jobs/{job_id}").json())["state"] not in ("done", "failed"):
            assert time.monotonic() < deadline, v
            time.sleep(0.2)
    assert v["state"] == "done", v
    job = plan(ROOT / "examples" / "nx_first_pass.cls", PlanSettings.from_dict(DEMO))
    return job_id, job, job.trajectory().collect()


def open_view(d, server, job_id):
    d.get(server.url + "/")
    wait(d, lambda d: d.execute_script("return !!window.view3d"))
    wait(d, lambda d: d.find_elements("css selector", "#jobs tr.job"))
    d.find_element("css selector", "#jobs tr.job").click()
    wait(d, lambda d: d.execute_script("const s = window.view3d.state; return window.view3d.jobId === arguments[0] "
                                       "&& s.firstFrameMs !== null", job_id))
    d.execute_script("document.getElementById('view3d').scrollIntoView()")


def frame_at(d, t: float):
    """Pose the view at job time t (the slider, as a person moves it) and return the screenshot (RGB array, CSS
    pixels) and the camera's matrices once that frame is drawn."""
    n = d.execute_script("const n = window.view3d.state.frames; "
                         "const s = document.querySelector('#view3d [data-v=slider]'); s.value = arguments[0]; "
                         "s.dispatchEvent(new Event('input')); return n;", t)
    wait(d, lambda d: d.execute_script("return window.view3d.state.frames") > n, 10)
    cam = d.execute_script("return window.view3d.cameraMatrices()")
    shot = Image.open(io.BytesIO(d.get_screenshot_as_png())).convert("RGB")
    scale = shot.width / d.execute_script("return window.innerWidth")
    if scale != 1:
        shot = shot.resize((round(shot.width / scale), round(shot.height / scale)))
    return np.asarray(shot).astype(int), cam


def project(cam, xyz):
    """Pixels (n, 2) of base-frame points (n, 3) through the page's camera (column-major 4x4 matrices)."""
    P = np.array(cam["projection"]).reshape(4, 4).T
    V = np.array(cam["view"]).reshape(4, 4).T
    h = np.c_[xyz, np.ones(len(xyz))] @ (P @ V).T
    ndc = h[:, :3] / h[:, 3:]
    box = cam["canvas"]
    return np.c_[box["x"] + (ndc[:, 0] + 1) / 2 * box["width"], box["y"] + (1 - ndc[:, 1]) / 2 * box["height"]]


def near(img, xy, r: int, test) -> bool:
    x, y = int(round(xy[0])), int(round(xy[1]))
    patch = img[max(y - r, 0):y + r + 1, max(x - r, 0):x + r + 1]
    return bool(test(patch.reshape(-1, 3)).any())


def test_the_view_draws_the_demo_job_where_the_planner_puts_it(server, browser, demo, tmp_path):
    from planner.kinematics.forward import link_frames

    job_id, job, traj = demo
    d = browser
    open_view(d, server, job_id)
    state = d.execute_script("return window.view3d.state")
    assert state["bytes"] < 50_000, state  # the demo's scene: a few kB
    rate = float(job.settings.rate)
    duration = float(traj.times[-1])
    for t in (0.1 * duration, 0.5 * duration, 0.9 * duration):
        img, cam = frame_at(d, t)
        Image.fromarray(img.astype(np.uint8)).save(tmp_path / f"view-{t:.1f}.png")
        k = int(round(t * rate))
        # the arm's TCP (the magenta sphere drawn over everything) within 3 px of the planned TCP
        tcp = project(cam, traj.poses[k:k + 1, :3])[0]
        magenta = (np.abs(img - [255, 0, 255]).sum(axis=2) < 60)
        ys, xs = np.nonzero(magenta)
        assert xs.size > 10, f"t = {t:.2f} s: no TCP marker drawn"
        centre = np.array([xs.mean(), ys.mean()])
        assert np.linalg.norm(centre - tcp) < 3.0, (t, centre, tcp)
        # the arm: drawn (not the background) where the planner's joint origins (shoulder .. wrist 2) project
        origins = link_frames(job.settings.robot, traj.joints[k])[1:5, :3, 3]
        for xy in project(cam, origins):
            assert near(img, xy, 2, lambda p: np.abs(p - BACKGROUND).sum(axis=1) > 60), (t, xy)
        # the path: a coloured pixel (the pass's colour, the rapid's, a tool axis) within 3 px of 90 % of the
        # planned path's samples that are not behind the arm's TCP marker
        pts = project(cam, traj.poses[::200, :3])
        inside = [p for p in pts if np.linalg.norm(p - tcp) > 15]

        def coloured(p):
            return (p.max(axis=1) - p.min(axis=1)) > 80

        hits = [near(img, p, 3, coloured) for p in inside]
        assert np.mean(hits) > 0.9, f"t = {t:.2f} s: path drawn at only {np.mean(hits):.0%} of its samples"


def test_the_slider_poses_the_arm_at_the_planned_joints_of_its_time(server, browser, demo):
    job_id, job, traj = demo
    d = browser
    open_view(d, server, job_id)
    with server.client() as c:
        scene = c.get(f"/v1/jobs/{job_id}/view", params={"pixels": 1000}).json()
    bound = scene["path"]["tolerance"] / scene["robot"]["reach"] + 1e-5  # rad: the thinning's bound (float32)
    rng = np.random.default_rng(7)
    for t in rng.uniform(0.0, float(traj.times[-1]), 6):
        frame_at(d, float(t))
        q_page = np.array(d.execute_script("return window.view3d.state.q"))
        i = min(int(t * job.settings.rate), len(traj.times) - 2)
        w = (t - traj.times[i]) / (traj.times[i + 1] - traj.times[i])
        q_plan = traj.joints[i] * (1 - w) + traj.joints[i + 1] * w
        assert np.abs(q_page - q_plan).max() < bound, (t, q_page, q_plan, bound)
        assert d.find_element("css selector", "#view3d [data-v=time]").text.startswith(f"{t:.3f} s")


def test_the_view_data_refuses_bad_windows_and_serves_detail(server, demo):
    job_id, job, traj = demo
    with server.client() as c:
        r = c.get(f"/v1/jobs/{job_id}/view/path", params={"t0": 5, "t1": 1})
        assert r.status_code == 422 and r.json()["detail"][0]["msg"] == \
            "the window needs t0 < t1, got t0 = 5.0 s, t1 = 1.0 s"
        for bad in ("nan", "0", "1"):  # the schema's bounds [1e-5, 0.1] m, naming the parameter
            r = c.get(f"/v1/jobs/{job_id}/view", params={"tolerance": bad})
            assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["query", "tolerance"], r.text
        coarse = c.get(f"/v1/jobs/{job_id}/view", params={"tolerance": 2e-3}).json()["path"]
        fine = c.get(f"/v1/jobs/{job_id}/view/path", params={"t0": 10, "t1": 20, "tolerance": 1e-5}).json()["path"]
        assert c.get("/view3d/../routes/view.py").status_code == 404
        assert c.get(f"/v1/jobs/{'0' * 32}/view").status_code == 404
    import base64

    t = np.frombuffer(base64.b64decode(fine["t"]), "<f8")
    xyz = np.frombuffer(base64.b64decode(fine["xyz"]), "<f4").reshape(-1, 3)
    assert t[0] <= 10 and t[-1] >= 20 and t.size > 2
    # every planned sample of the window within the tolerance of the detail's linear interpolation in time
    sel = (traj.times >= t[0]) & (traj.times <= t[-1])
    interp = np.c_[[np.interp(traj.times[sel], t, xyz[:, k]) for k in range(3)]].T
    assert np.linalg.norm(interp - traj.poses[sel, :3], axis=1).max() < 1e-5 + 1e-6
    assert coarse["n"] < fine["n"] * 3 + 20


def test_a_run_on_the_simulated_robot_is_shown_live(server, browser, demo):
    """The execution's recorded joint states reach the page by Server-Sent Events at 60 Hz of job time; the page's
    actual arm shows them (its joints within 0.01 rad of the recording's at the same job time) and its TCP trace
    grows; the stream ends with the execution's state."""
    job_id, job, traj = demo
    d = browser
    open_view(d, server, job_id)
    wait(d, lambda d: d.find_element("id", "exec-robot").text.strip().startswith("sim"), 30)
    d.find_element("id", "execute").click()
    seen = []
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline:
        s = d.execute_script("return window.view3d.state")
        if s["liveT"] is not None and s["liveQ"] is not None:
            seen.append((s["liveT"], s["liveQ"]))
        if d.find_element("id", "exec-state").text in ("done", "failed", "cancelled"):
            break
        time.sleep(0.25)
    assert d.find_element("id", "exec-state").text == "done", d.find_element("id", "execute-result").text
    end = time.monotonic() + 30
    while "execution done" not in (text := d.find_element("css selector", "#view3d [data-v=live]").text):
        assert time.monotonic() < end, (text, d.execute_script("return window.view3d.state"))
        time.sleep(0.2)
    assert len(seen) >= 5, seen
    with server.client() as c:
        execution = [e for e in c.get("/v1/executions").json()["executions"] if e["job_id"] == job_id][0]
        with c.stream("GET", f"/v1/executions/{execution['id']}/live") as r:
            assert r.headers["content-type"].startswith("text/event-stream")
            rows = []
            for line in r.iter_lines():
                if line.startswith("data: [") and "[" in line:
                    rows += json.loads(line[6:])
                if line == "event: end":
                    break
    t = np.array([r[0] for r in rows])
    assert t.size > 0.9 * 60 * traj.times[-1] and np.all(np.diff(t) > 0)
    assert np.median(np.diff(t)) <= 1 / 30 + 1e-9  # at least 30 joint states per second of the run
    assert d.execute_script("return window.view3d.traceN") > 100  # the actual TCP trace drawn
    # what the page showed: the recording's joint states of the same job time (the stream's rows)
    by_t = {round(r[0], 6): np.array(r[1:7]) for r in rows}
    for t, q in seen:
        assert round(t, 6) in by_t, t
        assert np.abs(np.array(q) - by_t[round(t, 6)]).max() < 0.01, (t, q, by_t[round(t, 6)])
