"""The fast submit path (planner.frontends.service.fast_submit) answers as the route does: the same requests sent to
a service with it and to one without it (the route answering every submit) get the same status, body (the job's id
aside) and headers. Both are real uvicorn servers on 127.0.0.1, in threads of this process, with API keys."""

from __future__ import annotations

import json
import re
import socket
import threading
import time
from pathlib import Path

import httpx
import pytest

from planner.frontends.service.config import ServiceConfig

#: Headers whose values differ between any two responses (time, server name).
VARYING = {"date", "server"}


class ThreadedService:
    """``create_app(cfg, fast_submit=...)`` under uvicorn on a free loopback port, in a thread."""

    def __init__(self, folder: Path, fast_submit: bool):
        import uvicorn

        from planner.frontends.service.app import create_app

        folder.mkdir(parents=True)
        self.cfg = ServiceConfig(db_url=f"sqlite:///{folder / 'jobs.sqlite'}", data_dir=folder / "data", workers=1,
                                 max_request_bytes=4096)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.bind(("127.0.0.1", 0))
        self.url = f"http://127.0.0.1:{self.sock.getsockname()[1]}"
        self.app = create_app(self.cfg, fast_submit=fast_submit)
        config = uvicorn.Config(self.app, log_level="warning")
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, kwargs={"sockets": [self.sock]}, daemon=True)

    def start(self) -> ThreadedService:
        self.thread.start()
        deadline = time.monotonic() + 60
        while not self.server.started:
            if not self.thread.is_alive() or time.monotonic() > deadline:
                raise AssertionError(f"the service at {self.url} did not start")
            time.sleep(0.05)
        return self

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(30)
        self.sock.close()
        assert not self.thread.is_alive(), "the service did not stop"

    def key(self, role: str = "planner") -> str:
        from planner.frontends.service.auth import create_key
        from planner.frontends.service.store import open_store

        engine, sessions = open_store(self.cfg.db_url)
        try:
            with sessions() as s:
                return create_key(s, "test", role)[1]
        finally:
            engine.dispose()


@pytest.fixture(scope="module")
def services(tmp_path_factory):
    root = tmp_path_factory.mktemp("fast")
    fast = ThreadedService(root / "fast", fast_submit=True).start()
    try:
        route = ThreadedService(root / "route", fast_submit=False).start()
    except BaseException:
        fast.stop()
        raise
    yield fast, route
    fast.stop()
    route.stop()


def _answer(url: str, key: str | None, body: bytes, content_type: str, use_key: str = "bearer") -> tuple:
    """Status, the body with the job's id replaced, and the headers that matter."""
    headers = {"content-type": content_type}
    if key is not None:
        headers["authorization" if use_key == "bearer" else "x-api-key"] = (f"Bearer {key}" if use_key == "bearer"
                                                                            else key)
    r = httpx.post(url + "/v1/jobs", content=body, headers=headers, timeout=30)
    text = r.content
    found = re.search(rb'"id":"([0-9a-f]{32})"', text)
    job_id = found.group(1).decode() if found else None
    if job_id is not None:
        assert r.headers["location"] == f"/v1/jobs/{job_id}" and json.loads(text)["location"] == r.headers["location"]
        text = text.replace(job_id.encode(), b"<id>")
    kept = {k: v.replace(job_id, "<id>") if job_id else v for k, v in r.headers.items() if k not in VARYING}
    if job_id is not None:
        kept["content-length"] = str(len(r.content))  # the same length (ids are 32 digits in both)
    return r.status_code, text, kept


REQUESTS = {  # name: body, content type, key ("good", "bad", None)
    "waypoints": (b'{"waypoints": [[0, 0, 0], [0.1, 0, 0], [0.1, 0.1, 0]]}', "application/json", "good"),
    "settings": (json.dumps({"waypoints": [[0, 0, 0], [0.1, 0, 0], [0.1, 0.1, 0.02]],
                             "settings": {"tolerance": 1e-5, "rate": 250}}).encode(), "application/json", "good"),
    "charset": (b'{"waypoints": [[0, 0, 0], [0.1, 0, 0]]}', "application/json; charset=utf-8", "good"),
    "x-api-key": (b'{"waypoints": [[0, 0, 0], [0.1, 0, 0]]}', "application/json", "x-api-key"),
    "no key": (b'{"waypoints": [[0, 0, 0], [0.1, 0, 0]]}', "application/json", None),
    "bad key": (b'{"waypoints": [[0, 0, 0], [0.1, 0, 0]]}', "application/json", "bad"),
    "not json": (b'{"waypoints": [[0, 0, 0], ', "application/json", "good"),
    "unknown field": (b'{"waypoints": [[0, 0, 0], [1, 0, 0]], "speed": 1}', "application/json", "good"),
    "nan": (b'{"waypoints": [[0, 0, NaN], [1, 0, 0]]}', "application/json", "good"),
    "bad setting": (b'{"waypoints": [[0, 0, 0], [1, 0, 0]], "settings": {"tolerance": -1}}', "application/json",
                    "good"),
    "one waypoint": (b'{"waypoints": [[0, 0, 0]]}', "application/json", "good"),
    "repeated waypoints": (b'{"waypoints": [[0, 0, 0], [0, 0, 0]]}', "application/json", "good"),
    "too large": (b'{"waypoints": [' + b"[0, 0, 0], " * 1000 + b"[1, 0, 0]]}", "application/json", "good"),
    "text": (b"waypoints", "text/plain", "good"),
}


@pytest.mark.parametrize("name", sorted(REQUESTS))
def test_the_fast_path_answers_as_the_route(services, name):
    from planner.frontends.service.fast_submit import FastSubmit

    fast, route = services
    assert [m.cls for m in fast.app.user_middleware].count(FastSubmit) == 1  # the fast path answers one of them,
    assert FastSubmit not in [m.cls for m in route.app.user_middleware]  # the route every request of the other
    body, ctype, key = REQUESTS[name]
    keys = {}
    for svc in services:
        keys[svc.url] = {"good": svc.key(), "x-api-key": svc.key(), "bad": "pk_" + "0" * 40, None: None}[key]
    via = "x-api-key" if key == "x-api-key" else "bearer"
    got = _answer(fast.url, keys[fast.url], body, ctype, via)
    expected = _answer(route.url, keys[route.url], body, ctype, via)
    assert got == expected, f"{name}: fast path {got} != route {expected}"
    if key == "good" and name in ("waypoints", "settings", "charset"):
        assert got[0] == 202 and got[1] == b'{"id":"<id>","state":"queued","location":"/v1/jobs/<id>"}'
