"""docker/Dockerfile built and docker/compose.yaml run on a real Docker engine (marker ``docker``: ``./run test`` runs
these last, on their own, after starting dockerd when none answers).

No container registry is reachable here: the image is built FROM a stand-in for python:3.11-slim made from Debian's
packages (tests/docker_images.py, built once per machine). The single-machine stack: the healthcheck turns healthy,
the service is published on the host's loopback only and wants a key, a key is created with ``compose exec``, the
demo job is planned through the published port (the same trajectory as this checkout's CLI) and executed on the
simulated "cell" robot of the stack; the job and the key outlive a restart of the service, which still reaches the
cell; ``down`` leaves no container, network or volume behind. Compose is Debian's docker-compose 1.29 when
installed, else Compose v2.
"""

from __future__ import annotations

import json
import time

import httpx
import numpy as np
import pytest

from planner.frontends.cli.main import DEMO_PART_FRAME
from tests.compose_stack import DOCKER, ComposeStack, free_port, free_subnet, planner_image, print_times
from tests.docker_images import PYTHON, ROOT, docker, run
from tests.test_service_executions import wait_execution
from tests.test_service_jobs import cli_outputs, cli_settings
from tests.test_service_server import wait_state

pytestmark = pytest.mark.docker

DEMO = ROOT / "examples" / "nx_first_pass.cls"
#: The demo pass for the stack's ur5e at 4x its feed (16 s of motion), outputs on standard[0] while cutting.
OPTIONS = ["--robot", "ur5e", "--part-frame", DEMO_PART_FRAME, "--feed-override", "4", "--cut-output", "standard:0"]
#: Seconds each step took in this session (printed at the end of the module, for the README's figures).
TIMES: dict[str, float] = {}


@pytest.fixture(scope="module", autouse=True)
def report_times(request):
    yield
    print_times(request.config, "docker", TIMES)


@pytest.fixture(scope="module")
def image() -> str:
    """The planner's image built by Compose from docker/compose.yaml's build section, FROM the local stand-in."""
    return planner_image(TIMES)


def test_the_image_builds_from_the_debian_stand_in_and_carries_the_service(image):
    config = json.loads(docker("image", "inspect", image))[0]["Config"]
    assert config["User"] == "planner"  # never root
    assert "/healthz" in " ".join(config["Healthcheck"]["Test"])
    assert "8000/tcp" in config["ExposedPorts"] and "/data" in config["Volumes"]
    assert config["Entrypoint"] == ["python", "-m", "planner.frontends.service"]
    probe = ("import sys, planner, psycopg, planner.curves._hermite_member as m, planner.cam._spin_search as g; "
             "print(sys.version_info[:2] == (3, 11), planner.__file__, m.__file__, g.__file__)")
    same, package, member, search = docker("run", "--rm", "--entrypoint", "python", image, "-c", probe).split()
    # Python 3.11 of the base, the package installed from the wheel (not a source folder), the compiled member rule
    # and grid search
    assert same == "True" and "/site-packages/planner/" in package, package
    assert member.endswith(".so") and search.endswith(".so"), (member, search)
    # the compiler stayed in the wheel's stage
    no_cc = run(["docker", "run", "--rm", "--entrypoint", "sh", image, "-c", "command -v gcc || command -v cc"],
                timeout=120, what="docker run", check=False)
    assert no_cc.returncode != 0 and not no_cc.stdout.strip(), no_cc.stdout


def _trajectory(csv: bytes) -> np.ndarray:
    rows = [line.split(",") for line in csv.decode().splitlines() if line and not line.startswith(("#", "t"))]
    return np.array(rows, dtype=float)


def _execute_on_the_cell(client: httpx.Client, job: dict, stack: ComposeStack) -> None:
    """The done ``job`` executed as a program on the robot "cell": done, following the plan."""
    r = client.post(f"/v1/jobs/{job['id']}/executions", json={"robot": "cell", "mode": "program"})
    assert r.status_code == 202, r.text
    view = wait_execution(client, r.json()["id"], timeout=300)
    assert view["state"] == "done", f"execution {view['state']}: {view['error']}\n{view}\n{stack.logs()}"
    rep = view["report"]
    assert rep["ok"] and rep["failure"] is None and rep["mode"] == "program"
    assert 0.0 < rep["max_path_error_m"] < 0.2e-3, rep["describe"]
    assert rep["io_switches_planned"] == rep["io_switches_made"] == 2
    assert rep["planned_duration_s"] == pytest.approx(job["summary"]["duration_s"], abs=0.01)
    assert 0.95 * rep["planned_duration_s"] <= rep["duration_s"] <= 1.1 * rep["planned_duration_s"]


def test_single_machine_stack_plans_and_executes_on_the_simulated_cell(image, tmp_path):
    port = free_port()
    subnet, robot = free_subnet()
    stack = ComposeStack(DOCKER / "compose.yaml", {"PLANNER_IMAGE": image, "PLANNER_PORT": str(port),
                                                   "PLANNER_BASE_IMAGE": PYTHON, "PLANNER_CELL_SUBNET": subnet,
                                                   "PLANNER_CELL_ROBOT": robot})
    url = f"http://127.0.0.1:{port}"
    try:
        t0 = time.monotonic()
        stack.compose("up", "--detach", "--no-build")
        stack.wait_healthy("planner", 180)
        TIMES["single stack up to healthy"] = time.monotonic() - t0
        # published on the host's loopback only; keys required (no dev mode)
        bindings = stack.inspect("planner")["NetworkSettings"]["Ports"]["8000/tcp"]
        assert bindings == [{"HostIp": "127.0.0.1", "HostPort": str(port)}]
        assert httpx.get(url + "/v1/jobs", timeout=30).status_code == 401
        out = stack.exec("planner", "python", "-m", "planner.frontends.service", "keys", "create", "--name",
                         "docker test", "--role", "operator")
        key = out.split("key ")[1].split()[0]
        with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {key}"}, timeout=60) as c:
            assert sorted(r["name"] for r in c.get("/v1/robots").json()["robots"]) == ["cell", "sim"]
            with open(DEMO, "rb") as f:
                r = c.post("/v1/jobs", files={"file": (DEMO.name, f)},
                           data={"settings": json.dumps(cli_settings(*OPTIONS))})
            assert r.status_code == 202, r.text
            job_id = r.json()["id"]
            view = wait_state(c, job_id, timeout=180)
            assert view["state"] == "done", view["error"]
            # the image plans what this checkout plans: the CLI's trajectory, row for row, to a unit of the last
            # printed digit (the image's numpy and scipy are the newest wheels, this checkout's may be older)
            got = c.get(f"/v1/jobs/{job_id}/trajectory")
            assert got.status_code == 200, got.text
            expected = cli_outputs(tmp_path, DEMO, OPTIONS, ["csv"])["csv"]
            a, b = _trajectory(got.content), _trajectory(expected)
            assert a.shape == b.shape and a.shape[0] > 1000, (a.shape, b.shape)
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-6)
            # executed on the stack's simulated ur5e ("cell", its own address on the cell network)
            t0 = time.monotonic()
            _execute_on_the_cell(c, view, stack)
            TIMES["execution on the cell"] = time.monotonic() - t0
        # the job and the key are in the volume: a restarted service still has both, and still reaches the cell
        t0 = time.monotonic()
        stack.compose("restart", "planner")
        stack.wait_healthy("planner", 180)
        TIMES["restart to healthy"] = time.monotonic() - t0
        with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {key}"}, timeout=60) as c:
            again = c.get(f"/v1/jobs/{job_id}")
            assert again.status_code == 200 and again.json()["state"] == "done", again.text
            assert c.get(f"/v1/jobs/{job_id}/trajectory").content == got.content
            _execute_on_the_cell(c, view, stack)
    finally:
        t0 = time.monotonic()
        stack.down()
        TIMES["single stack down"] = time.monotonic() - t0
    assert stack.resources() == {"containers": [], "networks": [], "volumes": []}
