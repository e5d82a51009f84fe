"""The service's configuration: from ``planner serve`` options and the environment (``PLANNER_*``)."""

from __future__ import annotations

import ipaddress
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

from planner.errors import PlannerError

#: Key roles: planner (submit and read its own jobs) and operator (may also execute on robots).
ROLES = ("planner", "operator")
#: Default database: one SQLite file in the working directory.
DEFAULT_DB = "sqlite:///jobs.sqlite"


@dataclass(frozen=True)
class ServiceConfig:
    """What one running service uses.

    Attributes
    ----------
    db_url : str
        SQLAlchemy URL of the job store (``PLANNER_DB``; SQLite by default, PostgreSQL given a URL).
    data_dir : Path
        Folder the service owns for uploaded inputs and saved jobs (``PLANNER_DATA``; default: beside a
        SQLite file, ``<db>.data``). No path from a request is ever used as a file name.
    workers : int
        Planning worker processes.
    dev_no_auth : bool
        ``PLANNER_DEV_NO_AUTH=1``: no API keys, every request is a development operator; loopback only.
    max_request_bytes : int
        Largest request body (413 above).
    max_waypoints : int
        Largest number of waypoints of a JSON job (422 above).
    job_timeout_s : float
        Wall time a planning job may take before its worker is stopped and the job failed.
    max_attempts : int
        Starts of a job (a restart of the service while it runs re-queues it until this many).
    """

    db_url: str = DEFAULT_DB
    data_dir: Path = field(default_factory=lambda: Path("jobs.sqlite.data"))
    workers: int = 2
    dev_no_auth: bool = False
    max_request_bytes: int = 64 * 2**20
    max_waypoints: int = 100_000
    job_timeout_s: float = 3600.0
    max_attempts: int = 2

    @classmethod
    def from_env(cls, env: dict | None = None, **overrides) -> ServiceConfig:
        """The configuration from ``PLANNER_DB``, ``PLANNER_DATA``, ``PLANNER_WORKERS``, ``PLANNER_DEV_NO_AUTH``,
        ``PLANNER_MAX_REQUEST_BYTES``, ``PLANNER_MAX_WAYPOINTS``, ``PLANNER_JOB_TIMEOUT``, ``PLANNER_MAX_ATTEMPTS``;
        ``overrides`` win."""
        env = dict(os.environ if env is None else env)
        db = env.get("PLANNER_DB") or DEFAULT_DB
        kw: dict = {"db_url": db, "dev_no_auth": env.get("PLANNER_DEV_NO_AUTH", "") == "1"}
        for key, name, conv in (("PLANNER_WORKERS", "workers", int),
                                ("PLANNER_MAX_REQUEST_BYTES", "max_request_bytes", int),
                                ("PLANNER_MAX_WAYPOINTS", "max_waypoints", int),
                                ("PLANNER_JOB_TIMEOUT", "job_timeout_s", float),
                                ("PLANNER_MAX_ATTEMPTS", "max_attempts", int)):
            if env.get(key):
                try:
                    kw[name] = conv(env[key])
                except ValueError:
                    raise PlannerError(f"{key} must be a number, got {env[key]!r}") from None
        kw.update({k: v for k, v in overrides.items() if v is not None})
        data = env.get("PLANNER_DATA")
        kw["data_dir"] = Path(data) if data else default_data_dir(kw["db_url"])
        if "data_dir" in overrides and overrides["data_dir"] is not None:
            kw["data_dir"] = Path(overrides["data_dir"])
        cfg = cls(**kw)
        if cfg.workers < 1:
            raise PlannerError(f"workers must be at least 1, got {cfg.workers}")
        return replace(cfg, data_dir=cfg.data_dir.resolve())


def default_data_dir(db_url: str) -> Path:
    """``<file>.data`` beside a SQLite file, else ``planner-data`` in the working directory."""
    prefix = "sqlite:///"
    if db_url.startswith(prefix) and db_url[len(prefix):] not in ("", ":memory:"):
        return Path(db_url[len(prefix):] + ".data")
    return Path("planner-data")


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and ``localhost``."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
