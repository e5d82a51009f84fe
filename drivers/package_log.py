"""Every RTDE data package of a run: a recording connection of its own, read whole package by package.

Program mode watches the controller from Python, a loop of a few ms that a loaded machine can stall for tens of
ms. Read through ur_rtde's ``RTDEReceiveInterface`` a sample is not one data package: each getter
(``getTimestamp()``, ``getActualTCPPose()``, ...) reads the interface's latest state on its own, so a package
arriving between two calls gives a sample with one package's time and the next one's pose (the speed computed
from such samples spikes to twice the feed, and drops to 0 at a package read twice); and a poll loop reads
only the latest package, missing those between two polls (at 20x fast-forward a stall could hide a rapid's brief
output-off). ur_rtde 1.6.5's ``startFileRecording`` does not help: it writes the latest state from a thread of
its own at the recipe's rate, another poll (measured against the simulated controller at 1x: of 1500 packages in
3 s, 101 written twice, 160 missed, some rows mixing two packages).

:class:`PackageLog` opens a connection of its own to the controller's RTDE server (port 30004, protocol version
2, one output recipe: timestamp, actual TCP pose, actual joints, actual digital output bits and the runtime state
at the controller's rate) and reads its data packages from the socket whenever asked: the kernel's socket buffer
holds what arrives meanwhile, so a stall of the caller loses nothing, and each sample is one package, whole.
Decoded vectorized (the data packages are of one size; a text message between them is skipped). Its memory is
what arrived since the last read. The runtime state marks the program's start to the package (the start of a
program run's recording, :meth:`drivers.ur.URDriver._program_start`).
"""

from __future__ import annotations

import socket
import struct
import time

import numpy as np

from drivers.base import ConnectionLostError

#: The recipe: (name, RTDE type) -> 15 columns (timestamp, pose 6, joints 6, bits, runtime state: 1 stopped,
#: 2 playing, 4 paused).
RECIPE = (("timestamp", "DOUBLE"), ("actual_TCP_pose", "VECTOR6D"), ("actual_q", "VECTOR6D"),
          ("actual_digital_output_bits", "UINT64"), ("runtime_state", "UINT32"))
COLUMNS = 15
_HEADER = struct.Struct(">HB")
_V, _O, _S, _P, _U = ord("V"), ord("O"), ord("S"), ord("P"), ord("U")
#: A data package of the recipe: header (size, type), recipe id, the fields (big-endian).
_DATA = np.dtype([("size", ">u2"), ("kind", "u1"), ("recipe", "u1"), ("t", ">f8"), ("x", ">f8", (6,)),
                  ("q", ">f8", (6,)), ("bits", ">u8"), ("state", ">u4")])


class PackageLog:
    """A recording connection to the RTDE server at ``host`` (see the module doc): :meth:`read` gives every data
    package that arrived since the last call. ConnectionLostError when it cannot be set up."""

    def __init__(self, host: str, frequency: float = 500.0, *, port: int = 30004, timeout: float = 2.0) -> None:
        self.host = host
        self._buf = bytearray()
        self._held = np.zeros((0, COLUMNS))
        self.closed = False
        try:
            self._sock = socket.create_connection((host, port), timeout=timeout)
        except OSError as exc:
            raise ConnectionLostError(f"cannot open a recording connection to {host}:{port} (RTDE): {exc}") from exc
        try:
            self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)  # a stall of seconds fits
            if self._ask(_V, struct.pack(">H", 2))[:1] != b"\x01":
                raise ConnectionLostError(f"the controller at {host} refused RTDE protocol version 2")
            names = ",".join(n for n, _ in RECIPE).encode()
            reply = self._ask(_O, struct.pack(">d", float(frequency)) + names)
            self.recipe = reply[0] if reply else 0
            types = tuple(reply[1:].decode("ascii", "replace").split(","))
            if self.recipe == 0 or types != tuple(t for _, t in RECIPE):
                raise ConnectionLostError(f"the controller at {host} refused the recording's recipe: {types}")
            if self._ask(_S)[:1] != b"\x01":
                raise ConnectionLostError(f"the controller at {host} did not start the recording's data")
            self._sock.setblocking(False)
        except (OSError, ConnectionLostError) as exc:
            self._sock.close()
            self.closed = True
            if isinstance(exc, ConnectionLostError):
                raise
            raise ConnectionLostError(f"the recording connection to {host} failed: {exc}") from exc

    def _ask(self, kind: int, payload: bytes = b"") -> bytes:
        """Send a request and return the payload of its reply (the packages before it, text messages, skipped)."""
        self._sock.sendall(_HEADER.pack(3 + len(payload), kind) + payload)
        end = time.monotonic() + 2.0
        while True:
            while len(self._buf) >= 3:
                size, got = _HEADER.unpack_from(self._buf)
                if size < 3 or len(self._buf) < size:
                    break
                body = bytes(self._buf[3:size])
                del self._buf[:size]
                if got == kind:
                    return body
            if time.monotonic() > end:
                raise ConnectionLostError(f"no answer from the controller at {self.host} to RTDE request {chr(kind)}")
            chunk = self._sock.recv(65536)
            if not chunk:
                raise ConnectionLostError(f"the controller at {self.host} closed the recording connection")
            self._buf += chunk

    def _drain(self) -> None:
        while not self.closed:
            try:
                chunk = self._sock.recv(1 << 20)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                self.closed = True
                return
            if not chunk:
                self.closed = True
                return
            self._buf += chunk

    def read(self) -> np.ndarray:
        """The data packages received since the last call: (m, 15) rows of timestamp s, actual TCP pose (6) m,
        rad, actual joints (6) rad, output bits, runtime state; in the controller's order (each package whole; the
        rows given back with :meth:`unread` first)."""
        self._drain()
        out = [self._held] if self._held.shape[0] else []
        self._held = np.zeros((0, COLUMNS))
        buf = self._buf
        size = _DATA.itemsize
        while len(buf) >= 3:
            n = len(buf) // size
            m = 0
            if n:
                head = np.frombuffer(bytes(buf[:n * size]), dtype=_DATA)  # a copy: the buffer is cut below
                ok = (head["size"] == size) & (head["kind"] == _U) & (head["recipe"] == self.recipe)
                m = n if ok.all() else int(np.argmin(ok))
                if m:
                    d = head[:m]
                    out.append(np.column_stack((d["t"], d["x"], d["q"], d["bits"].astype(float),
                                                d["state"].astype(float))))
                    del buf[:m * size]
                    if m == n:
                        break
            # a package other than a data package of the recipe (a text message): skipped whole
            psize, _ = _HEADER.unpack_from(buf)
            if psize < 3:
                raise ConnectionLostError(f"the controller at {self.host} sent a malformed RTDE package")
            if len(buf) < psize:
                break
            del buf[:psize]
        return np.concatenate(out) if out else np.zeros((0, COLUMNS))

    def unread(self, rows: np.ndarray) -> None:
        """Give back ``rows`` (from :meth:`read`, in order): the next read returns them first."""
        self._held = np.concatenate((rows, self._held))

    def close(self) -> None:
        """Stop the data (RTDE pause, best effort) and close the connection."""
        if not self.closed:
            try:
                self._sock.setblocking(True)
                self._sock.settimeout(0.2)
                self._sock.sendall(_HEADER.pack(3, _P))
            except OSError:
                pass
        self.closed = True
        self._sock.close()
