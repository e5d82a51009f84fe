"""Teams: created, listed, given robots and deleted by ``planner teams``.

A key belongs to one team (``planner keys create --team``); a job and its executions belong to the team of the key
that submitted the job. A team's keys see and manage its jobs (the ``planner`` role) and, with the ``operator``
role, run them on the team's robots: names of robots the service is configured with (``PLANNER_ROBOTS``, the one
robot configuration), or every configured robot. Another team's job or execution is a 404, exactly like one that
does not exist. The "default" team holds everything made before teams and keys made without ``--team``.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from dataclasses import dataclass

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from planner.errors import PlannerError
from planner.frontends.service.config import RobotConfig
from planner.frontends.service.store import DEFAULT_TEAM, ApiKey, Job, Team, now

#: A team's name: 1..32 of A-Z a-z 0-9 _ - (as a robot's).
TEAM_NAME = re.compile(r"^[A-Za-z0-9_-]{1,32}$")
_ROBOT_NAME = TEAM_NAME
#: ``--robots`` for every configured robot.
ALL = "all"


@dataclass(frozen=True)
class TeamInfo:
    """A team as ``planner teams list`` shows it: its robots (None: every configured robot), its active keys and its
    jobs."""

    name: str
    robots: tuple[str, ...] | None
    keys: int
    jobs: int
    created_at: float


def parse_robots(text: str) -> tuple[str, ...] | None:
    """``--robots``: ``all`` (None: every configured robot), ``none`` or empty (no robot), or names separated by
    commas."""
    text = text.strip()
    if text == ALL:
        return None
    if text in ("", "none"):
        return ()
    names = tuple(dict.fromkeys(n.strip() for n in text.split(",")))
    for n in names:
        if not _ROBOT_NAME.match(n):
            raise PlannerError(f"--robots: {n!r} is not a robot name (1..32 of A-Z a-z 0-9 _ -); give names "
                               f"separated by commas, {ALL!r} or 'none'")
    return names


def robots_text(robots: tuple[str, ...] | None) -> str:
    """A team's robots as ``planner teams list`` prints them."""
    if robots is None:
        return ALL
    return ",".join(robots) if robots else "none"


def _stored(robots: tuple[str, ...] | None) -> str | None:
    return None if robots is None else json.dumps(list(robots))


def _loaded(text: str | None) -> tuple[str, ...] | None:
    return None if text is None else tuple(json.loads(text))


def create_team(session: Session, name: str, robots: tuple[str, ...] | None = ()) -> Team:
    """A new team (with no robot unless given)."""
    if not TEAM_NAME.match(name):
        raise PlannerError(f"a team's name is 1..32 of A-Z a-z 0-9 _ -, got {name!r}")
    if session.get(Team, name) is not None:
        raise PlannerError(f"team {name!r} exists already")
    row = Team(name=name, robots=_stored(robots), created_at=now())
    session.add(row)
    session.commit()
    return row


def _team(session: Session, name: str) -> Team:
    row = session.get(Team, name)
    if row is None:
        raise PlannerError(f"no team {name!r} (planner teams list)")
    return row


def set_robots(session: Session, name: str, robots: tuple[str, ...] | None) -> Team:
    """The team's robots from now on (the next execution request reads them)."""
    row = _team(session, name)
    row.robots = _stored(robots)
    session.commit()
    return row


def delete_team(session: Session, name: str) -> None:
    """Delete a team that has no active key and no job; never the default team."""
    row = _team(session, name)
    if name == DEFAULT_TEAM:
        raise PlannerError(f"the {DEFAULT_TEAM!r} team cannot be deleted (keys made without --team join it)")
    keys = session.scalar(select(func.count()).select_from(ApiKey).where(ApiKey.team == name,
                                                                          ApiKey.revoked_at.is_(None)))
    jobs = session.scalar(select(func.count()).select_from(Job).where(Job.team == name))
    if keys or jobs:
        raise PlannerError(f"team {name!r} still has {keys} active key(s) and {jobs} job(s); a team is deleted once "
                           "it has neither (planner keys revoke ID)")
    session.delete(row)
    session.commit()


def list_teams(session: Session) -> list[TeamInfo]:
    """Every team, oldest first, with its robots, active keys and jobs."""
    keys = dict(session.execute(select(ApiKey.team, func.count()).where(ApiKey.revoked_at.is_(None))
                                .group_by(ApiKey.team)).all())
    jobs = dict(session.execute(select(Job.team, func.count()).group_by(Job.team)).all())
    return [TeamInfo(t.name, _loaded(t.robots), keys.get(t.name, 0), jobs.get(t.name, 0), t.created_at)
            for t in session.scalars(select(Team).order_by(Team.created_at, Team.name))]


def team_robots(session: Session, team: str, configured: Sequence[RobotConfig]) -> tuple[RobotConfig, ...]:
    """The configured robots ``team`` may use (none for a team that no longer exists)."""
    row = session.get(Team, team)
    if row is None:
        return ()
    names = _loaded(row.robots)
    return tuple(configured) if names is None else tuple(r for r in configured if r.name in names)
