"""The service's configuration: from ``planner serve`` options and the environment (``PLANNER_*``).

Both are pydantic models: :class:`RobotSpec` is one robot of ``PLANNER_ROBOTS`` as the operator writes it,
:class:`ServiceConfig` the whole configuration, each field with its environment variable; a refused value is one
:class:`~planner.errors.PlannerError` line naming the variable (and the robot) and the field (:func:`one_line`).
"""

from __future__ import annotations

import ipaddress
import json
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator
from pydantic_core import PydanticCustomError

from drivers.report import PATH_TOLERANCE_RANGE
from drivers.servo import DEFAULT_GAIN, DEFAULT_LOOKAHEAD, GAIN_RANGE, LOOKAHEAD_RANGE
from planner.errors import PlannerError
from planner.export.job_script import MAX_PROGRAM_BYTES

#: Key roles: planner (submit and read its own jobs) and operator (may also execute on robots).
ROLES = ("planner", "operator")
#: Default database: one SQLite file in the working directory.
DEFAULT_DB = "sqlite:///jobs.sqlite"
#: The longest planning time a service may allow a job, s (30 days).
MAX_JOB_TIMEOUT = 30 * 86400.0
#: Planning work from which the celery backend splits a job across its workers (PLANNER_SPLIT_CHORDS), in CAM chords
#: of passes whose tool axis varies (a chord of a constant axis counts 0.115: planner.plan.PIECE_COST). From
#: bench/bench_scale.py --only nx-split (2 workers, a loaded machine): a split costs about 0.5 s whatever the size
#: (the pieces found, the messages, the coordinator's polling, the join's parse) and saves about 0.23 ms per such
#: chord (the NX job's 13,300: its two pieces 6.4 and 5.2 s with their bytes 0.8 s each, against 10.8 s in one
#: process), so it pays from about 2,200; twice that for a margin.
SPLIT_CHORDS = 4096


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
    lookahead, gain, compensate : float, float, bool
        Stream mode's servoJ settings and target shaping (:class:`drivers.ur.URDriver`'s, same defaults and ranges).
    path_tolerance : float or None
        m: the report lists where the tracked TCP left the planned path by more; None: no tolerance.
    fail_on_deviation : bool
        A run beyond ``path_tolerance`` fails.
    max_program_bytes : int or None
        Program mode: the largest program sent to the controller (a longer job goes in pieces); None: no limit.
    """

    name: str
    host: str | None = None
    model: str | None = None
    io: str = "rtde"
    modbus_port: int = 502
    sim_speed: float = 1.0
    approach_speed: float = 0.5
    approach_acceleration: float = 0.5
    lookahead: float = DEFAULT_LOOKAHEAD
    gain: float = DEFAULT_GAIN
    compensate: bool = True
    path_tolerance: float | None = None
    fail_on_deviation: bool = False
    max_program_bytes: int | None = MAX_PROGRAM_BYTES

    @property
    def simulated(self) -> bool:
        return self.host is None

    def driver_options(self) -> dict[str, Any]:
        """The options of :func:`drivers.execute.execute_job` (:class:`drivers.ur.URDriver`) this robot sets."""
        return {"approach_speed": self.approach_speed, "approach_acceleration": self.approach_acceleration,
                "lookahead": self.lookahead, "gain": self.gain, "compensate": self.compensate,
                "path_tolerance": self.path_tolerance, "fail_on_deviation": self.fail_on_deviation,
                "max_program_bytes": self.max_program_bytes}


#: The default robots: one simulated controller, "sim", of the job's model.
DEFAULT_ROBOTS = (RobotConfig("sim"),)
_ROBOT_NAME = re.compile(r"^[A-Za-z0-9_-]{1,32}$")


def _refused(text: str) -> PydanticCustomError:
    """A validator's refusal whose message is ``text`` as it is (:func:`one_line` prints it so)."""
    return PydanticCustomError("planner", "{text}", {"text": text})


def one_line(exc: ValidationError, names: dict[str, str] | None = None) -> str:
    """The first error of ``exc`` as one line naming the field (``names`` maps a field to the name the user knows,
    e.g. its environment variable): ``modbus_port must be at most 65535, got 70000``."""
    e = exc.errors(include_url=False)[0]
    field = ".".join(str(x) for x in e["loc"])
    field = (names or {}).get(field, field)
    kind, ctx, got = e["type"], e.get("ctx", {}), e.get("input")
    if kind == "planner":
        return str(ctx["text"])
    if kind == "planner_field":
        return f"{field} {ctx['text']}"
    if kind == "extra_forbidden":
        return f"unknown field {field!r}"
    rules = {"literal_error": lambda: f"must be {ctx['expected']}", "greater_than": lambda: f"must be > {ctx['gt']}",
             "greater_than_equal": lambda: f"must be at least {ctx['ge']}",
             "less_than": lambda: f"must be < {ctx['lt']}", "less_than_equal": lambda: f"must be at most {ctx['le']}"}
    rule = rules[kind]() if kind in rules else e["msg"][:1].lower() + e["msg"][1:]
    shown = repr(got) if len(repr(got)) <= 80 else f"{repr(got)[:60]}... ({len(str(got))} characters)"
    return f"{field} {rule}, got {shown}" if kind in rules else f"{field}: {rule}, got {shown}"


class RobotSpec(BaseModel):
    """One robot of ``PLANNER_ROBOTS`` (``planner serve --robots``): either a ``host`` (the controller's IP address,
    with its ``model``) or ``"sim": true``."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)

    host: str | None = Field(None, description="the controller's IP address")
    sim: bool = Field(False, description="a simulated controller, started for each execution")
    model: str | None = Field(None, description="UR model (ur3e, ur5e, ...); needed with a host")
    io: Literal["rtde", "modbus"] = Field("rtde", description="how the job's outputs are switched")
    modbus_port: int = Field(502, ge=1, le=65535, description="the controller's Modbus TCP port")
    sim_speed: float | None = Field(None, gt=0, le=100, description="simulated seconds per second (default 1)")
    approach_speed: float = Field(0.5, gt=0, le=3.14, description="joint move onto the start, rad/s")
    approach_acceleration: float = Field(0.5, gt=0, le=40.0, description="joint move onto the start, rad/s^2")
    # the driver's servo and deviation options (planner run --lookahead, --gain, --no-compensation, --path-tolerance,
    # --fail-on-deviation, --max-program-bytes), with the driver's ranges
    lookahead: float = Field(DEFAULT_LOOKAHEAD, ge=LOOKAHEAD_RANGE[0], le=LOOKAHEAD_RANGE[1],
                             description="stream mode: servoJ lookahead time, s")
    gain: float = Field(DEFAULT_GAIN, ge=GAIN_RANGE[0], le=GAIN_RANGE[1], description="stream mode: servoJ gain")
    compensate: bool = Field(True, description="stream mode: targets shaped by the servo model (false: the planned "
                                               "joints unshaped)")
    path_tolerance_mm: float | None = Field(None, gt=1e3 * PATH_TOLERANCE_RANGE[0],
                                            le=1e3 * PATH_TOLERANCE_RANGE[1],
                                            description="the report lists where the tracked TCP left the planned "
                                                        "path by more, mm")
    fail_on_deviation: bool = Field(False, description="a run beyond path_tolerance_mm fails")
    max_program_bytes: int | None = Field(MAX_PROGRAM_BYTES, ge=4096, description="program mode: the largest "
                                          "program sent (a longer job goes in pieces); null: no limit")

    @field_validator("host")
    @classmethod
    def _ip(cls, host: str | None) -> str | None:
        if host is None:
            return None
        try:
            return str(ipaddress.ip_address(host))
        except ValueError:
            raise _refused(f"host must be an IP address, got {host!r}") from None

    @field_validator("model")
    @classmethod
    def _model(cls, model: str | None) -> str | None:
        if model is None:
            return None
        from planner.kinematics import get_model

        try:
            return get_model(model).name
        except (ValueError, KeyError, TypeError) as exc:
            raise _refused(f"model: {exc}") from None

    @model_validator(mode="after")
    def _kind(self) -> RobotSpec:
        if (self.host is None) == (not self.sim):
            raise _refused("give either host (the controller's IP address) or \"sim\": true")
        if self.host is not None and self.model is None:
            raise _refused("model is needed for a real controller (ur3e, ur5e, ...)")
        if self.host is not None and self.sim_speed is not None:
            raise _refused("sim_speed applies to simulated robots only")
        if self.fail_on_deviation and self.path_tolerance_mm is None:
            raise _refused("fail_on_deviation needs path_tolerance_mm")
        return self

    def robot(self, name: str) -> RobotConfig:
        """The :class:`RobotConfig` of this robot under ``name``."""
        return RobotConfig(name, self.host, self.model, self.io, self.modbus_port,
                           1.0 if self.sim_speed is None else float(self.sim_speed), float(self.approach_speed),
                           float(self.approach_acceleration), float(self.lookahead), float(self.gain),
                           self.compensate, None if self.path_tolerance_mm is None else 1e-3 * self.path_tolerance_mm,
                           self.fail_on_deviation, self.max_program_bytes)


def robots_from_json(text: str, where: str = "PLANNER_ROBOTS") -> tuple[RobotConfig, ...]:
    """Robots from ``{"NAME": {"host": "192.168.0.10", "model": "ur10e", "io": "modbus", "modbus_port": 502},
    "NAME2": {"sim": true, "model": "ur5e", "sim_speed": 5}}`` (each a :class:`RobotSpec`). Errors name the robot
    and the field."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise PlannerError(f"{where}: not JSON ({exc})") from None
    if not isinstance(data, dict) or not data:
        raise PlannerError(f"{where}: must be a JSON object of robot name -> settings, with at least one robot")
    out: list[RobotConfig] = []
    for name, spec in data.items():
        at = f"{where}: robot {name!r}"
        if not _ROBOT_NAME.match(name):
            raise PlannerError(f"{at}: a name is 1..32 of A-Z a-z 0-9 _ -")
        if not isinstance(spec, dict):
            raise PlannerError(f"{at}: must be an object")
        try:
            robot = RobotSpec.model_validate(spec).robot(name)
        except ValidationError as exc:
            known = "" if exc.errors()[0]["type"] != "extra_forbidden" else \
                f" (known: {', '.join(sorted(RobotSpec.model_fields))})"
            raise PlannerError(f"{at}: {one_line(exc)}{known}", field=name, value=spec) from None
        same = next((r for r in out if robot.host is not None and r.host == robot.host), None)
        if same is not None:  # two names for one controller would let two executions drive one arm
            raise PlannerError(f"{at}: host {robot.host} is robot {same.name!r}'s already (one name per controller)")
        out.append(robot)
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


def _env(name: str) -> Any:
    """The environment variable a ServiceConfig field is read from (in its schema, ``env``)."""
    return {"env": name}


class ServiceConfig(BaseModel):
    """What one running service uses (each field read from its environment variable by :meth:`from_env`).

    Attributes
    ----------
    db_url : str
        SQLAlchemy URL of the job store (``PLANNER_DB``; SQLite by default, PostgreSQL given a URL).
    data_dir : Path
        Folder the service owns for uploaded inputs and saved jobs (``PLANNER_DATA``; default: beside a
        SQLite file, ``<db>.data``). No path from a request is ever used as a file name.
    workers : int
        Planning worker processes (``PLANNER_WORKERS``).
    dev_no_auth : bool
        ``PLANNER_DEV_NO_AUTH=1``: no API keys, every request is a development operator; loopback only.
    max_request_bytes : int
        Largest request body (413 above; ``PLANNER_MAX_REQUEST_BYTES``).
    max_waypoints : int
        Largest number of waypoints of a JSON job (422 above; ``PLANNER_MAX_WAYPOINTS``).
    job_timeout_s : float
        Wall time a planning job may take before its worker is stopped and the job failed (``PLANNER_JOB_TIMEOUT``).
    max_attempts : int
        Starts of a job (a restart of the service while it runs re-queues it until this many;
        ``PLANNER_MAX_ATTEMPTS``).
    robots : tuple of RobotConfig
        The robots jobs may be executed on (``PLANNER_ROBOTS``; default: one simulated robot named "sim"); which of
        them a team's operators may use is the team's (``planner teams robots``, :mod:`.teams`).
    queue : "local" or "celery"
        The task backend (``PLANNER_QUEUE``): "local" (the default) plans and executes in worker processes of the
        service itself; "celery" sends every task to ``planner worker`` processes on any machine through the broker.
    broker : str or None
        The Celery broker's URL, ``redis://HOST:PORT/DB`` (``PLANNER_BROKER``; needed with ``queue="celery"``).
    split_chords : int
        The celery backend plans a toolpath file in pieces across its workers when its planning work is at least this
        many CAM chords of passes whose tool axis varies (a chord of a constant tool axis counting 0.115)
        (``PLANNER_SPLIT_CHORDS``; 0: never; :mod:`.tasks.split`).
    worker_nice : int
        Niceness added to the service's worker and drawing processes, and to the whole of a ``planner worker``,
        0..19 (``PLANNER_WORKER_NICE``, default 10: batch work, the API's requests come first on a shared machine).
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    db_url: str = Field(DEFAULT_DB, min_length=1, max_length=4096, json_schema_extra=_env("PLANNER_DB"))
    data_dir: Path = Field(Path("jobs.sqlite.data"), json_schema_extra=_env("PLANNER_DATA"))
    workers: int = Field(2, ge=1, le=256, json_schema_extra=_env("PLANNER_WORKERS"))
    dev_no_auth: bool = Field(False, json_schema_extra=_env("PLANNER_DEV_NO_AUTH"))
    max_request_bytes: int = Field(64 * 2**20, ge=1, json_schema_extra=_env("PLANNER_MAX_REQUEST_BYTES"))
    max_waypoints: int = Field(100_000, ge=2, json_schema_extra=_env("PLANNER_MAX_WAYPOINTS"))
    job_timeout_s: Annotated[float, Field(gt=0, le=MAX_JOB_TIMEOUT, allow_inf_nan=False)] = Field(
        3600.0, json_schema_extra=_env("PLANNER_JOB_TIMEOUT"))
    max_attempts: int = Field(2, ge=1, le=1000, json_schema_extra=_env("PLANNER_MAX_ATTEMPTS"))
    robots: tuple[RobotConfig, ...] = Field(DEFAULT_ROBOTS, json_schema_extra=_env("PLANNER_ROBOTS"))
    queue: Literal["local", "celery"] = Field("local", json_schema_extra=_env("PLANNER_QUEUE"))
    broker: str | None = Field(None, max_length=4096, json_schema_extra=_env("PLANNER_BROKER"))
    split_chords: int = Field(SPLIT_CHORDS, ge=0, le=2**31 - 1, json_schema_extra=_env("PLANNER_SPLIT_CHORDS"))
    worker_nice: int = Field(10, ge=0, le=19, json_schema_extra=_env("PLANNER_WORKER_NICE"))

    @field_validator("db_url")
    @classmethod
    def _db_url(cls, url: str) -> str:
        check_db_url(url)
        return url

    @model_validator(mode="after")
    def _backend(self) -> ServiceConfig:
        if self.queue == "celery" and not self.broker:
            raise _refused("PLANNER_BROKER (the broker's URL, redis://HOST:PORT/0) is needed with PLANNER_QUEUE=celery")
        if self.broker:
            check_broker(self.broker)
        if self.data_dir.exists() and not self.data_dir.is_dir():
            raise _refused(f"PLANNER_DATA must be a folder (the service's own), got the file {str(self.data_dir)!r}")
        return self

    def robot(self, name: str) -> RobotConfig | None:
        """The configured robot of that name, or None."""
        return next((r for r in self.robots if r.name == name), None)

    @classmethod
    def env_names(cls) -> dict[str, str]:
        """Field -> environment variable."""
        return {name: str(f.json_schema_extra["env"]) for name, f in cls.model_fields.items()
                if isinstance(f.json_schema_extra, dict)}

    @classmethod
    def from_env(cls, env: dict | None = None, options: dict[str, str] | None = None, **overrides) -> ServiceConfig:
        """The configuration from ``PLANNER_DB``, ``PLANNER_DATA``, ``PLANNER_WORKERS``, ``PLANNER_DEV_NO_AUTH``,
        ``PLANNER_MAX_REQUEST_BYTES``, ``PLANNER_MAX_WAYPOINTS``, ``PLANNER_JOB_TIMEOUT``, ``PLANNER_MAX_ATTEMPTS``,
        ``PLANNER_ROBOTS``, ``PLANNER_QUEUE``, ``PLANNER_BROKER``, ``PLANNER_SPLIT_CHORDS``, ``PLANNER_WORKER_NICE``
        (unset or empty: the default); ``overrides`` (by field name, None: not given) win.
        PlannerError, one line naming the variable (or the option of an override: :data:`OPTIONS`, or ``options``
        by field name) and what is expected, for a refused value."""
        env = dict(os.environ if env is None else env)
        names = cls.env_names()
        raw: dict[str, Any] = {name: env[var] for name, var in names.items() if env.get(var)}
        dev = env.get(names["dev_no_auth"], "").strip()
        if dev not in ("", "0", "1"):
            raise PlannerError(f"PLANNER_DEV_NO_AUTH must be 1 (serve without API keys, loopback only) or 0 (keys "
                               f"needed, the default), got {dev!r}")
        raw["dev_no_auth"] = dev == "1"
        raw["robots"] = robots_from_env(env.get(names["robots"]))
        given = {k: v for k, v in overrides.items() if v is not None}
        raw.update(given)
        raw.setdefault("db_url", DEFAULT_DB)
        raw["data_dir"] = Path(raw["data_dir"]) if raw.get("data_dir") else default_data_dir(raw["db_url"])
        try:
            cfg = cls.model_validate(raw)
        except ValidationError as exc:
            raise PlannerError(one_line(exc, {k: v for k, v in names.items() if k not in given}
                                        | {k: v for k, v in (OPTIONS | (options or {})).items() if k in given})
                               ) from None
        return cfg.model_copy(update={"data_dir": cfg.data_dir.resolve()})


#: The command-line options of the fields (``planner serve``, ``worker``, ``keys``, ``teams``), named in errors of a
#: value given by an option.
OPTIONS = {"db_url": "--db", "data_dir": "--data", "workers": "--workers", "job_timeout_s": "--job-timeout"}

#: The database URLs of the job store, as errors show them.
DB_URLS = "sqlite:///PATH (a file) or postgresql+psycopg://USER@HOST:PORT/DB"


def check_db_url(url: str) -> None:
    """Refuse a database URL that SQLAlchemy cannot parse, a database other than SQLite and PostgreSQL, or one whose
    driver is not installed (the field's name is put before the message, :func:`one_line`)."""
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError, NoSuchModuleError

    try:
        u = make_url(url)
    except (ArgumentError, ValueError):
        hint = f" (for a file: sqlite:///{url})" if "://" not in url and url.strip() else ""
        raise _field_refused(f"must be a database URL, {DB_URLS}, got {url!r}{hint}") from None
    if u.get_backend_name() not in ("sqlite", "postgresql"):
        raise _field_refused(f"must be a SQLite or PostgreSQL URL, {DB_URLS}, got {u.get_backend_name()!r} in "
                             f"{u.render_as_string(hide_password=True)!r}")
    try:
        u.get_dialect().import_dbapi()
    except (NoSuchModuleError, ImportError) as exc:
        raise _field_refused(f"names the driver {u.drivername!r}, which is not installed ({exc}); {DB_URLS}") from None
    if u.port is not None and not 1 <= u.port <= 65535:
        raise _field_refused(f"has the port {u.port}, not one of 1..65535: {u.render_as_string(hide_password=True)!r}")


def check_broker(url: str) -> None:
    """Refuse a broker URL that is not ``redis://HOST:PORT/DB`` (or ``rediss://``)."""
    from urllib.parse import urlsplit

    form = "redis://HOST:PORT/DB (or rediss://)"
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError as exc:
        raise _refused(f"PLANNER_BROKER must be {form}: {exc}, got {url!r}") from None
    if parts.scheme not in ("redis", "rediss") or not parts.hostname:
        raise _refused(f"PLANNER_BROKER must be {form}, got {url!r}")
    if port is not None and port == 0:
        raise _refused(f"PLANNER_BROKER: port 0 is no port, got {url!r}")
    db = parts.path.strip("/")
    if db and not (db.isdigit() and int(db) < 2**31):
        raise _refused(f"PLANNER_BROKER must be {form} (DB a number), got {url!r}")


def _field_refused(text: str) -> PydanticCustomError:
    """A validator's refusal whose message follows the field's name (``PLANNER_DB must be ...``)."""
    return PydanticCustomError("planner_field", "{text}", {"text": text})


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
