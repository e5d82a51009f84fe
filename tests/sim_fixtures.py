"""Fixtures that start simulated UR controllers (sim.SimController) for tests, one address each.

Every controller gets its own loopback address (the UR ports are fixed), a random free one in
127.100-250.x.x, so tests run in parallel under pytest-xdist and beside other sessions. Use ``make_sim(**kwargs)``; everything started is stopped
after the test, pass or fail.
"""

from __future__ import annotations

import os
import random
import socket
import time

import pytest

from sim import SimController, SimError

_rng = random.Random(os.getpid() ^ int(time.time() * 1e6))
_PORTS = (30004, 29999, 30001, 30002, 30003)


def _free(host: str) -> bool:
    for port in _PORTS:
        with socket.socket() as s:
            try:
                s.bind((host, port))
            except OSError:
                return False
    return True


def next_host() -> str:
    """A loopback address on which nothing serves the UR ports (random: sessions run side by side)."""
    for _ in range(200):
        host = f"127.{_rng.randint(100, 250)}.{_rng.randint(0, 255)}.{_rng.randint(2, 254)}"
        if _free(host):
            return host
    raise RuntimeError("no free loopback address for a simulated controller")


def eventually(condition, timeout: float = 3.0) -> bool:
    """Whether ``condition()`` becomes true within ``timeout`` s of wall time (polled every 10 ms): the state
    reaches the client with the next RTDE data packages, later when the machine is loaded."""
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            return False
        time.sleep(0.01)
    return True


def start_sim(**kwargs) -> SimController:
    """A started SimController on a free address (retried if another session took it meanwhile)."""
    kwargs.setdefault("modbus_port", None)
    for attempt in range(3):
        try:
            return SimController(next_host(), **kwargs).start()
        except SimError as exc:
            if "Address already in use" not in str(exc) or attempt == 2:
                raise
    raise AssertionError("unreachable")


@pytest.fixture
def make_sim():
    """Factory: ``make_sim(model="ur5e", speed=1.0, record=None, modbus_port=None)`` -> started SimController."""
    sims: list[SimController] = []

    def make(**kwargs) -> SimController:
        sim = start_sim(**kwargs)
        sims.append(sim)
        return sim

    yield make
    for sim in sims:
        sim.stop()


@pytest.fixture(scope="module")
def shared_sim():
    """One controller for a module's tests that leave it as they found it."""
    sim = start_sim()
    yield sim
    sim.stop()


# ---- a raw RTDE client, for packages the real clients never send -------------------------------
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


def signal_state(pid: int) -> str:
    """A process's blocked, ignored and caught signals (/proc/PID/status, hexadecimal masks; bit 1 is SIGINT): what
    a test says when a process did not stop on a signal."""
    try:
        with open(f"/proc/{pid}/status") as f:
            return " ".join(line.strip().replace(":\t", "=") for line in f if line.startswith(("SigBlk", "SigIgn",
                                                                                                  "SigCgt")))
    except OSError as exc:
        return f"(no /proc/{pid}/status: {exc})"
