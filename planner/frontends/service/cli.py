"""``planner serve``, ``planner worker``, ``planner keys`` and ``planner teams``: :func:`add_subcommands` adds them to
the CLI's parser (``python -m planner.frontends.service serve|worker|keys|teams ...`` runs them alone).

``serve`` prints ``planner serve: listening on http://HOST:PORT`` once its socket is bound (``--port 0`` picks a
free port), then serves until SIGINT/SIGTERM, stopping its worker processes.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import socket
import sys

from planner.errors import PlannerError
from planner.frontends.service.config import DEFAULT_DB, ROLES, ServiceConfig, is_loopback, robots_from_env
from planner.frontends.service.store import DEFAULT_TEAM


def add_subcommands(sub) -> None:
    """Add ``serve``, ``worker``, ``keys`` and ``teams`` to an ``add_subparsers()`` object."""
    s = sub.add_parser("serve", help="run the REST service for path jobs (FastAPI under uvicorn)")
    s.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    s.add_argument("--port", type=int, default=8000, help="port (default 8000; 0 picks a free one)")
    s.add_argument("--workers", type=int, default=None, help="planning worker processes (default 2, PLANNER_WORKERS)")
    s.add_argument("--db", default=None, help=f"database URL (default PLANNER_DB or {DEFAULT_DB})")
    s.add_argument("--data", default=None, help="folder for inputs and saved jobs (default PLANNER_DATA or <db>.data)")
    s.add_argument("--job-timeout", type=float, default=None, help="seconds a job may plan (default 3600)")
    s.add_argument("--robots", default=None,
                   help="robots jobs may run on: a JSON file (or text) of name -> {host, model, io, modbus_port} or "
                        "{\"sim\": true} (default PLANNER_ROBOTS, else one simulated robot named sim)")
    s.add_argument("--log-level", default="warning", help="uvicorn log level (default warning)")
    s.set_defaults(func=cmd_serve)
    w = sub.add_parser("worker", help="run a Celery worker of the service's tasks (PLANNER_QUEUE=celery: planning "
                                      "and executions on this machine for every API replica)")
    w.add_argument("--concurrency", type=int, default=None,
                   help="tasks at once, each in a worker process of its own (default PLANNER_WORKERS, 2)")
    w.add_argument("--queues", default="plan,execute",
                   help="the queues served: plan, execute or both (default plan,execute)")
    w.add_argument("--db", default=None, help="database URL (default PLANNER_DB)")
    w.add_argument("--log-level", default="warning", help="Celery's log level (default warning)")
    w.set_defaults(func=cmd_worker)
    k = sub.add_parser("keys", help="create, list and revoke the service's API keys")
    k.add_argument("--db", default=None, help=f"database URL (default PLANNER_DB or {DEFAULT_DB})")
    ks = k.add_subparsers(dest="keys_command", required=True)
    c = ks.add_parser("create", help="create a key (printed once; only its hash is stored)")
    c.add_argument("--name", required=True, help="who or what uses the key")
    c.add_argument("--role", choices=list(ROLES), default="planner",
                   help="planner (default: submits, reads and cancels the team's jobs) or operator (also runs them on "
                        "the team's robots)")
    c.add_argument("--team", default=DEFAULT_TEAM,
                   help=f"the team whose jobs the key sees (default {DEFAULT_TEAM}; planner teams create NAME first)")
    c.set_defaults(func=cmd_keys_create)
    ks.add_parser("list", help="list the keys (id, role, team, name, created, revoked)").set_defaults(
        func=cmd_keys_list)
    r = ks.add_parser("revoke", help="revoke a key by its id")
    r.add_argument("key_id")
    r.set_defaults(func=cmd_keys_revoke)
    t = sub.add_parser("teams", help="create, list, give robots to and delete the service's teams (a key's team "
                                     "sees the team's jobs; its operators run them on the team's robots)")
    t.add_argument("--db", default=None, help=f"database URL (default PLANNER_DB or {DEFAULT_DB})")
    ts = t.add_subparsers(dest="teams_command", required=True)
    robots_help = ("robot names of PLANNER_ROBOTS separated by commas, 'all' (every configured robot) or 'none'")
    tc = ts.add_parser("create", help="create a team")
    tc.add_argument("name", help="1..32 of A-Z a-z 0-9 _ -")
    tc.add_argument("--robots", dest="team_robots", default="none",
                    help=robots_help + " (default none: a team of planners)")
    tc.set_defaults(func=cmd_teams_create)
    ts.add_parser("list", help="list the teams (name, robots, active keys, jobs, created)").set_defaults(
        func=cmd_teams_list)
    tr = ts.add_parser("robots", help="set the robots a team's operators may run its jobs on")
    tr.add_argument("name")
    tr.add_argument("team_robots", metavar="robots", help=robots_help)
    tr.set_defaults(func=cmd_teams_robots)
    td = ts.add_parser("delete", help="delete a team without active keys or jobs")
    td.add_argument("name")
    td.set_defaults(func=cmd_teams_delete)


def _config(args: argparse.Namespace) -> ServiceConfig:
    robots = getattr(args, "robots", None)
    return ServiceConfig.from_env(db_url=args.db, workers=getattr(args, "workers", None),
                                  data_dir=getattr(args, "data", None),
                                  job_timeout_s=getattr(args, "job_timeout", None),
                                  robots=None if robots is None else robots_from_env(robots, "--robots"))


def cmd_serve(args: argparse.Namespace) -> None:
    import uvicorn

    from planner.frontends.service.app import create_app

    cfg = _config(args)
    if cfg.dev_no_auth and not is_loopback(args.host):
        raise PlannerError(f"PLANNER_DEV_NO_AUTH=1 serves without keys and binds only to loopback, not {args.host!r}")
    check_store(args, cfg)
    if not is_loopback(args.host):
        print(f"planner serve: warning: binding {args.host}: the service is reachable from other hosts "
              "(API keys required)", file=sys.stderr)
    family = socket.AF_INET6 if ":" in args.host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM, socket.IPPROTO_TCP)  # asyncio sets TCP_NODELAY on its sockets
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((args.host, args.port))
    except OSError as exc:
        raise PlannerError(f"cannot bind {args.host}:{args.port}: {exc.strerror}") from None
    sock.listen(1024)
    sock.set_inheritable(True)
    host, port = sock.getsockname()[:2]
    mode = "; development mode: no API keys" if cfg.dev_no_auth else ""
    workers = f"{cfg.workers} workers" if cfg.queue == "local" else f"tasks to celery workers through {cfg.broker}"
    print(f"planner serve: listening on http://{host}:{port} ({workers}; db {cfg.db_url}{mode})", flush=True)
    config = uvicorn.Config(create_app(cfg), log_level=args.log_level, timeout_graceful_shutdown=5)
    signal.signal(signal.SIGTERM, _stopped)  # uvicorn re-raises the signal after its graceful shutdown
    try:
        uvicorn.Server(config).run(sockets=[sock])
    except KeyboardInterrupt:  # uvicorn re-raises SIGINT after its graceful shutdown
        pass


def cmd_worker(args: argparse.Namespace) -> None:
    from planner.frontends.service.tasks.celery_backend import run_worker, worker_queues

    cfg = ServiceConfig.from_env(options={"workers": "--concurrency"}, db_url=args.db, workers=args.concurrency)
    worker_queues(cfg, args.queues)  # (refused before the store is opened, or a file made)
    check_store(args, cfg)
    print(f"planner worker: {cfg.workers} tasks at once on queues {args.queues}; broker {cfg.broker}; db "
          f"{cfg.db_url}", flush=True)
    run_worker(cfg, cfg.workers, args.queues, args.log_level)


def _stopped(signum, frame) -> None:
    raise KeyboardInterrupt


def _sessions(args: argparse.Namespace):
    return _open(args, _config(args))


def _open(args: argparse.Namespace, cfg: ServiceConfig):
    """A session factory of the configuration's store (migrated); PlannerError naming PLANNER_DB (or --db) if the
    database cannot be opened (:func:`check_store`)."""
    from planner.frontends.service.store import open_store

    with _store_errors(args, cfg):
        return open_store(cfg.db_url)[1]


def check_store(args: argparse.Namespace, cfg: ServiceConfig) -> None:
    """The store opens and is migrated (before ``serve`` binds its socket or ``worker`` joins the broker): a
    database that cannot be opened or is not a database is one line naming PLANNER_DB (or --db), not a traceback."""
    from planner.frontends.service.store import open_store

    with _store_errors(args, cfg):
        open_store(cfg.db_url)[0].dispose()


@contextlib.contextmanager
def _store_errors(args: argparse.Namespace, cfg: ServiceConfig):
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import SQLAlchemyError

    try:
        yield
    except (SQLAlchemyError, OSError) as exc:
        orig = getattr(exc, "orig", None) or exc
        first = next((line.strip() for line in str(orig).splitlines() if line.strip()), type(orig).__name__)
        url = make_url(cfg.db_url).render_as_string(hide_password=True)
        where = "--db" if getattr(args, "db", None) else "PLANNER_DB"
        raise PlannerError(f"{where} {url}: the database cannot be opened: {first[:300]}") from None


def cmd_keys_create(args: argparse.Namespace) -> None:
    from planner.frontends.service.auth import create_key

    with _sessions(args)() as s:
        row, key = create_key(s, args.name, args.role, args.team)
    print(f"id {row.id}  role {row.role}  team {row.team}  name {row.name}")
    print(f"key {key}")
    print("(shown once: only its hash is stored)", file=sys.stderr)


def cmd_keys_list(args: argparse.Namespace) -> None:
    from planner.frontends.service.auth import list_keys

    with _sessions(args)() as s:
        rows = list_keys(s)
    print(f"{'id':<10} {'role':<9} {'team':<16} {'created (UTC)':<20} {'revoked (UTC)':<20} name")
    for r in rows:
        revoked = "-" if r.revoked_at is None else _utc(r.revoked_at)
        print(f"{r.id:<10} {r.role:<9} {r.team:<16} {_utc(r.created_at):<20} {revoked:<20} {r.name}")


def cmd_keys_revoke(args: argparse.Namespace) -> None:
    from planner.frontends.service.auth import revoke_key

    with _sessions(args)() as s:
        row = revoke_key(s, args.key_id)
    print(f"revoked {row.id} ({row.name})")


def _utc(t: float) -> str:
    import time

    return time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(t))


def _team_robots(args: argparse.Namespace, cfg: ServiceConfig) -> tuple[str, ...] | None:
    """``--robots`` of ``planner teams``; a warning for a name this environment's PLANNER_ROBOTS does not
    configure (the service may be configured elsewhere: the name is kept)."""
    from planner.frontends.service.teams import parse_robots

    names = parse_robots(args.team_robots)
    unknown = [n for n in names or () if cfg.robot(n) is None]
    if unknown:
        configured = ", ".join(r.name for r in cfg.robots)
        print(f"planner teams: warning: {', '.join(unknown)} not in this environment's PLANNER_ROBOTS (configured: "
              f"{configured}); the team may use {'it' if len(unknown) == 1 else 'them'} where the service configures "
              "that name", file=sys.stderr)
    return names


def cmd_teams_create(args: argparse.Namespace) -> None:
    from planner.frontends.service.teams import create_team

    _team_with_robots(args, create_team)


def _team_with_robots(args: argparse.Namespace, change) -> None:
    """``change(session, name, robots)`` (create a team, set its robots) and the line naming the team's robots."""
    from planner.frontends.service.teams import robots_text

    cfg = _config(args)
    robots = _team_robots(args, cfg)
    with _open(args, cfg)() as s:
        row = change(s, args.name, robots)
    print(f"team {row.name}  robots {robots_text(robots)}")


def cmd_teams_list(args: argparse.Namespace) -> None:
    from planner.frontends.service.teams import list_teams, robots_text

    with _sessions(args)() as s:
        rows = list_teams(s)
    print(f"{'team':<16} {'keys':>5} {'jobs':>8} {'created (UTC)':<20} robots")
    for t in rows:
        print(f"{t.name:<16} {t.keys:>5} {t.jobs:>8} {_utc(t.created_at):<20} {robots_text(t.robots)}")


def cmd_teams_robots(args: argparse.Namespace) -> None:
    from planner.frontends.service.teams import set_robots

    _team_with_robots(args, set_robots)


def cmd_teams_delete(args: argparse.Namespace) -> None:
    from planner.frontends.service.teams import delete_team

    with _sessions(args)() as s:
        delete_team(s, args.name)
    print(f"deleted team {args.name}")


def main(argv: list[str] | None = None) -> int:
    """``python -m planner.frontends.service serve|worker|keys|teams ...`` (the same as ``planner serve|worker|keys|
    teams``)."""
    ap = argparse.ArgumentParser(prog="planner")
    add_subcommands(ap.add_subparsers(dest="command", required=True))
    args = ap.parse_args(argv)
    try:
        args.func(args)
    except PlannerError as exc:
        print(f"planner: error: {exc}", file=sys.stderr)
        return 2
    return 0
