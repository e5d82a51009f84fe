"""A client connection's output side: non-blocking writes with a bounded backlog, as a controller serves its streams.

A controller never waits for a client: what the socket does not take at once is kept and sent with the next write
or :meth:`OutputStream.flush`; a client that leaves more than `MAX_BACKLOG` bytes unread is dropped (a vanished
client), and so is one whose socket fails. A stream can start held (:meth:`OutputStream.release` sends what was
written meanwhile).
"""

from __future__ import annotations

import contextlib
import socket
import threading

#: Bytes a client may leave unread before the controller drops it (a vanished client).
MAX_BACKLOG = 1 << 20


class OutputStream:
    """The sending side of one client connection on ``sock``."""

    def __init__(self, sock: socket.socket, held: bool = False) -> None:
        self.sock = sock
        self.closed = False
        self.held = held
        self._out = bytearray()
        self._lock = threading.Lock()

    def write(self, data: bytes) -> None:
        """Queue ``data`` and send as much as the socket takes without blocking."""
        with self._lock:
            if self.closed:
                return
            if self._out or self.held:
                self._out += data
                if not self.held:
                    self._flush_locked()
                return
            # nothing queued (the usual case): straight to the socket, only what it does not take is kept
            try:
                n = self.sock.send(data, socket.MSG_DONTWAIT)
            except (BlockingIOError, InterruptedError):
                n = 0
            except OSError:
                self._close_locked()
                return
            if n < len(data):
                self._out += memoryview(data)[n:]
                if len(self._out) > MAX_BACKLOG:
                    self._close_locked()

    @property
    def backlog(self) -> int:
        """Bytes written but not yet taken by the socket."""
        return len(self._out)

    def flush(self) -> None:
        """Send what is queued, as far as the socket takes it without blocking."""
        with self._lock:
            if self._out and not self.closed and not self.held:
                self._flush_locked()

    def release(self) -> None:
        """Stop holding the output back: send what was written meanwhile."""
        with self._lock:
            self.held = False
            if self._out and not self.closed:
                self._flush_locked()

    def _flush_locked(self) -> None:
        try:
            while self._out:
                n = self.sock.send(self._out, socket.MSG_DONTWAIT)
                del self._out[:n]
        except (BlockingIOError, InterruptedError):
            if len(self._out) > MAX_BACKLOG:
                self._close_locked()
        except OSError:
            self._close_locked()

    def close(self) -> None:
        """Hang up (idempotent)."""
        with self._lock:
            self._close_locked()

    def _close_locked(self) -> None:
        if self.closed:
            return
        self.closed = True
        with contextlib.suppress(OSError):
            self.sock.shutdown(socket.SHUT_RDWR)
        self.sock.close()
