"""A real PostgreSQL server for tests: ``initdb`` and ``pg_ctl`` in a temporary folder, listening on 127.0.0.1
(a free port) and a unix socket in that folder; stopped and removed afterwards.

The binaries come from ``/usr/lib/postgresql/*/bin`` (Debian's postgresql package) or PATH. Without them the
fixture FAILS, naming the package to install; it never skips. Run as root (as in CI), the server runs as the
``postgres`` user the package creates (initdb refuses root).

Fixtures: ``postgres`` (one server per test session) and ``pg_url`` (a new empty database on it for each test, as
a SQLAlchemy URL for psycopg 3: ``postgresql+psycopg://planner@127.0.0.1:PORT/NAME``).
"""

from __future__ import annotations

import atexit
import glob
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
import uuid
from pathlib import Path

import pytest

INSTALL = "apt-get install -y postgresql (Debian's PostgreSQL server: initdb, pg_ctl, postgres)"


def postgres_bin() -> Path:
    """The folder of initdb, pg_ctl and postgres (the newest version installed); AssertionError if absent."""
    candidates = sorted(glob.glob("/usr/lib/postgresql/*/bin"), key=lambda p: int(Path(p).parent.name)
                        if Path(p).parent.name.isdigit() else 0)
    for folder in reversed(candidates):
        if all((Path(folder) / b).is_file() for b in ("initdb", "pg_ctl", "postgres")):
            return Path(folder)
    found = shutil.which("pg_ctl")
    if found:
        folder = Path(os.path.realpath(found)).parent
        if all((folder / b).is_file() for b in ("initdb", "pg_ctl", "postgres")):
            return folder
    raise AssertionError(f"the PostgreSQL tests need a PostgreSQL server's binaries; none found in "
                         f"/usr/lib/postgresql/*/bin or PATH: {INSTALL}")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class PostgresServer:
    """One PostgreSQL server in a temporary folder (trust authentication, loopback only, fsync off: test data)."""

    def __init__(self) -> None:
        self.bin = postgres_bin()
        self.folder: Path | None = None
        self.port = 0
        self.user = "planner"
        self._run_as: str | None = None

    def _run(self, *args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
        r = subprocess.run([str(self.bin / args[0]), *args[1:]], capture_output=True, text=True, timeout=timeout,
                           user=self._run_as, cwd=self.folder)
        if r.returncode != 0:
            raise AssertionError(f"{args[0]} failed ({r.returncode}): {r.stderr.strip() or r.stdout.strip()}"
                                 + self._log_tail())
        return r

    def _log_tail(self) -> str:
        log = self.folder / "server.log" if self.folder else None
        return f"\nserver log:\n{log.read_text()[-3000:]}" if log and log.exists() else ""

    def start(self) -> PostgresServer:
        self.folder = Path(tempfile.mkdtemp(prefix="planner-pg-"))
        if os.geteuid() == 0:
            try:
                account = pwd.getpwnam("postgres")
            except KeyError:
                raise AssertionError(f"running as root, the server needs the 'postgres' user: {INSTALL}") from None
            os.chown(self.folder, account.pw_uid, account.pw_gid)
            self._run_as = "postgres"
        data = self.folder / "data"
        self._run("initdb", "-D", str(data), "-U", self.user, "--auth=trust", "--encoding=UTF8", "--no-sync",
                  "--no-instructions", timeout=120)
        for attempt in range(3):
            self.port = _free_port()
            options = (f"-c listen_addresses=127.0.0.1 -p {self.port} -c unix_socket_directories={self.folder} "
                       "-c fsync=off -c synchronous_commit=off -c full_page_writes=off -c max_connections=200")
            try:
                self._run("pg_ctl", "-D", str(data), "-l", str(self.folder / "server.log"), "-o", options, "-w",
                          "-t", "60", "start", timeout=90)
                break
            except AssertionError:
                if attempt == 2 or "already in use" not in self._log_tail():
                    raise
        atexit.register(self.stop)
        return self

    def pause(self) -> None:
        """Stop the server (fast shutdown: clients are disconnected), keeping its data and port."""
        assert self.folder is not None
        self._run("pg_ctl", "-D", str(self.folder / "data"), "-m", "fast", "-w", "stop", timeout=60)

    def resume(self) -> None:
        """Start a paused server again on the same port."""
        assert self.folder is not None
        options = (f"-c listen_addresses=127.0.0.1 -p {self.port} -c unix_socket_directories={self.folder} "
                   "-c fsync=off -c synchronous_commit=off -c full_page_writes=off -c max_connections=200")
        self._run("pg_ctl", "-D", str(self.folder / "data"), "-l", str(self.folder / "server.log"), "-o", options,
                  "-w", "-t", "60", "start", timeout=90)

    def url(self, database: str = "postgres") -> str:
        return f"postgresql+psycopg://{self.user}@127.0.0.1:{self.port}/{database}"

    def create_database(self, name: str | None = None) -> str:
        """A new empty database; its SQLAlchemy URL."""
        import psycopg

        name = name or f"t_{uuid.uuid4().hex[:12]}"
        with psycopg.connect(host="127.0.0.1", port=self.port, user=self.user, dbname="postgres",
                             autocommit=True) as conn:
            conn.execute(f'CREATE DATABASE "{name}"')
        return self.url(name)

    def stop(self) -> None:
        if self.folder is None:
            return
        folder, self.folder = self.folder, None
        data = folder / "data"
        if (data / "postmaster.pid").exists():
            subprocess.run([str(self.bin / "pg_ctl"), "-D", str(data), "-m", "immediate", "-w", "stop"],
                           capture_output=True, timeout=60, user=self._run_as, cwd=folder)
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(scope="session")
def postgres():
    server = PostgresServer().start()
    yield server
    server.stop()


@pytest.fixture
def pg_url(postgres) -> str:
    return postgres.create_database()
