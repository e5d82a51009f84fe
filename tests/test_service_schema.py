"""Schemathesis over the service's whole OpenAPI schema, as its command line runs it, against a real service (uvicorn
on 127.0.0.1, keys required, the simulated robot configured): every operation, every phase (the schema's examples,
coverage of its edges, fuzzing, stateful runs along the links: a job submitted, then read, cancelled, exported,
executed), every check (no 5xx, status codes, content types, headers and bodies as the schema says, schema-violating
requests refused, schema-valid ones accepted, methods and Allow, authentication). Seeded and bounded (20 examples
per operation: under three minutes on two loaded cores).

Where the service's documented meaning differs from what a check assumes, the configuration below says so, each with
its reason; nothing else is excused.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys

from tests.test_service_keys import created
from tests.test_service_server import ServiceProcess

#: The run's configuration (schemathesis.toml).
CONFIG = """
# Planning-bound answers (the first plot starts the drawing process and draws a job of thousands of waypoints).
[checks]
max_response_time = 120

# A schema-valid request the service refuses by what it means, not its shape, with a documented 4xx: a submitted
# file that is no toolpath or settings whose combination the planner refuses (422), a robot name the service does
# not configure (422), an export or execution of a job that is not done or was planned without a robot (409, 422),
# a window of the 3D view's path that is not one (422).
[[operations]]
include-operation-id = "submit"
checks.positive_data_acceptance.expected-statuses = ["2xx", "422"]

[[operations]]
include-operation-id = "create_execution"
checks.positive_data_acceptance.expected-statuses = ["2xx", "404", "409", "422"]

[[operations]]
include-operation-id = "trajectory"
checks.positive_data_acceptance.expected-statuses = ["2xx", "404", "409", "422"]

# the 3D view's detail: a window of job time needs t0 < t1 within the job (422 naming them otherwise)
[[operations]]
include-operation-id = "view_path"
checks.positive_data_acceptance.expected-statuses = ["2xx", "404", "409", "422"]
"""
#: Checks not run: a job's DELETE cancels it and an execution's stops it; the record stays (state cancelled),
#: readable as before (use_after_free expects a 404 after a DELETE).
EXCLUDED = "use_after_free"
#: Examples generated per operation and phase.
MAX_EXAMPLES = 20


def test_schemathesis_over_the_whole_schema_finds_no_failure(tmp_path):
    robots = {"sim": {"sim": True, "sim_speed": 20}}
    s = ServiceProcess(tmp_path / "service", workers=1, dev=False,
                       env={"PLANNER_ROBOTS": json.dumps(robots), "PLANNER_MAX_WAYPOINTS": "2000",
                            "PLANNER_JOB_TIMEOUT": "20"})
    key = created(s.keys("create", "--name", "schemathesis", "--role", "operator"))[1]
    s.start()
    with s.client() as c:
        operations = sum(len(ops) for ops in c.get("/openapi.json").json()["paths"].values())
    assert operations >= 14
    config = tmp_path / "schemathesis.toml"
    config.write_text(CONFIG)
    try:
        run = subprocess.run(
            [sys.executable, "-m", "schemathesis.cli", "--config-file", str(config), "--no-color", "run",
             s.url + "/openapi.json", "--header", f"X-API-Key: {key}", "--checks", "all", "--exclude-checks", EXCLUDED, "--max-examples",
             str(MAX_EXAMPLES), "--seed", "1", "--workers", "1", "--request-timeout", "60", "--no-shrink"],
            capture_output=True, text=True, timeout=900, cwd=tmp_path)
    finally:
        assert s.stop() == 0, s.log.read_text()
    out = run.stdout + run.stderr
    assert run.returncode == 0, out
    assert f"{operations} selected / {operations} total" in out, out  # every operation of the schema
    for phase in ("Examples", "Coverage", "Fuzzing", "Stateful"):
        assert re.search(rf"✅\s+{phase}", out), (phase, out)
    covered = re.search(r"API Links:\s+(\d+) covered / (\d+) selected", out)
    assert covered and int(covered.group(1)) >= 8, out  # the job's links followed: read, cancel, export, execute
