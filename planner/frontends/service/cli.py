"""``planner serve``, ``planner worker`` and ``planner keys``: :func:`add_subcommands` adds them to the CLI's parser
(``python -m planner.frontends.service serve|worker|keys ...`` runs them alone).

``serve`` prints ``planner serve: listening on http://HOST:PORT`` once its socket is bound (``--port 0`` picks a
free port), then serves until SIGINT/SIGTERM, stopping its worker processes.
"""

from __future__ import annotations

import argparse
import signal
import socket
import sys

from planner.errors import PlannerError
from planner.frontends.service.config import DEFAULT_DB, ROLES, ServiceConfig, is_loopback, robots_from_env


def add_subcommands(sub) -> None:
    """Add ``serve`` and ``keys`` to an ``add_subparsers()`` object."""
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
    c.add_argument("--role", choices=list(ROLES), default="planner", help="planner (default) or operator")
    c.set_defaults(func=cmd_keys_create)
    ks.add_parser("list", help="list the keys (id, role, name, created, revoked)").set_defaults(func=cmd_keys_list)
    r = ks.add_parser("revoke", help="revoke a key by its id")
    r.add_argument("key_id")
    r.set_defaults(func=cmd_keys_revoke)


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
    from planner.frontends.service.tasks.celery_backend import run_worker

    cfg = ServiceConfig.from_env(db_url=args.db, workers=args.concurrency)
    print(f"planner worker: {cfg.workers} tasks at once on queues {args.queues}; broker {cfg.broker}; db "
          f"{cfg.db_url}", flush=True)
    run_worker(cfg, cfg.workers, args.queues, args.log_level)


def _stopped(signum, frame) -> None:
    raise KeyboardInterrupt


def _sessions(args: argparse.Namespace):
    from planner.frontends.service.store import open_store

    return open_store(_config(args).db_url)[1]


def cmd_keys_create(args: argparse.Namespace) -> None:
    from planner.frontends.service.auth import create_key

    with _sessions(args)() as s:
        row, key = create_key(s, args.name, args.role)
    print(f"id {row.id}  role {row.role}  name {row.name}")
    print(f"key {key}")
    print("(shown once: only its hash is stored)", file=sys.stderr)


def cmd_keys_list(args: argparse.Namespace) -> None:
    import time

    from planner.frontends.service.auth import list_keys

    with _sessions(args)() as s:
        rows = list_keys(s)
    print(f"{'id':<10} {'role':<9} {'created (UTC)':<20} {'revoked (UTC)':<20} name")
    for r in rows:
        created = time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(r.created_at))
        revoked = "-" if r.revoked_at is None else time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(r.revoked_at))
        print(f"{r.id:<10} {r.role:<9} {created:<20} {revoked:<20} {r.name}")


def cmd_keys_revoke(args: argparse.Namespace) -> None:
    from planner.frontends.service.auth import revoke_key

    with _sessions(args)() as s:
        row = revoke_key(s, args.key_id)
    print(f"revoked {row.id} ({row.name})")


def main(argv: list[str] | None = None) -> int:
    """``python -m planner.frontends.service serve|worker|keys ...`` (the same as ``planner serve|worker|keys``)."""
    ap = argparse.ArgumentParser(prog="planner")
    add_subcommands(ap.add_subparsers(dest="command", required=True))
    args = ap.parse_args(argv)
    try:
        args.func(args)
    except PlannerError as exc:
        print(f"planner: error: {exc}", file=sys.stderr)
        return 2
    return 0
