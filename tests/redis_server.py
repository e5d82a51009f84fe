"""A real Redis server for tests: Debian's ``redis-server`` on 127.0.0.1 (a free port), no persistence to disk unless
asked, in a temporary folder; stopped and removed afterwards. Without the binary the fixture FAILS, naming the
package to install; it never skips.

Fixture: ``redis`` (one server per test session).
"""

from __future__ import annotations

import atexit
import shutil
import socket
import subprocess
import tempfile
import time
from pathlib import Path

import pytest

INSTALL = "apt-get install -y redis-server (Debian's Redis server)"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class RedisServer:
    """One ``redis-server`` (loopback only). ``appendonly``: its data kept across :meth:`restart` (as a production
    broker should be configured)."""

    def __init__(self, appendonly: bool = True) -> None:
        found = shutil.which("redis-server") or ("/usr/bin/redis-server" if Path("/usr/bin/redis-server").is_file()
                                                 else None)
        if found is None:
            raise AssertionError(f"the celery backend's tests need a Redis server; redis-server not found: {INSTALL}")
        self.binary = found
        self.appendonly = appendonly
        self.folder = Path(tempfile.mkdtemp(prefix="planner-redis-"))
        self.port = _free_port()
        self.proc: subprocess.Popen | None = None
        atexit.register(self.stop)

    @property
    def url(self) -> str:
        return f"redis://127.0.0.1:{self.port}/0"

    def start(self) -> RedisServer:
        args = [self.binary, "--port", str(self.port), "--bind", "127.0.0.1", "--save", "", "--dir", str(self.folder),
                "--appendonly", "yes" if self.appendonly else "no", "--appendfsync", "always", "--protected-mode", "yes",
                "--logfile", str(self.folder / "redis.log")]
        self.proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        deadline = time.monotonic() + 20
        while True:
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=1) as s:
                    s.sendall(b"PING\r\n")
                    if s.recv(64).startswith(b"+PONG"):
                        return self
            except OSError:
                pass
            if self.proc.poll() is not None or time.monotonic() > deadline:
                log = (self.folder / "redis.log")
                raise AssertionError(f"redis-server did not start on 127.0.0.1:{self.port}: "
                                     f"{log.read_text()[-2000:] if log.exists() else self.proc.stderr}")
            time.sleep(0.05)

    def shutdown(self) -> None:
        """Stop the server (SIGTERM: it writes its append-only file first)."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait(20)
        self.proc = None

    def restart(self, down_s: float = 0.0) -> None:
        self.shutdown()
        time.sleep(down_s)
        self.start()

    def stop(self) -> None:
        self.shutdown()
        shutil.rmtree(self.folder, ignore_errors=True)


@pytest.fixture(scope="session")
def redis():
    server = RedisServer().start()
    yield server
    server.stop()
