"""Script input of the controller's client ports (TCP 30001, 30002, 30003): URScript programs and primary commands.

Each connection's byte stream is cut into programs (:class:`sim.programs.ProgramFramer`); every whole program
replaces the running one (:meth:`sim.core.Core.load_program`), which runs ur_rtde's control script and refuses
anything it cannot run whole, and every program in local control mode. A one-line program that is one of
`PRIMARY_COMMANDS` (what UR's C++ client library sends to power the arm on, release its brakes, unlock a protective
stop or stop the program) is carried out instead, and refused in local control mode. :mod:`sim.primary_server` serves
30001 and 30002, :mod:`sim.realtime_server` 30003, each beside its state stream.
"""

from __future__ import annotations

import socket

from sim.primary_packages import READ_ONLY_INTERFACE, WARNING
from sim.programs import ProgramFramer


def _unlock(core) -> None:
    refusal = core.unlock_protective_stop()
    if refusal:
        core.event("error", code=0, level=WARNING, text=refusal)


#: One-line commands of the primary interface (lower case) and the controller's action for each.
PRIMARY_COMMANDS = {
    "power on": lambda core: core.power_on(),
    "power off": lambda core: core.power_off(),
    "set robotmode run": lambda core: core.brake_release(),
    "brake release": lambda core: core.brake_release(),
    "set unlock protective stop": _unlock,
    "stop program": lambda core: core.stop_program(),
}


def take_script(core, text: str, port: int | None = None) -> None:
    """One framed program (or command line) from a client port; the caller holds ``core.lock``."""
    action = PRIMARY_COMMANDS.get(text.strip().lower())
    if action is None:
        core.load_program(text, port)
    elif not core.remote_control:
        core.event("error", code=READ_ONLY_INTERFACE, level=3,
                   text=f"{text.strip()!r} refused: the primary interface is read-only in local control mode")
    else:
        action(core)


def serve_scripts(core, sock: socket.socket, on_quiet=None, quiet: float = 0.05) -> None:
    """Read programs from ``sock`` until the client hangs up (a partial program at hang-up is dropped).

    ``on_quiet()``, if given, is called once the client has sent nothing for ``quiet`` s (right after connecting,
    or after a first burst of programs)."""
    framer = ProgramFramer()
    port = sock.getsockname()[1]
    if on_quiet is not None:
        sock.settimeout(quiet)
    while True:
        try:
            chunk = sock.recv(65536)
        except TimeoutError:
            sock.settimeout(None)
            on_quiet()
            continue
        if not chunk:
            return
        for text in framer.feed(chunk):
            with core.lock:
                take_script(core, text, port)

