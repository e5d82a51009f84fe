"""The fast submit path: ``POST /v1/jobs`` with a JSON body answered without the framework's routing, request and
dependency machinery (:class:`FastSubmit`, measured by ``bench/bench_service.py``); the same checks
(:func:`.submit.accept_json`) and the same answer (:func:`created`) as the route (:func:`.routes.jobs.submit`), and a
test keeps its answers (status, body, headers) equal to the route's."""

from __future__ import annotations

import json

from fastapi import HTTPException
from sqlalchemy.exc import InterfaceError, OperationalError

from planner.frontends.service.deps import API, Service, caller
from planner.frontends.service.submit import accept_json


class FastSubmit:
    """``POST /v1/jobs`` with a JSON body, accepted without the framework's routing, request and dependency
    machinery (a quarter of the event loop's CPU for a submit of 100 waypoints: with 20 clients submitting at once,
    every request waits for the others' share). The same :func:`accept_json` as the route; a request it does not
    accept (no valid key, a bad body, another content type) goes to the route with its body replayed, which answers
    it exactly as it answers any request."""

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http" or scope["method"] != "POST" or scope["path"] != SUBMIT_PATH:
            return await self.app(scope, receive, send)
        headers = dict(scope["headers"])
        if not headers.get(b"content-type", b"").lower().startswith(b"application/json"):
            return await self.app(scope, receive, send)
        chunks = []
        while True:
            message = await receive()
            if message["type"] != "http.request":  # the client went away
                return
            chunks.append(message.get("body", b""))
            if not message.get("more_body", False):
                break
        body = b"".join(chunks)
        svc: Service = scope["app"].state.service
        try:
            key = headers.get(b"x-api-key")
            who = caller(svc, None if key is None else key.decode("latin-1"),
                         headers.get(b"authorization", b"").decode("latin-1"))
            job_id = await accept_json(svc, who, body)
        except (HTTPException, OperationalError, InterfaceError):  # (the database away: the route answers 503)
            return await self.app(scope, _replay(body, receive), send)
        content, location = created(job_id)
        answer = json.dumps(content, ensure_ascii=False, allow_nan=False, separators=(",", ":")).encode()
        await send({"type": "http.response.start", "status": 202, "headers": [
            (b"content-length", str(len(answer)).encode()), (b"content-type", b"application/json"),
            (b"location", location.encode())]})
        await send({"type": "http.response.body", "body": answer})


SUBMIT_PATH = f"{API}/jobs"


def created(job_id: str) -> tuple[dict, str]:
    """The answer to an accepted submit, the route's and the fast path's: its JSON (:class:`.schemas.JobCreated`)
    and the job's location."""
    location = f"{SUBMIT_PATH}/{job_id}"
    return {"id": job_id, "state": "queued", "location": location}, location


def _replay(body: bytes, receive):
    """``receive`` that gives ``body`` (already read) first."""
    sent = False

    async def replayed():
        nonlocal sent
        if not sent:
            sent = True
            return {"type": "http.request", "body": body, "more_body": False}
        return await receive()

    return replayed
