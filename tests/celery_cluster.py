"""The celery backend's topology for tests, on real servers (tests/pg_server.py, tests/redis_server.py): API replicas
(``planner serve`` with ``PLANNER_QUEUE=celery``) and ``planner worker`` processes on one PostgreSQL database and one
Redis database, each a subprocess on loopback.

:class:`CeleryService` is a :class:`~tests.test_service_server.ServiceProcess` (the REST tests run against it
unchanged) that owns its workers; :class:`WorkerProcess` is one ``planner worker``.
"""

from __future__ import annotations

import itertools
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from tests.test_service_server import ServiceProcess

_redis_db = itertools.count(1)


def fresh_broker(redis) -> str:
    """A Redis database of its own (1..15, flushed) on the session's server: its URL."""
    import socket

    n = 1 + (next(_redis_db) - 1) % 15
    with socket.create_connection(("127.0.0.1", redis.port), timeout=5) as s:
        s.sendall(f"SELECT {n}\r\nFLUSHDB\r\n".encode())
        s.recv(64)
    return f"redis://127.0.0.1:{redis.port}/{n}"


def fresh_database(postgres) -> str:
    """A new PostgreSQL database, migrated (the replicas and workers then start on the schema at once)."""
    from planner.frontends.service.store import open_store

    url = postgres.create_database()
    engine, _ = open_store(url)
    engine.dispose()
    return url


class WorkerProcess:
    """``planner worker`` in a subprocess (its log in ``folder``)."""

    def __init__(self, folder: Path, env: dict, concurrency: int = 1, queues: str = "plan,execute", name: str = "w"):
        self.folder = Path(folder)
        self.env = env
        self.concurrency = concurrency
        self.queues = queues
        self.log = self.folder / f"worker-{name}.log"
        self.proc: subprocess.Popen | None = None

    def start(self) -> WorkerProcess:
        out = open(self.log, "ab")  # noqa: SIM115 (kept open for the process)
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "planner.frontends.service", "worker", "--concurrency", str(self.concurrency),
             "--queues", self.queues], cwd=self.folder, env=self.env, stdout=out, stderr=subprocess.STDOUT)
        out.close()
        return self

    def children(self, name: str | None = None) -> list[int]:
        """The worker's child processes (named ``name``: planner-work, planner-exec)."""
        if self.proc is None or self.proc.poll() is not None:
            return []
        pids: list[int] = []
        for task in Path(f"/proc/{self.proc.pid}/task").iterdir():
            try:
                pids += [int(x) for x in (task / "children").read_text().split()]
            except OSError:
                continue
        out = []
        for p in pids:
            try:
                comm = Path(f"/proc/{p}/comm").read_text().strip()
            except OSError:
                continue
            if name is None or comm == name:
                out.append(p)
        return out

    def kill(self) -> None:
        """SIGKILL, as a crash or a machine lost (its worker processes die with it)."""
        assert self.proc is not None
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(10)

    def stop(self) -> int:
        if self.proc is None or self.proc.poll() is not None:
            return 0 if self.proc is None else self.proc.returncode
        self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            return self.proc.wait(10)


class CeleryService(ServiceProcess):
    """An API replica of the celery backend and the workers it waits for (``workers`` worker processes of one task
    each, started with it unless ``own_workers`` is False: a second replica shares the first one's)."""

    def __init__(self, folder: Path, *, db: str, broker: str, workers: int = 1, own_workers: bool = True,
                 dev: bool = True, env: dict | None = None):
        env = {"PLANNER_QUEUE": "celery", "PLANNER_BROKER": broker, "PLANNER_DB": db,
               "PLANNER_DATA": str(Path(folder) / "data"), **(env or {})}
        super().__init__(folder, workers=workers, dev=dev, env=env)
        self.db = db
        self.data = self.folder / "data"
        self.broker = broker
        self.pool: list[WorkerProcess] = []
        if own_workers:
            self.pool = [WorkerProcess(self.folder, self.env, name=str(i)) for i in range(workers)]

    def start(self, timeout: float = 90.0, port: int = 0) -> CeleryService:
        for w in self.pool:
            if w.proc is None or w.proc.poll() is not None:
                w.start()
        try:
            super().start(timeout, port)
        except BaseException:
            for w in self.pool:
                w.stop()
            raise
        return self

    def _wait_healthy(self, timeout: float) -> None:
        try:
            super()._wait_healthy(timeout)
        except AssertionError as exc:
            logs = "\n".join(w.log.read_text()[-3000:] for w in self.pool if w.log.exists())
            raise AssertionError(f"{exc}\nworkers:\n{logs}") from None

    def children(self, name: str | None = None) -> list[int]:
        return super().children(name) + [p for w in self.pool for p in w.children(name)]

    def stop(self) -> int:
        code = super().stop()
        for w in self.pool:
            w.stop()
        return code

    def kill(self) -> None:
        super().kill()


def wait_for(predicate, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {timeout} s: {what}")
        time.sleep(0.05)


def env_without_planner() -> dict:
    return {k: v for k, v in os.environ.items() if not k.startswith("PLANNER_")}
