"""The service's errors for a user's mistake: 422 with ``detail`` a list of ``{"loc": [...], "msg": ...}`` naming the
field; and :func:`documented`, the 4xx answers a route declares in the OpenAPI schema (every one with the error model
:class:`.schemas.Problem`)."""

from __future__ import annotations

from typing import Any

from fastapi import HTTPException, Request
from fastapi.routing import APIRoute
from pydantic import ValidationError

from planner.frontends.service.auth import KEY_HEADER
from planner.frontends.service.schemas import Problem

#: What each error status means, as every route that can answer it documents it (a route may say more).
ANSWERS = {
    401: f"no valid API key in the {KEY_HEADER} header",
    403: "the key's role may not do this (executions need an operator key)",
    404: "no such job or execution of this key",
    409: "the job or execution is not in a state that allows this",
    413: "request body larger than the service's limit",
    415: "a content type this route does not take",
    422: "a refused input: detail lists each field with its place (loc) and the reason; a body that is not UTF-8 "
         "names the byte offset",
    503: "the job store (database) does not answer; try again after Retry-After seconds",
}


def documented(*codes: int, key: bool = True, **said: str) -> dict[int | str, dict[str, Any]]:
    """The ``responses=`` of a route answering ``codes`` (plus 503, which every route reading the store may answer,
    and 401 for a route that needs a key): each with the error model; ``said`` (``e404="..."``) replaces a status's
    description."""
    out: dict[int | str, dict[str, Any]] = {}
    for code in sorted({503, *codes, *((401,) if key else ())}):
        out[code] = {"model": Problem, "description": said.get(f"e{code}", ANSWERS[code])}
    return out


class Unprocessable(HTTPException):
    """422 naming the field: ``detail`` = [{"loc": [...], "msg": ..., "type": ...}]."""

    def __init__(self, loc: list, msg: str, kind: str = "value_error"):
        super().__init__(422, [{"loc": loc, "msg": msg, "type": kind}])


def utf8_checked(body: bytes, loc: list) -> None:
    """Unprocessable (422) naming the first byte that is not UTF-8 and its offset, if ``body`` is not UTF-8 text."""
    try:
        body.decode("utf-8")
    except UnicodeDecodeError as exc:
        bad = body[exc.start:exc.end]
        raise Unprocessable(loc, f"not UTF-8 text: byte 0x{bad[0]:02x} at offset {exc.start} ({exc.reason}); send "
                                 "JSON as UTF-8", "utf8") from None


def validation_detail(errors: list[dict], prefix: list | None = None) -> list[dict]:
    """A framework's validation errors as the service's 422 detail: loc, msg and type only (the input, possibly huge
    or not JSON, is not echoed)."""
    return [{"loc": (prefix or []) + list(e["loc"]), "msg": e["msg"], "type": e["type"]} for e in errors]


def _validation_detail(exc: ValidationError, prefix: list) -> list[dict]:
    """pydantic errors without the (possibly huge or non-JSON) input values."""
    return [{"loc": prefix + list(e["loc"]), "msg": e["msg"], "type": e["type"]}
            for e in exc.errors(include_url=False, include_context=False, include_input=False)]


class CheckedRoute(APIRoute):
    """A route whose JSON body is checked to be UTF-8 before the framework parses it: a body that is not is a 422
    naming the first bad byte's offset (the framework's own answer was an undocumented 400 without a reason)."""

    def get_route_handler(self):
        handler = super().get_route_handler()

        async def checked(request: Request):
            if request.headers.get("content-type", "").lower().startswith("application/json"):
                utf8_checked(await request.body(), ["body"])  # (the body is kept: the framework reads it again)
            return await handler(request)

        return checked
