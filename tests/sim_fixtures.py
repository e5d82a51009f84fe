"""Fixtures that start simulated UR controllers (sim.SimController) for tests, one address each.

Every controller gets its own loopback address (the UR ports are fixed): 127.0.<100 + xdist worker>.<n>,
so tests run in parallel under pytest-xdist. Use ``make_sim(**kwargs)``; everything started is stopped
after the test, pass or fail.
"""

from __future__ import annotations

import itertools
import os

import pytest

from sim import SimController

_counter = itertools.count(2)


def next_host() -> str:
    """A loopback address no other simulator of this test session uses."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    idx = int(worker[2:]) if worker.startswith("gw") and worker[2:].isdigit() else 0
    n = next(_counter)
    if n > 254:
        raise RuntimeError("more than 253 simulated controllers in one test worker")
    return f"127.0.{100 + idx}.{n}"


@pytest.fixture
def make_sim():
    """Factory: ``make_sim(model="ur5e", speed=1.0, record=None, modbus_port=None)`` -> started SimController."""
    sims: list[SimController] = []

    def make(**kwargs) -> SimController:
        kwargs.setdefault("modbus_port", None)
        sim = SimController(next_host(), **kwargs).start()
        sims.append(sim)
        return sim

    yield make
    for sim in sims:
        sim.stop()


@pytest.fixture(scope="module")
def shared_sim():
    """One controller for a module's tests that leave it as they found it."""
    sim = SimController(next_host(), modbus_port=None).start()
    yield sim
    sim.stop()


# ---- a raw RTDE client, for packages the real clients never send -------------------------------
import socket  # noqa: E402
import struct  # noqa: E402


class RawRTDE:
    """A bare RTDE socket: send any package, read the next reply package (type, payload)."""

    def __init__(self, host: str, timeout: float = 3.0) -> None:
        self.sock = socket.create_connection((host, 30004), timeout=timeout)
        self.buf = b""

    def send(self, kind: int | str, payload: bytes = b"", size: int | None = None) -> None:
        kind = ord(kind) if isinstance(kind, str) else kind
        self.sock.sendall(struct.pack(">HB", size if size is not None else 3 + len(payload), kind) + payload)

    def recv(self, skip_data: bool = True) -> tuple[str, bytes]:
        """The next package (skipping 'U' data packages unless ``skip_data`` is False)."""
        while True:
            while len(self.buf) < 3 or len(self.buf) < struct.unpack(">H", self.buf[:2])[0]:
                chunk = self.sock.recv(65536)
                if not chunk:
                    raise ConnectionError("connection closed by the controller")
                self.buf += chunk
            size, kind = struct.unpack(">HB", self.buf[:3])
            payload, self.buf = self.buf[3:size], self.buf[size:]
            if kind == ord("U") and skip_data:
                continue
            return chr(kind), payload

    @staticmethod
    def text(payload: bytes) -> str:
        """The message of an 'M' package."""
        n = payload[0]
        return payload[1 : 1 + n].decode()

    def close(self) -> None:
        self.sock.close()
