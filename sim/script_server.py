"""Script ports (TCP 30001, 30002, 30003): URScript programs sent as a byte stream.

Each connection's stream is cut into programs (:class:`sim.programs.ProgramFramer`); every whole
program replaces the running one (:meth:`sim.core.Core.load_program`), which runs ur_rtde's control
script and refuses anything it cannot run whole, and every program in local control mode. The state
streams a real controller also sends on these ports (primary, secondary, real-time packages) are not
served: ur_rtde never reads them.
"""

from __future__ import annotations

import socket

from sim.listeners import Listeners
from sim.programs import ProgramFramer

SCRIPT_PORTS = (30001, 30002, 30003)


class ScriptServer(Listeners):
    """One listener per script port of one simulated controller."""

    name = "script"

    def __init__(self, core, host: str, ports=SCRIPT_PORTS) -> None:
        super().__init__(host, ports)
        self.core = core

    def serve(self, sock: socket.socket) -> None:
        framer = ProgramFramer()
        port = sock.getsockname()[1]
        while True:
            chunk = sock.recv(65536)
            if not chunk:
                return
            for text in framer.feed(chunk):
                with self.core.lock:
                    self.core.load_program(text, port)
