"""Dashboard server (TCP 29999): line commands and the controller's reply strings (PolyScope 5).

Replies follow Universal Robots' dashboard server documentation for e-Series as the clients check
them (ur_rtde 1.6.5 src/dashboard_client.cpp compares ``Stopped``, ``Starting program``,
``Pausing program``, ``Protective stop releasing``, ``Loading program:``; Universal Robots' client
library lists the expected patterns of the rest). Commands are matched case-insensitively.

In local control mode (the pendant is the single point of control) the commands that would load or
start programs, power or release the arm, or clear its stops are refused with the controller's
`LOCAL_REFUSAL`; queries still answer (``is in remote control`` says ``false``). Which commands: the
e-Series dashboard documentation and Universal Robots' ROS driver documentation (remote control is
needed to power on, release the brakes, load and start programs, and restart after a protective or
emergency stop), and what URSim answers in local mode.

The controller's version (:attr:`sim.core.Core.version`) is what ``PolyscopeVersion`` and ``version`` answer; a
command newer than it (`COMMANDS_SINCE`) is not understood, as on a controller of that version.
"""

from __future__ import annotations

import socket

from sim import core as c
from sim.listeners import Listeners

GREETING = "Connected: Universal Robots Dashboard Server"
SERIAL_NUMBER = "20235500001"
#: The controller's reply to a command it takes only in remote control mode, while in local control mode.
LOCAL_REFUSAL = ("Command is not allowed due to safety reasons, please switch robot to Remote Control mode "
                 "and reconnect to port 29999")
#: Commands refused in local control mode (lower case; ``load`` covers ``load <program>``).
REMOTE_ONLY = ("load", "load installation", "play", "stop", "pause", "power on", "power off", "brake release",
               "unlock protective stop", "restart safety", "shutdown")
#: Commands newer than PolyScope 5.0 (lower case) -> the release that brought them; an older controller answers
#: them as an unknown command. Universal Robots' C++ client library's dashboard command table
#: (``src/ur/dashboard_client_implementation_g5.cpp``, its e-Series column).
COMMANDS_SINCE: dict[str, tuple[int, int, int]] = {
    "restart safety": (5, 1, 0),
    "safetystatus": (5, 4, 0),
    "is in remote control": (5, 6, 0),
    "get serial number": (5, 6, 0),
    "get robot model": (5, 6, 0),
    "get operational mode": (5, 6, 0),
}


class DashboardServer(Listeners):
    """The dashboard listener of one simulated controller."""

    name = "dashboard"

    def __init__(self, core, host: str, port: int = 29999) -> None:
        super().__init__(host, (port,))
        self.core = core
        self.user_role = "PROGRAMMER"

    def serve(self, sock: socket.socket) -> None:
        sock.sendall((GREETING + "\n").encode())
        buf = b""
        while True:
            chunk = sock.recv(4096)
            if not chunk:
                return
            buf += chunk
            while b"\n" in buf:
                line, buf = buf.split(b"\n", 1)
                text = line.decode("utf-8", "replace").strip()
                if not text:
                    continue
                reply, close = self.reply(text)
                sock.sendall((reply + "\n").encode())
                if close:
                    return

    def reply(self, text: str) -> tuple[str, bool]:  # noqa: C901 - one branch per command
        """The controller's reply to one command line, and whether it closes the connection."""
        core = self.core
        cmd = text.lower()
        arg = text.split(" ", 1)[1] if " " in text else ""
        with core.lock:
            if cmd == "quit":
                return "Disconnected", True
            if cmd in COMMANDS_SINCE and not core.version.at_least(COMMANDS_SINCE[cmd]):
                return f"could not understand: '{text}'", False
            if not core.remote_control and (cmd in REMOTE_ONLY or cmd.startswith("load ")):
                return LOCAL_REFUSAL, False
            if cmd == "shutdown":
                core.power_off()
                return "Shutting down", True
            if cmd == "power on":
                core.power_on()
                return "Powering on", False
            if cmd == "power off":
                core.power_off()
                return "Powering off", False
            if cmd == "brake release":
                core.brake_release()
                return "Brake releasing", False
            if cmd == "play":
                if core.resume():
                    return "Starting program", False
                return "Failed to execute: play", False
            if cmd == "stop":
                core.stop_program()
                return "Stopped", False
            if cmd == "pause":
                if core.pause():
                    return "Pausing program", False
                return "Failed to execute: pause", False
            if cmd == "running":
                return f"Program running: {'true' if core.runtime_state == c.RUNTIME_PLAYING else 'false'}", False
            if cmd == "robotmode":
                return f"Robotmode: {c.MODE_NAMES.get(core.robot_mode)}", False
            if cmd == "safetymode":
                return f"Safetymode: {c.SAFETY_NAMES.get(core.safety_mode)}", False
            if cmd == "safetystatus":
                return f"Safetystatus: {c.SAFETY_NAMES.get(core.safety_mode)}", False
            if cmd == "programstate":
                return f"{c.RUNTIME_NAMES.get(core.runtime_state)} {core.program_name}", False
            if cmd == "unlock protective stop":
                refusal = core.unlock_protective_stop()
                return (refusal or "Protective stop releasing"), False
            if cmd == "close safety popup":
                return "closing safety popup", False
            if cmd == "restart safety":
                return "Restarting safety", False
            if cmd == "close popup":
                return "closing popup", False
            if cmd.startswith("popup "):
                return "showing popup", False
            if cmd.startswith("addtolog"):
                return ("Added log message" if arg else "No log message to add"), False
            if cmd == "is in remote control":
                return ("true" if core.remote_control else "false"), False
            if cmd == "polyscopeversion":
                return core.version.polyscope_text, False
            if cmd == "version":
                return core.version.text, False
            if cmd == "get serial number":
                return SERIAL_NUMBER, False
            if cmd == "get robot model":
                return core.model_name.upper().rstrip("E"), False
            if cmd == "get loaded program":
                return "No program loaded", False
            if cmd == "isprogramsaved":
                return f"true {core.program_name}", False
            if cmd.startswith("load installation "):
                return f"File not found: {text[len('load installation '):]}", False
            if cmd.startswith("load "):
                return f"File not found: {arg}", False
            if cmd == "getuserrole":
                return self.user_role, False
            if cmd.startswith("setuserrole "):
                self.user_role = arg.upper()
                return f"Setting user role: {arg}", False
            if cmd == "get operational mode":
                return "NONE", False
            if cmd == "clear operational mode":
                return "No longer controlling the operational mode. Current operational mode: 'NONE'.", False
            if cmd.startswith("set operational mode "):
                return f"Operational mode '{arg.split()[-1].lower()}' is set", False
        return f"could not understand: '{text}'", False
