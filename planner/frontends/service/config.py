"""The service's configuration: from ``planner serve`` options and the environment (``PLANNER_*``)."""

from __future__ import annotations

import ipaddress
import json
import os
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

from planner.errors import PlannerError

#: Key roles: planner (submit and read its own jobs) and operator (may also execute on robots).
ROLES = ("planner", "operator")
#: Default database: one SQLite file in the working directory.
DEFAULT_DB = "sqlite:///jobs.sqlite"


@dataclass(frozen=True)
class RobotConfig:
    """A robot the operator configured: jobs are executed on it by name (a request never carries a host).

    Attributes
    ----------
    name : str
        The name requests use (``[A-Za-z0-9_-]``, 1..32 characters).
    host : str or None
        The controller's IP address; None for a simulated controller (:class:`sim.SimController`) started on a
        free loopback address for each execution and stopped after it.
    model : str or None
        UR model (``ur5e``, ...); a job must be planned for it. None (simulated robots only): the job's model.
    io : "rtde" or "modbus"
        How the job's digital outputs are switched.
    modbus_port : int
        The controller's Modbus TCP port (``io="modbus"``; a simulated controller gets a free one).
    sim_speed : float
        Simulated seconds per second of a simulated controller in program mode (streaming runs in real time).
    approach_speed, approach_acceleration : float
        The joint move onto the job's start before a run, rad/s and rad/s^2 (the driver's defaults 0.5, 0.5).
    """

    name: str
    host: str | None = None
    model: str | None = None
    io: str = "rtde"
    modbus_port: int = 502
    sim_speed: float = 1.0
    approach_speed: float = 0.5
    approach_acceleration: float = 0.5

    @property
    def simulated(self) -> bool:
        return self.host is None


#: The default robots: one simulated controller, "sim", of the job's model.
DEFAULT_ROBOTS = (RobotConfig("sim"),)
_ROBOT_NAME = re.compile(r"^[A-Za-z0-9_-]{1,32}$")
_ROBOT_KEYS = {"host", "sim", "model", "io", "modbus_port", "sim_speed", "approach_speed", "approach_acceleration"}


def robots_from_json(text: str, where: str = "PLANNER_ROBOTS") -> tuple[RobotConfig, ...]:
    """Robots from ``{"NAME": {"host": "192.168.0.10", "model": "ur10e", "io": "modbus", "modbus_port": 502},
    "NAME2": {"sim": true, "model": "ur5e", "sim_speed": 5}}``: each either a ``host`` (an IP address) or
    ``"sim": true``. Errors name the robot and the field."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise PlannerError(f"{where}: not JSON ({exc})") from None
    if not isinstance(data, dict) or not data:
        raise PlannerError(f"{where}: must be a JSON object of robot name -> settings, with at least one robot")
    from planner.kinematics import get_model

    out: list[RobotConfig] = []
    for name, spec in data.items():
        at = f"{where}: robot {name!r}"
        if not _ROBOT_NAME.match(name):
            raise PlannerError(f"{at}: a name is 1..32 of A-Z a-z 0-9 _ -")
        if not isinstance(spec, dict):
            raise PlannerError(f"{at}: must be an object")
        unknown = sorted(set(spec) - _ROBOT_KEYS)
        if unknown:
            raise PlannerError(f"{at}: unknown field {unknown[0]!r} (known: {', '.join(sorted(_ROBOT_KEYS))})")
        host, sim = spec.get("host"), spec.get("sim", False)
        if not isinstance(sim, bool) or (host is None) == (not sim):
            raise PlannerError(f"{at}: give either host (the controller's IP address) or \"sim\": true")
        if host is not None:
            try:
                host = str(ipaddress.ip_address(host))
            except ValueError:
                raise PlannerError(f"{at}: host must be an IP address, got {host!r}") from None
        model = spec.get("model")
        if model is None and host is not None:
            raise PlannerError(f"{at}: model is needed for a real controller (ur3e, ur5e, ...)")
        if model is not None:
            try:
                model = get_model(model).name
            except (ValueError, KeyError, TypeError) as exc:
                raise PlannerError(f"{at}: model: {exc}") from None
        io = spec.get("io", "rtde")
        if io not in ("rtde", "modbus"):
            raise PlannerError(f"{at}: io must be 'rtde' or 'modbus', got {io!r}")
        port = spec.get("modbus_port", 502)
        if isinstance(port, bool) or not isinstance(port, int) or not 1 <= port <= 65535:
            raise PlannerError(f"{at}: modbus_port must be an integer within 1..65535, got {port!r}")
        speed = spec.get("sim_speed", 1.0)
        if isinstance(speed, bool) or not isinstance(speed, int | float) or not 0 < speed <= 100:
            raise PlannerError(f"{at}: sim_speed must be a number within (0, 100], got {speed!r}")
        if host is not None and "sim_speed" in spec:
            raise PlannerError(f"{at}: sim_speed applies to simulated robots only")
        approach = []
        for key, top in (("approach_speed", 3.14), ("approach_acceleration", 40.0)):
            v = spec.get(key, 0.5)
            if isinstance(v, bool) or not isinstance(v, int | float) or not 0 < v <= top:
                raise PlannerError(f"{at}: {key} must be a number within (0, {top:g}], got {v!r}")
            approach.append(float(v))
        same = next((r for r in out if host is not None and r.host == host), None)
        if same is not None:  # two names for one controller would let two executions drive one arm
            raise PlannerError(f"{at}: host {host} is robot {same.name!r}'s already (one name per controller)")
        out.append(RobotConfig(name, host, model, io, port, float(speed), *approach))
    return tuple(out)


def robots_from_env(value: str | None, where: str = "PLANNER_ROBOTS") -> tuple[RobotConfig, ...]:
    """``PLANNER_ROBOTS`` (or ``planner serve --robots``, named by ``where`` in errors): a JSON object (see
    :func:`robots_from_json`) or the path of a file holding one; unset: :data:`DEFAULT_ROBOTS`."""
    if not value:
        return DEFAULT_ROBOTS
    if value.lstrip().startswith("{"):
        return robots_from_json(value, where)
    try:
        text = open(value, encoding="utf-8").read()  # noqa: SIM115
    except OSError as exc:
        raise PlannerError(f"{where}: cannot read {value}: {exc.strerror}") from None
    return robots_from_json(text, f"{where} file {value}")


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
    robots : tuple of RobotConfig
        The robots jobs may be executed on (``PLANNER_ROBOTS``; default: one simulated robot named "sim").
    """

    db_url: str = DEFAULT_DB
    data_dir: Path = field(default_factory=lambda: Path("jobs.sqlite.data"))
    workers: int = 2
    dev_no_auth: bool = False
    max_request_bytes: int = 64 * 2**20
    max_waypoints: int = 100_000
    job_timeout_s: float = 3600.0
    max_attempts: int = 2
    robots: tuple[RobotConfig, ...] = DEFAULT_ROBOTS

    def robot(self, name: str) -> RobotConfig | None:
        """The configured robot of that name, or None."""
        return next((r for r in self.robots if r.name == name), None)

    @classmethod
    def from_env(cls, env: dict | None = None, **overrides) -> ServiceConfig:
        """The configuration from ``PLANNER_DB``, ``PLANNER_DATA``, ``PLANNER_WORKERS``, ``PLANNER_DEV_NO_AUTH``,
        ``PLANNER_MAX_REQUEST_BYTES``, ``PLANNER_MAX_WAYPOINTS``, ``PLANNER_JOB_TIMEOUT``, ``PLANNER_MAX_ATTEMPTS``,
        ``PLANNER_ROBOTS``; ``overrides`` win."""
        env = dict(os.environ if env is None else env)
        db = env.get("PLANNER_DB") or DEFAULT_DB
        kw: dict = {"db_url": db, "dev_no_auth": env.get("PLANNER_DEV_NO_AUTH", "") == "1",
                    "robots": robots_from_env(env.get("PLANNER_ROBOTS"))}
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
