"""Script ports (TCP 30001, 30002, 30003): URScript programs sent as a byte stream.

Each connection's stream is cut into programs (:class:`sim.programs.ProgramFramer`); every whole
program replaces the running one (:meth:`sim.core.Core.load_program`), which runs ur_rtde's control
script and refuses anything it cannot run whole, and every program in local control mode. The state
streams a real controller also sends on these ports (primary, secondary, real-time packages) are not
served: ur_rtde never reads them.
"""

from __future__ import annotations

import socket
import threading

from sim.programs import ProgramFramer

SCRIPT_PORTS = (30001, 30002, 30003)


class ScriptServer:
    """One listener per script port of one simulated controller."""

    def __init__(self, core, host: str, ports=SCRIPT_PORTS) -> None:
        self.core = core
        self.socks = [socket.create_server((host, p)) for p in ports]
        self._clients: list[socket.socket] = []

    def start(self) -> None:
        for s in self.socks:
            threading.Thread(target=self._accept, args=(s,), name="script-accept", daemon=True).start()

    def close(self) -> None:
        for s in self.socks:
            s.close()
        for s in list(self._clients):
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            s.close()

    def _accept(self, listener: socket.socket) -> None:
        while True:
            try:
                sock, _ = listener.accept()
            except OSError:
                return
            self._clients.append(sock)
            threading.Thread(target=self._serve, args=(sock,), name="script", daemon=True).start()

    def _serve(self, sock: socket.socket) -> None:
        framer = ProgramFramer()
        port = sock.getsockname()[1]
        try:
            while True:
                try:
                    chunk = sock.recv(65536)
                except OSError:
                    return
                if not chunk:
                    return
                for text in framer.feed(chunk):
                    with self.core.lock:
                        self.core.load_program(text, port)
        finally:
            if sock in self._clients:
                self._clients.remove(sock)
            sock.close()
