"""The service's errors for a user's mistake: 422 with ``detail`` a list of ``{"loc": [...], "msg": ...}`` naming the
field."""

from __future__ import annotations

from fastapi import HTTPException
from pydantic import ValidationError


class Unprocessable(HTTPException):
    """422 naming the field: ``detail`` = [{"loc": [...], "msg": ..., "type": ...}]."""

    def __init__(self, loc: list, msg: str, kind: str = "value_error"):
        super().__init__(422, [{"loc": loc, "msg": msg, "type": kind}])


def _validation_detail(exc: ValidationError, prefix: list) -> list[dict]:
    """pydantic errors without the (possibly huge or non-JSON) input values."""
    return [{"loc": prefix + list(e["loc"]), "msg": e["msg"], "type": e["type"]}
            for e in exc.errors(include_url=False, include_context=False, include_input=False)]
