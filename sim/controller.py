"""`SimController`: a simulated UR e-Series controller in a child process, as a context manager.

    with SimController("127.0.0.2", model="ur5e") as sim:
        rtde_c = rtde_control.RTDEControlInterface(sim.host)
        ...

The child (:mod:`sim.server`) runs in its own process group. It exits when its stdin closes, so it
never outlives the parent, even one killed with SIGKILL; :meth:`SimController.stop` asks it to stop,
then terminates and finally kills its process group. Several controllers run at once on 127.0.0.2,
127.0.0.3, ... (the protocol ports are fixed, so one controller per address).
"""

from __future__ import annotations

import atexit
import json
import os
import select
import signal
import subprocess
import sys
import tempfile
import threading
import time
import weakref
from pathlib import Path

from sim.hosts import check_host, check_speed
from sim.versions import DEFAULT, REMOTE_CONTROL_SINCE, SoftwareVersion, parse_polyscope

_LIVE: weakref.WeakSet = weakref.WeakSet()
_REPO = Path(__file__).resolve().parents[1]


class SimError(RuntimeError):
    """The simulated controller failed to start or to answer."""


class SimController:
    """A simulated UR controller serving RTDE, dashboard, the primary and secondary interfaces, the script port and
    Modbus on ``host``.

    Parameters
    ----------
    host : str
        Loopback IPv4 address to bind (``127.0.0.2``, ...).
    model : str
        UR model (``"ur3e"``, ``"ur5e"``, ``"ur10e"``, ``"ur16e"``, ``"ur20"``).
    modbus_port : int or None
        Modbus TCP port (None: no Modbus server).
    speed : float
        Simulated seconds per wall-clock second (RTDE timestamps follow the simulated clock).
    record : str or path, optional
        Recording file (``.npz`` or ``.csv``), written when the controller stops.
    allow_remote : bool
        Allow a non-loopback ``host``.
    startup_timeout : float
        Seconds to wait until every port serves.
    realtime : bool
        Run the child's threads SCHED_FIFO where the system allows it (its control loop highest), so
        that a loaded machine does not delay the 500 Hz loop.
    remote_control : bool
        Start in remote control mode (True, what a cell run from a computer uses) or in local control
        mode (False: the pendant is in control; the dashboard's ``is in remote control`` says false and
        it refuses to load or play programs, power on or release the brakes; the script ports refuse
        programs). See :meth:`set_remote_control`. Local control needs PolyScope 5.6 or later.
    polyscope : str or sim.versions.SoftwareVersion
        The PolyScope 5 version the controller reports and behaves as: ``"5.11.6"`` (default), ``"5.4.0"``,
        ``"5.9.4.1234"`` (with its build number). Every interface reports it (dashboard ``PolyscopeVersion``, the
        primary interface's version message, RTDE ``get_urcontrol_version``), RTDE fields newer than it answer
        ``NOT_FOUND``, dashboard commands newer than it are not understood, the real-time interface sends that
        release's package. CB3 (3.x) and PolyScope X (10.x) versions are refused (ValueError).
    """

    def __init__(self, host: str = "127.0.0.2", model: str = "ur5e", modbus_port: int | None = 5020,
                 speed: float = 1.0, record=None, *, allow_remote: bool = False,
                 startup_timeout: float = 20.0, realtime: bool = True, remote_control: bool = True,
                 polyscope: str | SoftwareVersion = DEFAULT) -> None:
        from planner.kinematics import get_model

        self.host = check_host(host, allow_remote)
        self.model = get_model(model).name
        if modbus_port is not None and (isinstance(modbus_port, bool) or not 0 <= int(modbus_port) <= 65535):
            raise ValueError(f"modbus_port must be within 0..65535 or None, got {modbus_port!r}")
        self.modbus_port = modbus_port
        self.speed = check_speed(speed)
        self.record = Path(record) if record is not None else None
        if self.record is not None:
            if self.record.suffix not in (".npz", ".csv"):
                raise ValueError(f"record: use a .npz or .csv file name, got {self.record}")
            from planner.export.files import output_target

            try:  # a regular file or a new one, through symbolic links (written there, the link kept)
                output_target(self.record)
            except ValueError as exc:
                raise ValueError(f"record: {exc}") from None
            folder = self.record.parent
            while not folder.exists() and folder != folder.parent:
                folder = folder.parent
            if not os.access(folder, os.W_OK):
                raise ValueError(f"record: cannot write {self.record} (no write permission in {folder})")
        self.allow_remote = allow_remote
        self.startup_timeout = startup_timeout
        self.realtime = realtime
        if not isinstance(remote_control, bool):
            raise ValueError(f"remote_control must be True or False, got {remote_control!r}")
        self.remote_control = remote_control
        self.version = parse_polyscope(polyscope)
        if not remote_control:
            self._check_local_control()
        self.proc: subprocess.Popen | None = None
        self.ports: dict = {}
        self._lock = threading.Lock()

    # ---- lifecycle ---------------------------------------------------------------------------
    def start(self) -> SimController:
        """Start the child and wait until it serves every port."""
        if self.proc is not None:
            raise SimError("this SimController is already started")
        cmd = [sys.executable, "-m", "sim.server", "--host", self.host, "--model", self.model,
               "--speed", repr(self.speed)]
        if self.modbus_port is not None:
            cmd += ["--modbus-port", str(int(self.modbus_port))]
        if self.record is not None:
            cmd += ["--record", str(self.record.resolve())]
        if self.allow_remote:
            cmd.append("--allow-remote")
        if not self.realtime:
            cmd.append("--no-realtime")
        if not self.remote_control:
            cmd.append("--local-control")
        cmd += ["--polyscope", self.version.text]
        env = dict(os.environ)
        env["PYTHONPATH"] = str(_REPO) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        # the child's stderr goes to a file (a pipe nobody reads could fill up and stall the child)
        self._stderr = tempfile.TemporaryFile(mode="w+", prefix=f"sim-{self.host}-")
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._stderr,
                                     text=True, bufsize=1, start_new_session=True, env=env)
        _LIVE.add(self)
        deadline = time.monotonic() + self.startup_timeout
        while True:
            line = self._readline(deadline - time.monotonic())
            if line is None:
                err = self._stop_and_collect()
                raise SimError(f"simulated controller on {self.host} did not start: {err.strip()[-2000:]}")
            if line.startswith("READY "):
                self.ports = json.loads(line[6:])["ports"]
                return self

    def _readline(self, timeout: float) -> str | None:
        out = self.proc.stdout if self.proc is not None else None
        if out is None or timeout <= 0:
            return None
        r, _, _ = select.select([out], [], [], timeout)
        if not r:
            return None
        line = out.readline()
        return line if line else None

    def _stop_and_collect(self) -> str:
        self.stop()
        return self.stderr()

    def stderr(self) -> str:
        """What the child wrote to stderr so far (tracebacks, warnings)."""
        f = getattr(self, "_stderr", None)
        if f is None:
            return ""
        try:
            f.flush()
            f.seek(0)
            return f.read()
        except (OSError, ValueError):
            return ""

    def stop(self, timeout: float = 10.0) -> None:
        """Stop the child: ask, then SIGTERM, then SIGKILL its process group; wait for it."""
        proc = self.proc
        if proc is None or proc.returncode is not None:
            return
        try:
            if proc.stdin is not None:
                proc.stdin.close()  # the child exits on EOF (writing its recording first)
        except OSError:
            pass
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self._signal(signal.SIGTERM)
            try:
                proc.wait(5.0)
            except subprocess.TimeoutExpired:
                self._signal(signal.SIGKILL)
                proc.wait(5.0)
        self._signal(signal.SIGKILL)  # anything left in its group
        if proc.stdout is not None:
            try:
                proc.stdout.close()
            except OSError:
                pass

    def _signal(self, sig: int) -> None:
        if self.proc is None:
            return
        try:
            os.killpg(self.proc.pid, sig)
        except (ProcessLookupError, PermissionError):
            pass

    def __enter__(self) -> SimController:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    # ---- queries -----------------------------------------------------------------------------
    def _ask(self, req: dict, timeout: float = 5.0) -> dict:
        stdin = self.proc.stdin if self.proc is not None else None
        if stdin is None or not self.running:
            raise SimError(f"simulated controller on {self.host} is not running")
        with self._lock:
            stdin.write(json.dumps(req) + "\n")
            stdin.flush()
            line = self._readline(timeout)
        if line is None:
            raise SimError(f"simulated controller on {self.host} did not answer {req}")
        reply = json.loads(line)
        if "error" in reply:
            raise SimError(reply["error"])
        return reply

    def state(self) -> dict:
        """Joints, TCP pose, modes, running program, I/O words and the last messages."""
        return self._ask({"cmd": "state"})

    def set_digital_in(self, mask: int, value: int) -> None:
        """Drive the simulated digital inputs (bits 0-7 standard, 8-15 configurable, 16-17 tool)."""
        self._ask({"cmd": "set_digital_in", "mask": int(mask), "value": int(value)})

    def press_emergency_stop(self, kind: str = "robot") -> None:
        """Press the emergency stop: ``"robot"`` (the teach pendant's button: safety mode
        ROBOT_EMERGENCY_STOP) or ``"system"`` (the cell's emergency stop input: SYSTEM_EMERGENCY_STOP). The
        arm stops at once, the program stops and the arm is powered off (robot mode POWER_OFF)."""
        if kind not in ("robot", "system"):
            raise ValueError(f"kind must be 'robot' or 'system', got {kind!r}")
        self._ask({"cmd": "emergency_stop", "pressed": True, "kind": kind})

    def release_emergency_stop(self) -> bool:
        """Release the emergency stop (safety mode NORMAL again; the arm stays powered off until the
        dashboard's ``power on`` and ``brake release``). False when none was pressed."""
        return bool(self._ask({"cmd": "emergency_stop", "pressed": False})["ok"])

    def set_speed(self, speed: float) -> None:
        """Change the simulated seconds per wall-clock second (e.g. fast-forward once a long program runs)."""
        speed = check_speed(speed)
        self._ask({"cmd": "speed", "speed": speed})
        self.speed = speed

    def _check_local_control(self) -> None:
        if not self.version.at_least(REMOTE_CONTROL_SINCE):
            raise ValueError(f"remote_control: PolyScope {self.version.text} has no local control mode (from 5.6.0)")

    def set_remote_control(self, on: bool) -> None:
        """Switch between remote (True) and local (False) control, as on the teach pendant."""
        if not isinstance(on, bool):
            raise ValueError(f"on must be True or False, got {on!r}")
        if not on:
            self._check_local_control()
        self._ask({"cmd": "remote_control", "on": on})
        self.remote_control = on


@atexit.register
def _stop_all() -> None:
    for sim in list(_LIVE):
        sim.stop(timeout=3.0)
