"""TCP listeners that serve each client connection in a thread of its own (dashboard, primary, secondary, script).

One listening socket per port on the controller's address; :meth:`Listeners.close` closes the listeners and
hangs up every client still connected (a client whose connection ends is forgotten at once, so a
long-running controller does not collect dead sockets).
"""

from __future__ import annotations

import contextlib
import socket
import threading
from collections.abc import Iterable


class Listeners:
    """Listening sockets on ``host`` at ``ports``; a subclass serves one client in :meth:`serve`."""

    #: Name of the accept and client threads (what a thread dump shows).
    name = "listener"

    def __init__(self, host: str, ports: Iterable[int]) -> None:
        self.socks = [socket.create_server((host, p)) for p in ports]
        self._clients: set[socket.socket] = set()
        self._lock = threading.Lock()

    def start(self) -> None:
        """Accept clients on every port, each in a thread of its own."""
        for s in self.socks:
            threading.Thread(target=self._accept, args=(s,), name=f"{self.name}-accept", daemon=True).start()

    def close(self) -> None:
        """Stop listening and hang up every connected client."""
        for s in self.socks:
            s.close()
        with self._lock:
            clients = list(self._clients)
        for s in clients:
            with contextlib.suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)
            s.close()

    def serve(self, sock: socket.socket) -> None:
        """Serve one client until it hangs up (the connection is closed afterwards)."""
        raise NotImplementedError

    def _accept(self, listener: socket.socket) -> None:
        while True:
            try:
                sock, _ = listener.accept()
            except OSError:  # closed
                return
            with self._lock:
                self._clients.add(sock)
            threading.Thread(target=self._client, args=(sock,), name=self.name, daemon=True).start()

    def _client(self, sock: socket.socket) -> None:
        try:
            self.serve(sock)
        except OSError:
            pass
        finally:
            with self._lock:
                self._clients.discard(sock)
            sock.close()
