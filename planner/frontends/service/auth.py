"""API keys: created, listed and revoked by ``planner keys``; only the SHA-256 of a key is stored.

A key is ``pk_<id>_<secret>`` (the id names the key in lists and logs; the secret is 32 random bytes). A request
sends it in the ``X-API-Key`` header (:data:`KEY_HEADER`; the OpenAPI scheme :data:`API_KEY` makes ``/docs`` ask for
it; ``Authorization: Bearer <key>`` is accepted too, as before, but not taught). A key belongs to a team
(:mod:`.teams`); roles: ``planner`` submits, reads and cancels the team's jobs, ``operator`` may also run them on the
team's robots. A key never sees another team's jobs (404, as for a job that does not exist).
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
from dataclasses import dataclass

from fastapi.security import APIKeyHeader
from sqlalchemy import select
from sqlalchemy.orm import Session

from planner.errors import PlannerError
from planner.frontends.service.store import DEFAULT_TEAM, DEV_OWNER, ROLES, ApiKey, Team, now

#: The header a request carries its key in: the one the docs, the page and every 401/403 text name.
KEY_HEADER = "X-API-Key"
#: The API's security scheme in the OpenAPI schema (``components.securitySchemes.APIKey``, required by every route
#: under /v1): /docs shows Authorize and its "Try it out" calls send the key. The key itself is checked by the
#: service (``deps.principal``), not by this object (``auto_error=False``).
API_KEY = APIKeyHeader(name=KEY_HEADER, scheme_name="APIKey", auto_error=False,
                       description="an API key from `planner keys create` (pk_...), sent in the X-API-Key header")
#: The 401's text: no key, or one that is not valid (unknown, revoked).
NO_KEY = (f"a valid API key is needed in the {KEY_HEADER} header ({KEY_HEADER}: pk_...; `planner keys create` "
          "makes one)")
#: The 401's ``WWW-Authenticate`` header: the scheme and the header to use.
CHALLENGE = {"WWW-Authenticate": f'APIKey header="{KEY_HEADER}"'}
#: The 403's text: a planner key asked to run (or stop) a job on a robot.
NOT_OPERATOR = (f"the key in {KEY_HEADER} is of the planner role; running a job on a robot (or stopping it) needs a "
                "key of the operator role (`planner keys create --role operator`)")


@dataclass(frozen=True)
class Principal:
    """Who makes a request: the key's id (the owner of the jobs it submits), role and team (whose jobs it sees)."""

    key_id: str
    role: str
    name: str = ""
    team: str = DEFAULT_TEAM


#: Everyone in development mode (PLANNER_DEV_NO_AUTH=1): an operator of the default team (jobs owned by "dev").
DEV_PRINCIPAL = Principal(DEV_OWNER, "operator", "development mode", DEFAULT_TEAM)


def key_hash(key: str) -> str:
    """SHA-256 of a key, hex (keys are 256-bit random secrets: a fast hash is the right one)."""
    return hashlib.sha256(key.encode("utf-8")).hexdigest()


def create_key(session: Session, name: str, role: str, team: str = DEFAULT_TEAM) -> tuple[ApiKey, str]:
    """A new key of ``team`` (stored as its hash) and the key itself, shown once."""
    if role not in ROLES:
        raise PlannerError(f"role must be one of {', '.join(ROLES)}, got {role!r}")
    if not name or len(name) > 200:
        raise PlannerError("a key needs a name of 1..200 characters")
    if session.get(Team, team) is None:
        raise PlannerError(f"--team: no team {team!r} (planner teams create {team}; planner teams list)")
    key_id = secrets.token_hex(4)
    key = f"pk_{key_id}_{secrets.token_urlsafe(32)}"
    row = ApiKey(id=key_id, name=name, role=role, team=team, key_hash=key_hash(key), created_at=now())
    session.add(row)
    session.commit()
    return row, key


def list_keys(session: Session) -> list[ApiKey]:
    return list(session.scalars(select(ApiKey).order_by(ApiKey.created_at)))


def revoke_key(session: Session, key_id: str) -> ApiKey:
    row = session.get(ApiKey, key_id)
    if row is None:
        raise PlannerError(f"no key with id {key_id!r}")
    if row.revoked_at is None:
        row.revoked_at = now()
        session.commit()
    return row


def authenticate(session: Session, key: str | None) -> Principal | None:
    """The principal of a valid, unrevoked key, else None."""
    if not key or not key.startswith("pk_"):
        return None
    digest = key_hash(key)
    row = session.scalars(select(ApiKey).where(ApiKey.key_hash == digest)).first()
    if row is None or row.revoked_at is not None or not hmac.compare_digest(row.key_hash, digest):
        return None
    return Principal(row.id, row.role, row.name, row.team)
