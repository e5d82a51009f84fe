"""The primary (TCP 30001) and secondary (30002) client interfaces of one simulated controller.

On connection a client gets the version message (once it has sent nothing for 50 ms: a client that connects only to
send a program gets nothing before it has sent it), then a robot state package
(:func:`sim.primary_packages.robot_state`) every 100 ms of wall time (10 Hz on an absolute schedule, as the
controller sends them, whatever the simulator's fast-forward factor); primary clients also get the controller's
robot messages as they happen (program started and stopped key messages, text messages, runtime and compile errors,
protective and emergency stops as safety mode and error code messages: :meth:`sim.core.Core.event`), sent with the
next state package. What a client sends is URScript or a primary command (:func:`sim.script_server.take_script`). A
client that stops reading is dropped once 1 MiB is left unsent (:class:`sim.streams.OutputStream`); one that hangs up
is forgotten at once.
"""

from __future__ import annotations

import socket
import sys
import threading
import time

from sim import primary_packages as pp
from sim.core import ROBOT_POWER_OFF, RUNTIME_PAUSED, RUNTIME_PLAYING
from sim.listeners import Listeners
from sim.motion import JOINT_ACCEL_MAX
from sim.script_server import serve_scripts
from sim.streams import OutputStream

PRIMARY_PORT, SECONDARY_PORT = 30001, 30002
#: Seconds between robot state packages (10 Hz).
STATE_PERIOD = 0.1
#: Seconds a client may send without a pause before the version message and state packages reach it (see serve).
QUIET = 0.05


def state_sample(core) -> pp.StateSample:
    """The controller's state for one robot state package (the caller holds ``core.lock``)."""
    m = core.motion
    io = core.io.snapshot()
    return pp.StateSample(
        time=core.time, robot_mode=core.robot_mode, safety_mode=core.safety_mode,
        powered=core.robot_mode != ROBOT_POWER_OFF, program_running=core.runtime_state == RUNTIME_PLAYING,
        program_paused=core.runtime_state == RUNTIME_PAUSED, speed_fraction=io["speed_slider"],
        speed_scaling=core.speed_scaling, q=tuple(m.q.tolist()), q_target=tuple(m.target_q.tolist()),
        qd=tuple(m.qd.tolist()), joint_mode=core.joint_mode, tcp_pose=tuple(core.tcp_pose().tolist()),
        tcp_offset=tuple(m.tcp.tolist()), digital_in=io["digital_in"], digital_out=io["digital_out"],
        analog_in=io["analog_in"], analog_out=io["analog_out"], analog_io_types=io["analog_io_types"],
        tool_voltage=io["tool_voltage"])


def robot_message(seq_time_kind_fields: tuple[int, float, str, dict]) -> bytes:
    """The primary interface's package of one :meth:`sim.core.Core.event`."""
    _, t, kind, f = seq_time_kind_fields
    if kind == "key":
        return pp.key_message(t, f["title"], f["text"])
    if kind == "error":
        return pp.error_code_message(t, f["code"], 0, f["level"], f["text"])
    if kind == "runtime":
        return pp.runtime_exception_message(t, f["line"], 0, f["text"])
    if kind == "safety":
        return pp.safety_mode_message(t, f["mode"])
    return pp.text_message(t, f["text"])


class PrimaryServer(Listeners):
    """The primary and secondary interfaces' listeners, and the thread that sends their state packages."""

    name = "primary"

    def __init__(self, core, host: str, ports=(PRIMARY_PORT, SECONDARY_PORT)) -> None:
        super().__init__(host, ports)
        self.core = core
        self.model = pp.ModelData.of(core.motion.model, JOINT_ACCEL_MAX)
        self.streams: dict[OutputStream, int] = {}  # connected clients and their port
        self.packages_sent = 0
        self._seq = core.event_seq
        self._stop = threading.Event()
        self._publisher = threading.Thread(target=self._publish_loop, name="primary-state", daemon=True)

    def start(self) -> None:
        super().start()
        self._publisher.start()

    def close(self) -> None:
        self._stop.set()
        super().close()
        if self._publisher.is_alive():
            self._publisher.join(1.0)

    def serve(self, sock: socket.socket) -> None:
        port = sock.getsockname()[1]
        # the output is held back while a client that connects to send programs is sending: one that sends a
        # program and hangs up without reading would otherwise close with unread data, which resets the connection
        # (RST) and can discard the end of its program before it is read
        out = OutputStream(sock, held=True)
        with self.core.lock:
            out.write(pp.version_message(self.core.time, self.core.version.words, self.core.version.message_build_date))
        with self._lock:
            self.streams[out] = port
        try:
            serve_scripts(self.core, sock, on_quiet=out.release, quiet=QUIET)
        finally:
            with self._lock:
                self.streams.pop(out, None)
            out.close()

    def publish(self) -> int:
        """Send one robot state package to every client, and the robot messages since the last one to the primary
        clients; returns the number of clients served."""
        core = self.core
        with core.lock:
            sample = state_sample(core)
            events = [e for e in core.events if e[0] > self._seq]
            self._seq = core.event_seq
        state = pp.robot_state(sample, self.model)
        messages = b"".join(robot_message(e) for e in events)
        with self._lock:
            streams = list(self.streams.items())
        for out, port in streams:
            if messages and port == PRIMARY_PORT:
                out.write(messages)
            out.write(state)
        self.packages_sent += len(streams)
        return len(streams)

    def _publish_loop(self) -> None:
        t0 = time.monotonic()
        k = 0
        while not self._stop.is_set():
            k += 1
            delay = t0 + k * STATE_PERIOD - time.monotonic()
            if delay > 0 and self._stop.wait(delay):
                return
            if delay < -STATE_PERIOD:  # held up for more than a period: skip the missed ones, keep the schedule
                k += int(-delay / STATE_PERIOD)
            try:
                self.publish()
            except Exception as exc:  # never let the stream die silently: say why on stderr, go on
                print(f"primary interface: {type(exc).__name__}: {exc}", flush=True, file=sys.stderr)
