"""The API's surface on a real service (uvicorn on 127.0.0.1, keys required): the OpenAPI schema declares the key
scheme (X-API-Key) on every /v1 operation and documents every error answer with the one error model; 401 and 403
name the header the docs teach (Bearer still accepted); OPTIONS and 405 list every method of a path; a body that is
not UTF-8 is a 422 naming the byte offset; cursors, limits and ids of any size are 4xx in one line."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from tests.test_service_keys import created
from tests.test_service_server import ServiceProcess

PATH = {"waypoints": [[0, 0, 0], [0.1, 0, 0], [0.2, 0.05, 0]]}
INT64_MAX = 2**63 - 1


@pytest.fixture(scope="module")
def keyed(tmp_path_factory):
    robots = {"sim": {"sim": True, "sim_speed": 20}}
    s = ServiceProcess(tmp_path_factory.mktemp("surface"), workers=1, dev=False,
                       env={"PLANNER_ROBOTS": json.dumps(robots)})
    keys = {name: created(s.keys("create", "--name", name, "--role", role))[1]
            for name, role in (("cam", "planner"), ("cell", "operator"))}
    s.start()
    yield s, keys
    assert s.stop() == 0, s.log.read_text()


def _schema(s: ServiceProcess) -> dict:
    with s.client() as c:
        r = c.get("/openapi.json")
    assert r.status_code == 200
    return r.json()


def test_the_schema_declares_the_key_scheme_and_every_error_answer(keyed):
    s, _ = keyed
    spec = _schema(s)
    assert spec["components"]["securitySchemes"] == {"APIKey": {
        "type": "apiKey", "in": "header", "name": "X-API-Key",
        "description": "an API key from `planner keys create` (pk_...), sent in the X-API-Key header"}}
    operations = [(m.upper(), p, op) for p, ops in spec["paths"].items() for m, op in ops.items()]
    assert len(operations) >= 13
    for method, path, op in operations:
        codes = {int(c) for c in op["responses"]}
        errors = {c for c in codes if c >= 400}
        assert 503 in errors, (method, path)
        if path.startswith("/v1/"):
            assert op.get("security") == [{"APIKey": []}], (method, path)
            assert 401 in errors, (method, path)
        else:
            assert "security" not in op and 401 not in errors, (method, path)
        if "{" in path:
            assert 404 in errors, (method, path)
        for code in errors:
            answer = op["responses"][str(code)]
            assert answer["description"], (method, path, code)
            if code < 500 or path != "/metrics":
                schema = answer["content"]["application/json"]["schema"]
                assert schema == {"$ref": "#/components/schemas/Problem"}, (method, path, code)
    assert "HTTPValidationError" not in spec["components"]["schemas"]
    submit = spec["paths"]["/v1/jobs"]["post"]["responses"]
    assert {"401", "413", "415", "422"} <= set(submit)
    run = spec["paths"]["/v1/jobs/{job_id}/executions"]["post"]["responses"]
    assert {"401", "403", "404", "409", "422"} <= set(run)
    assert "not_executable" in run["409"]["description"]


def test_401_and_403_name_the_header_and_bearer_still_works(keyed):
    s, keys = keyed
    with s.client() as c:
        for method, path in (("GET", "/v1/jobs"), ("POST", "/v1/jobs"), ("GET", "/v1/robots"),
                             ("GET", "/v1/executions/" + "0" * 32)):
            r = c.request(method, path, json=PATH if method == "POST" else None)
            assert r.status_code == 401, (method, path, r.text)
            assert r.json()["detail"] == ("a valid API key is needed in the X-API-Key header (X-API-Key: pk_...; "
                                          "`planner keys create` makes one)")
            assert r.headers["www-authenticate"] == 'APIKey header="X-API-Key"'
    with s.client(keys["cam"]) as c:  # the header the docs teach
        job = c.post("/v1/jobs", json=PATH).json()["id"]
        r = c.post(f"/v1/jobs/{job}/executions", json={"robot": "sim"})
        assert r.status_code == 403
        assert r.json()["detail"].startswith("the key in X-API-Key is of the planner role; running a job on a robot")
    with s.client() as c:  # Authorization: Bearer, as accepted before, still is (not taught)
        r = c.get(f"/v1/jobs/{job}", headers={"Authorization": f"Bearer {keys['cam']}"})
        assert r.status_code == 200 and r.json()["id"] == job


def test_options_and_405_list_every_method_of_a_path(keyed):
    s, keys = keyed
    with s.client(keys["cam"]) as c:
        job = c.post("/v1/jobs", json=PATH).json()["id"]
        expected = {f"/v1/jobs/{job}": "DELETE, GET, OPTIONS", "/v1/jobs": "GET, OPTIONS, POST",
                    f"/v1/jobs/{job}/executions": "OPTIONS, POST", f"/v1/executions/{'1' * 32}": "DELETE, GET, OPTIONS",
                    "/v1/robots": "GET, OPTIONS", "/healthz": "GET, OPTIONS"}
        for path, allow in expected.items():
            r = c.options(path)
            assert (r.status_code, r.headers.get("allow")) == (204, allow), path
            r = c.put(path)
            assert (r.status_code, r.headers.get("allow")) == (405, allow), path
        # the methods listed are the ones that work: DELETE on a job is its cancel (409 once it has ended)
        assert c.delete(f"/v1/jobs/{job}").status_code in (200, 409)
        assert c.options("/v1/nothing-here").status_code == 404


def test_a_body_that_is_not_utf8_is_a_422_naming_the_byte_offset(keyed):
    s, keys = keyed
    with s.client(keys["cell"]) as c:
        job = c.post("/v1/jobs", json=PATH).json()["id"]
        for path, body in (("/v1/jobs", b'{"waypoints": [[0, 0, 0], [1, 0, 0]], "x": "\xff"}'),
                           (f"/v1/jobs/{job}/executions", b'{"robot": "s\xc3\x28"}')):
            r = c.post(path, content=body, headers={"Content-Type": "application/json"})
            assert r.status_code == 422, (path, r.text)
            [error] = r.json()["detail"]
            offset = body.index(b"\xff") if b"\xff" in body else body.index(b"\xc3")
            assert error["loc"] == ["body"] and error["type"] == "utf8"
            assert error["msg"].startswith(f"not UTF-8 text: byte 0x{body[offset]:02x} at offset {offset} ")
        # a toolpath file that is not text: the reader's refusal naming the file (multipart carries bytes)
        r = c.post("/v1/jobs", files={"file": ("part.cls", b"\xff\xfe\x00garbage\x81\n")})
        assert r.status_code == 422 and r.json()["detail"][0]["loc"][:2] == ["body", "file"], r.text


@pytest.mark.parametrize("query, field", [
    (f"cursor={INT64_MAX + 1}", "cursor"), (f"cursor={10**400}", "cursor"), ("cursor=-1", "cursor"),
    ("cursor=1e3", "cursor"), (f"limit={10**30}", "limit"), ("limit=0", "limit"), ("limit=-5", "limit"),
    ("limit=x", "limit"),
])
def test_cursors_and_limits_of_any_size_are_422(keyed, query, field):
    s, keys = keyed
    with s.client(keys["cam"]) as c:
        r = c.get(f"/v1/jobs?{query}")
        assert r.status_code == 422, r.text
        assert [e["loc"] for e in r.json()["detail"]] == [["query", field]]
        assert "input" not in r.json()["detail"][0]  # the input is not echoed
        if field == "limit":
            assert c.get(f"/v1/executions?{query}").status_code == 422


def test_the_largest_cursor_is_an_empty_page_and_ids_of_any_shape_are_404(keyed):
    s, keys = keyed
    with s.client(keys["cam"]) as c:
        r = c.get(f"/v1/jobs?cursor={INT64_MAX}")
        assert r.status_code == 200 and r.json()["next_cursor"] is None
        for job_id in ("0" * 32, "x" * 5000, "%00", "..", "' or 1=1 --", str(10**400)):
            for path in (f"/v1/jobs/{job_id}", f"/v1/jobs/{job_id}/plot.png", f"/v1/executions/{job_id}"):
                r = c.get(path)
                assert r.status_code == 404, (path[:80], r.status_code)
                detail = r.json()["detail"]
                assert "\n" not in detail and len(detail) < 120, detail


@pytest.mark.parametrize("settings, loc", [
    ({"feed": True}, ["body", "settings", "feed"]), ({"passes": [False]}, ["body", "settings", "passes"]),
    ({"feed": "0.05"}, ["body", "settings", "feed"]), ({"passes": [INT64_MAX + 1]}, ["body", "settings", "passes"]),
])
def test_true_false_strings_and_huge_integers_are_not_numbers(keyed, settings, loc):
    s, keys = keyed
    with s.client(keys["cam"]) as c:
        r = c.post("/v1/jobs", json={**PATH, "settings": settings})
        assert r.status_code == 422, r.text
        assert r.json()["detail"][0]["loc"][:3] == loc, r.text


def test_planning_progress_counts_passes_planned_of_passes(keyed):
    s, keys = keyed
    src = Path(__file__).parent / "data" / "nx_clsf_ust_a2_excerpt.cls"
    with s.client(keys["cam"]) as c:
        # for a UR5e (its reach checked too: about a second of planning on a quiet machine, so that progress is
        # written while it plans; a job shorter than 0.5 s writes none)
        robot = {"robot": "ur5e", "part_frame": [0.4, 0.9965, -0.1, 0.0, 0.0, 0.0]}
        job = c.post("/v1/jobs", files={"file": (src.name, src.read_bytes())},
                     data={"settings": json.dumps(robot)}).json()["id"]
        seen = []
        while (v := c.get(f"/v1/jobs/{job}").json())["state"] in ("queued", "running"):
            seen.append(v["progress"])
            time.sleep(0.03)
    assert v["state"] == "done", v
    n = v["summary"]["passes"]
    assert n == 33
    assert v["progress"] == {"stage": "done", "done": n, "total": n, "unit": "passes", "pass": None, "line": None,
                             "text": f"{n} passes planned"}
    counting = [p for p in seen if p["unit"] == "passes"]
    assert counting, seen  # (written every 0.5 s while it plans: a few seconds here)
    assert all(p["total"] == n and 0 <= p["done"] <= n for p in counting), counting
    assert {p["stage"] for p in counting} <= {"fit", "plan", "place", "reach", "done"}, counting
    for p in counting:
        if p["stage"] in ("place", "reach"):
            what = {"place": "placing the part for the robot", "reach": "checking the robot's reach"}[p["stage"]]
            assert p["text"] == f"{what} ({n} passes)", p
        elif p["stage"] != "done":
            what = {"fit": "fitting the passes", "plan": "planning tool frames and time laws"}[p["stage"]]
            assert p["text"] == f"{what}: {p['done']:g} of {n} passes"
    assert all(p["text"] in ("waiting for a worker", "starting: reading the input") for p in seen if not p["unit"])
    assert not any(p["total"] == 0 and p["stage"] == "done" for p in seen)  # never "done 0/0"
