"""The real-time client interface (TCP 30003) of one simulated controller: a 500 Hz state stream and a script port.

Every control period of wall time (the control loop's schedule, :class:`sim.server.Loop`, the one RTDE's data packages
follow) each connected client gets one state package (:func:`sim.realtime_packages.realtime_state`, 1220 bytes from
PolyScope 5.10, the prefix an earlier release sends before: :func:`sim.realtime_packages.package_size`), built
under the controller's lock from the same snapshot of the controller as that period's RTDE packages. What a client
sends is URScript or a primary command (:func:`sim.script_server.serve_scripts`), as on 30001 and 30002.

A controller never waits for a client: a client that does not read (ur_rtde keeps 30003 open to upload its control
script and never reads it) has packages skipped while the previous one is still unsent, and always gets whole
packages, the newest. As on the primary interface, nothing is sent to a client until it has been quiet for 50 ms after
connecting (one that connects to send a program and hangs up without reading would otherwise reset the connection
and lose the program's end).
"""

from __future__ import annotations

import socket

from sim.listeners import Listeners
from sim.realtime_packages import package_size, realtime_state
from sim.rtde_fields import Snapshot
from sim.script_server import serve_scripts
from sim.streams import OutputStream

REALTIME_PORT = 30003
#: Seconds a client may send without a pause before the state stream reaches it.
QUIET = 0.05


class RealtimeServer(Listeners):
    """The real-time interface's listener; :meth:`publish` is called by the control loop once per period."""

    name = "realtime"

    def __init__(self, core, host: str, ports=(REALTIME_PORT,)) -> None:
        super().__init__(host, ports)
        self.core = core
        self.streams: set[OutputStream] = set()
        self.package_size = package_size(core.version)  # the controller's release's package
        self.packages_sent = 0
        self.packages_skipped = 0

    def serve(self, sock: socket.socket) -> None:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        out = OutputStream(sock, held=True)
        with self._lock:
            self.streams.add(out)
        try:
            serve_scripts(self.core, sock, on_quiet=out.release, quiet=QUIET)
        finally:
            with self._lock:
                self.streams.discard(out)
            out.close()

    def publish(self, snap: Snapshot | None = None) -> int:
        """One state package of the controller as ``snap`` sees it (None: as it is now) to every client ready for it
        (the caller holds ``core.lock``); returns how many."""
        if not self.streams:
            return 0
        with self._lock:
            streams = [s for s in self.streams if not s.held]
        ready = []
        for out in streams:
            out.flush()
            if out.backlog:  # the last package is still unsent: the client is not reading, skip this one
                self.packages_skipped += 1
            else:
                ready.append(out)
        if not ready:  # no package is built for clients that do not read (ur_rtde's script connection)
            return 0
        package = realtime_state(snap or Snapshot(self.core), self.package_size)
        for out in ready:
            out.write(package)
        self.packages_sent += len(ready)
        return len(ready)
