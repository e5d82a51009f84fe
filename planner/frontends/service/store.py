"""The job store: tables (SQLAlchemy 2), the engine (SQLite in WAL mode by default) and Alembic migrations.

What a job keeps: its input (waypoints as JSON text in its row, or the uploaded file's bytes in :class:`JobData`),
its settings, its summary and the saved :class:`planner.PlannedJob` (:class:`JobData` "plan": kilobytes to a few
megabytes, 4.2 MB for the whole NX job), all in the database: every API replica and worker reads them there, and a
plan is stored in the same transaction that marks its job done. Exports are never stored: they are streamed from the
saved plan.

Teams: a key belongs to a team (:class:`Team`); a job and its executions belong to the team of the key that submitted
the job (``team``; ``owner`` keeps the key itself). Keys and jobs made before teams are the :data:`DEFAULT_TEAM`'s.

Jobs and executions are tasks of one life cycle (:mod:`.tasks.lifecycle`) and share its columns: state, stage,
done, total, attempts, holder (the worker process running it, ``host:pid``), heartbeat_at (its holder's last sign
of life: an execution's lease on its robot expires :data:`.tasks.transitions.LEASE_S` after it), created_at,
started_at, finished_at, error_kind, error, note.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

from sqlalchemy import (
    Float,
    Index,
    Integer,
    LargeBinary,
    String,
    Text,
    create_engine,
    event,
    text,
)
from sqlalchemy.engine import Engine
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, sessionmaker

from planner.frontends.service.config import ROLES  # noqa: F401  (re-exported: the roles a key row may hold)

#: An execution holds its robot in these states (:data:`.tasks.lifecycle.EXECUTION`'s active states): at most one
#: per robot, a partial unique index.
_ACTIVE = text("state IN ('starting', 'running', 'stopping')")
#: The owner of jobs in development mode (PLANNER_DEV_NO_AUTH=1).
DEV_OWNER = "dev"
#: The team every key and job made before teams belongs to (migration 0004), keys made without ``--team`` and the
#: development mode's jobs; it may use every configured robot until ``planner teams robots`` says otherwise.
DEFAULT_TEAM = "default"


class Base(DeclarativeBase):
    pass


class Team(Base):
    """A team: its keys' planners see and manage its jobs, its operators run them on the team's robots (names of
    configured robots, ``PLANNER_ROBOTS``)."""

    __tablename__ = "teams"
    name: Mapped[str] = mapped_column(String(32), primary_key=True)
    robots: Mapped[str | None] = mapped_column(Text, nullable=True)  # JSON list of robot names; NULL: every robot
    created_at: Mapped[float] = mapped_column(Float)


class ApiKey(Base):
    """An API key: only the SHA-256 of the secret is stored."""

    __tablename__ = "api_keys"
    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    name: Mapped[str] = mapped_column(String(200))
    role: Mapped[str] = mapped_column(String(16))
    team: Mapped[str] = mapped_column(String(32), server_default=DEFAULT_TEAM)  # a teams.name
    key_hash: Mapped[str] = mapped_column(String(64), unique=True)
    created_at: Mapped[float] = mapped_column(Float)
    revoked_at: Mapped[float | None] = mapped_column(Float, nullable=True)


class Job(Base):
    """A planning job (times are Unix seconds)."""

    __tablename__ = "jobs"
    seq: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    id: Mapped[str] = mapped_column(String(32), unique=True)
    owner: Mapped[str] = mapped_column(String(32))  # an api_keys.id, or "dev"
    team: Mapped[str] = mapped_column(String(32), server_default=DEFAULT_TEAM)  # the owner's team: who sees the job
    state: Mapped[str] = mapped_column(String(16))
    created_at: Mapped[float] = mapped_column(Float)
    started_at: Mapped[float | None] = mapped_column(Float, nullable=True)
    finished_at: Mapped[float | None] = mapped_column(Float, nullable=True)
    input_kind: Mapped[str] = mapped_column(String(16))  # "waypoints" or "file"
    input_name: Mapped[str] = mapped_column(String(255))  # the file's (sanitized) base name, or "<waypoints>"
    input_format: Mapped[str] = mapped_column(String(16))
    input_bytes: Mapped[int] = mapped_column(Integer, default=0)
    input_json: Mapped[str | None] = mapped_column(Text, nullable=True)  # waypoints, axes, feeds
    settings: Mapped[str] = mapped_column(Text)  # PlanSettings.to_dict() as JSON
    read_options: Mapped[str] = mapped_column(Text, default="{}")
    stage: Mapped[str] = mapped_column(String(32), default="")
    done: Mapped[int] = mapped_column(Integer, default=0)
    total: Mapped[int] = mapped_column(Integer, default=0)
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    job_file: Mapped[str | None] = mapped_column(String(64), nullable=True)  # name inside the job's folder
    job_bytes: Mapped[int] = mapped_column(Integer, default=0)
    summary: Mapped[str | None] = mapped_column(Text, nullable=True)  # JSON of PlannedJob.summary()
    describe: Mapped[str | None] = mapped_column(Text, nullable=True)  # JSON list of lines
    planning_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    error_kind: Mapped[str | None] = mapped_column(String(16), nullable=True)  # input, internal, limit, interrupted
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    note: Mapped[str | None] = mapped_column(Text, nullable=True)  # e.g. "re-run after a restart of the service"
    holder: Mapped[str | None] = mapped_column(String(64), nullable=True)  # worker process running it, host:pid
    heartbeat_at: Mapped[float | None] = mapped_column(Float, nullable=True)

    __table_args__ = (Index("ix_jobs_team_seq", "team", "seq"), Index("ix_jobs_state_seq", "state", "seq"))


class Execution(Base):
    """A run of a done job on a configured robot (times are Unix seconds; the report is JSON of its figures)."""

    __tablename__ = "executions"
    seq: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    id: Mapped[str] = mapped_column(String(32), unique=True)
    job_id: Mapped[str] = mapped_column(String(32))
    owner: Mapped[str] = mapped_column(String(32))  # the operator's key
    team: Mapped[str] = mapped_column(String(32), server_default=DEFAULT_TEAM)  # its job's team
    robot: Mapped[str] = mapped_column(String(32))  # a configured robot's name
    mode: Mapped[str] = mapped_column(String(16))  # "stream" or "program"
    state: Mapped[str] = mapped_column(String(16))
    created_at: Mapped[float] = mapped_column(Float)
    started_at: Mapped[float | None] = mapped_column(Float, nullable=True)  # the run itself (after the approach)
    finished_at: Mapped[float | None] = mapped_column(Float, nullable=True)
    stage: Mapped[str] = mapped_column(String(32), default="")
    done: Mapped[int] = mapped_column(Integer, default=0)
    total: Mapped[int] = mapped_column(Integer, default=0)
    report: Mapped[str | None] = mapped_column(Text, nullable=True)  # JSON of the ExecutionReport's figures
    error_kind: Mapped[str | None] = mapped_column(String(32), nullable=True)  # DriverError.kind, interrupted, internal
    error: Mapped[str | None] = mapped_column(Text, nullable=True)  # the robot's reason
    error_t: Mapped[float | None] = mapped_column(Float, nullable=True)  # job time of the failure, s
    error_pose: Mapped[str | None] = mapped_column(Text, nullable=True)  # JSON p[x, y, z, rx, ry, rz], m, rad
    error_line: Mapped[int | None] = mapped_column(Integer, nullable=True)  # source line being carried out
    note: Mapped[str | None] = mapped_column(Text, nullable=True)
    attempts: Mapped[int] = mapped_column(Integer, default=0)  # 0 until a worker takes it, then 1 (never re-run)
    holder: Mapped[str | None] = mapped_column(String(64), nullable=True)  # worker process running it, host:pid
    heartbeat_at: Mapped[float | None] = mapped_column(Float, nullable=True)  # its lease on the robot: + LEASE_S

    __table_args__ = (Index("ix_executions_team_seq", "team", "seq"),
                      Index("ux_executions_robot_active", "robot", unique=True, sqlite_where=_ACTIVE,
                            postgresql_where=_ACTIVE))


class JobData(Base):
    """A job's bytes: "input" (an uploaded file, under its sanitized name), "plan" (the saved plan of the attempt
    that completed it) and, while a split job runs, "piece.<first>" (a piece's planned moves, :class:`JobChunk`)."""

    __tablename__ = "job_data"
    job_id: Mapped[str] = mapped_column(String(32), primary_key=True)
    name: Mapped[str] = mapped_column(String(16), primary_key=True)  # "input", "plan" or a piece's "piece.<first>"
    data: Mapped[bytes] = mapped_column(LargeBinary)
    bytes: Mapped[int] = mapped_column(Integer)
    created_at: Mapped[float] = mapped_column(Float)


class JobChunk(Base):
    """A piece of a large job split across workers (celery backend, :mod:`.tasks.split`): its cutting passes
    ``first`` .. ``stop - 1`` planned (:func:`planner.plan.plan_piece`: their moves, with the rapids, turns and dwells
    before them) by whichever worker takes it; its planned moves are stored in :class:`JobData` as ``piece.<first>``
    in the transaction that marks it done. The pieces are the same in every attempt of the job (its input and
    settings never change), so a job started again keeps the pieces already planned; they are removed when the job
    ends."""

    __tablename__ = "job_chunks"
    job_id: Mapped[str] = mapped_column(String(32), primary_key=True)
    first: Mapped[int] = mapped_column(Integer, primary_key=True)
    stop: Mapped[int] = mapped_column(Integer)
    chords: Mapped[int] = mapped_column(Integer)  # CAM chords of its passes
    state: Mapped[str] = mapped_column(String(16))  # queued, running, done, failed
    takes: Mapped[int] = mapped_column(Integer, default=0)  # times a worker took it (a dead holder's: taken again)
    holder: Mapped[str | None] = mapped_column(String(64), nullable=True)  # host:pid
    heartbeat_at: Mapped[float | None] = mapped_column(Float, nullable=True)
    seconds: Mapped[float | None] = mapped_column(Float, nullable=True)  # the piece's wall time in its worker, s
    error_kind: Mapped[str | None] = mapped_column(String(16), nullable=True)
    error: Mapped[str | None] = mapped_column(Text, nullable=True)


class Worker(Base):
    """A ``planner worker`` process (celery backend): its heartbeats say it is alive."""

    __tablename__ = "workers"
    id: Mapped[str] = mapped_column(String(64), primary_key=True)  # host:pid
    queues: Mapped[str] = mapped_column(String(200))
    concurrency: Mapped[int] = mapped_column(Integer)
    started_at: Mapped[float] = mapped_column(Float)
    heartbeat_at: Mapped[float] = mapped_column(Float)
    busy: Mapped[int] = mapped_column(Integer, default=0)


def make_engine(url: str, *, background_checkpoints: bool = False) -> Engine:
    """An engine for ``url``; SQLite gets WAL mode, a busy timeout and foreign keys on every connection (and, with
    ``background_checkpoints``, no automatic WAL checkpoints: a :class:`Checkpointer` does them)."""
    if url.startswith("sqlite"):
        if url.startswith("sqlite:///") and url[len("sqlite:///"):] not in ("", ":memory:"):
            Path(url[len("sqlite:///"):]).resolve().parent.mkdir(parents=True, exist_ok=True)
        engine = create_engine(url, connect_args={"check_same_thread": False, "timeout": 30}, pool_size=20,
                               max_overflow=20)

        @event.listens_for(engine, "connect")
        def _pragmas(dbapi_conn, _record):  # noqa: ANN001
            cur = dbapi_conn.cursor()
            cur.execute("PRAGMA journal_mode=WAL")
            cur.execute("PRAGMA synchronous=NORMAL")
            cur.execute("PRAGMA busy_timeout=30000")
            cur.execute("PRAGMA foreign_keys=ON")
            if background_checkpoints:  # no checkpoint (and its fsync) inside a commit: see Checkpointer
                cur.execute("PRAGMA wal_autocheckpoint=0")
            cur.close()

        return engine
    return create_engine(url, pool_pre_ping=True, pool_size=20, max_overflow=20)  # the service's warm threads


def migrate(engine: Engine, revision: str = "head") -> None:
    """Bring the database to the newest schema (Alembic ``upgrade head``; ``revision``: to that one, for tests of
    a migration)."""
    from alembic import command
    from alembic.config import Config

    cfg = Config()
    cfg.set_main_option("script_location", str(Path(__file__).resolve().parent / "migrations"))
    with engine.begin() as conn:
        cfg.attributes["connection"] = conn
        command.upgrade(cfg, revision)


class Checkpointer(threading.Thread):
    """SQLite's WAL checkpoints in a thread of their own, every ``every`` s (PASSIVE: never waits for readers or
    writers). SQLite otherwise checkpoints inside the commit that fills the WAL past 1000 pages, and the fsync of
    the database file that a checkpoint makes then delays that commit, and the requests waiting for it, by tens of
    milliseconds on a busy disk."""

    def __init__(self, engine: Engine, every: float = 1.0):
        super().__init__(name="planner-checkpoints", daemon=True)
        self.engine = engine
        self.every = every
        self.stopping = threading.Event()

    def run(self) -> None:
        while not self.stopping.wait(self.every):
            self.checkpoint()
        self.checkpoint()

    def checkpoint(self) -> None:
        try:
            with self.engine.connect() as conn:
                conn.exec_driver_sql("PRAGMA wal_checkpoint(PASSIVE)")
        except Exception:  # the database is gone or busy: the next round tries again
            pass

    def stop(self) -> None:
        self.stopping.set()
        self.join(10.0)


def open_store(url: str, *, background_checkpoints: bool = False) -> tuple[Engine, sessionmaker]:
    """The engine (migrated) and a session factory (see :func:`make_engine`)."""
    engine = make_engine(url, background_checkpoints=background_checkpoints)
    migrate(engine)
    return engine, sessionmaker(engine, expire_on_commit=False)


def import_legacy_files(engine: Engine, data_dir: Path) -> int:
    """Jobs stored before their bytes moved into the database (0.1 kept an uploaded input under
    ``<data>/jobs/<id>/input/<name>`` and the plan as ``<data>/jobs/<id>/plan.<attempt>.job``): their files copied into
    :class:`JobData` once (the files are left where they are). The number of files imported."""
    from sqlalchemy import insert, select

    folder = data_dir / "jobs"
    if not folder.is_dir():
        return 0
    n = 0
    with engine.begin() as conn:
        have = {(j, name) for j, name in conn.execute(select(JobData.job_id, JobData.name))}
        rows = conn.execute(select(Job.id, Job.input_kind, Job.input_name, Job.job_file)).all()
        for job_id, kind, input_name, job_file in rows:
            wanted = []
            if kind == "file" and (job_id, "input") not in have:
                wanted.append(("input", folder / job_id / "input" / input_name))
            if job_file and (job_id, "plan") not in have:
                wanted.append(("plan", folder / job_id / job_file))
            for name, path in wanted:
                if path.is_file():
                    data = path.read_bytes()
                    conn.execute(insert(JobData).values(job_id=job_id, name=name, data=data, bytes=len(data),
                                                        created_at=now()))
                    n += 1
    return n


def now() -> float:
    return time.time()
