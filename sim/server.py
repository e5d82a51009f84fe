"""The simulated controller's process: every listener and the 500 Hz control loop.

Run by :class:`sim.SimController` as ``python -m sim.server --host H --model M --polyscope 5.11.6 ...`` in a child
process of its own (ur_rtde's constructors hold the GIL while they connect, so a server inside the
client's process would deadlock). The child

* binds RTDE 30004, dashboard 29999, the primary and secondary interfaces 30001 and 30002 (their 10 Hz state
  stream, :mod:`sim.primary_server`), the real-time interface 30003 (its 500 Hz state stream,
  :mod:`sim.realtime_server`) and (if asked) Modbus on ``host`` only, then prints one line ``READY {json}`` on stdout;
* runs the control loop on an absolute schedule: tick k is due at ``start + k * 2 ms`` of wall time
  (no drift); each tick advances ``speed`` control periods of simulated time (fractions carried over)
  and sends the RTDE data packages due and one real-time state package;
* reads JSON commands, one per line, on stdin (``{"cmd": "state"}``, ``{"cmd": "set_digital_in",
  "mask": m, "value": v}``, ``{"cmd": "emergency_stop", "pressed": true, "kind": "robot"}``,
  ``{"cmd": "remote_control", "on": false}``, ``{"cmd": "speed", "speed": 100}``, ``{"cmd": "stop"}``)
  and answers each with one JSON line on stdout;
* runs SCHED_FIFO where the system allows it (``--no-realtime``: not), the loop highest;
* exits when stdin closes (the parent is gone) or on SIGTERM, writing its recording first.
"""

from __future__ import annotations

import argparse
import gc
import json
import math
import os
import signal
import sys
import threading
import time

from sim.core import Core
from sim.dashboard import DashboardServer
from sim.hosts import check_host, check_speed, set_realtime_priority
from sim.motion import DT
from sim.primary_server import PrimaryServer
from sim.realtime_server import RealtimeServer
from sim.rtde_fields import Snapshot
from sim.rtde_server import RTDEServer
from sim.versions import DEFAULT, parse_polyscope


class Loop:
    """The control loop thread: ticks the core on an absolute wall-clock schedule."""

    realtime = True

    def __init__(self, core: Core, rtde: RTDEServer, speed: float, realtime: RealtimeServer | None = None) -> None:
        self.core = core
        self.rtde = rtde
        self.realtime_server = realtime
        self.speed = speed
        self.stop = threading.Event()
        self.late = 0  # ticks skipped because the loop fell more than one period behind
        # most periods simulated in one wall-clock period when fast-forwarding (at speed <= 1 every missed
        # period is integrated: simulated time follows the wall clock)
        self.set_speed(speed)
        self.thread = threading.Thread(target=self.run, name="control-loop", daemon=True)

    def set_speed(self, speed: float) -> None:
        """Simulated seconds per wall-clock second from the next period on."""
        self.speed = float(speed)
        self.max_batch = int(4 * speed) if speed > 1 else 1 << 30

    def run(self) -> None:
        core, rtde, realtime = self.core, self.rtde, self.realtime_server
        if self.realtime:
            set_realtime_priority(10)
        period = DT
        t0 = time.perf_counter()
        k = 0  # wall-clock ticks done
        owed = 0.0
        while not self.stop.is_set():
            due = t0 + (k + 1) * period
            now = time.perf_counter()
            if due > now:
                time.sleep(due - now)
                now = time.perf_counter()
            behind = int((now - t0) / period) - k  # ticks due by now (>= 1)
            core.max_late_ms = max(core.max_late_ms, (now - t0 - (k + 1) * period) * 1e3)
            if behind > 1:
                # the loop was held up: simulated time still follows the wall clock, the missed periods
                # are integrated and their data packages sent late, in a burst: a client recording every
                # package sees no hole, as from a controller that never stalls
                self.late += behind - 1
                core.late_ticks += behind - 1
            k_before = k
            k += max(behind, 1)
            owed += self.speed * max(behind, 1)
            n = int(owed + 1e-9)
            owed -= n
            # one package per wall-clock period due, the n control periods spread over them
            wall = max(behind, 1)
            if n > self.max_batch:
                # fast-forward faster than this machine can simulate: simulated time falls behind the asked
                # speed instead of bursts of catch-up ticks that would hold the core (and its clients) for long;
                # the packages still carry whole wall periods of simulated time (speed control periods each),
                # fewer of them, as a client recording every package expects
                n, owed = self.max_batch, 0.0
                wall = max(1, min(wall, n // max(1, round(self.speed))))
            start = time.perf_counter()
            with core.lock:
                done = 0
                for w in range(1, wall + 1):
                    # the RTDE inputs that had arrived by this period's time (all of them in the last period)
                    rtde.apply_received(t0 + (k_before + w) * period if w < wall else math.inf)
                    for _ in range(n * w // wall - done):
                        core.tick()
                    done = n * w // wall
                    snap = Snapshot(core)  # the period's state, as every interface's packages carry it
                    core.packages_sent += rtde.publish(1, snap)
                    if realtime is not None:
                        realtime.publish(snap)
            core.execution_time_ms = (time.perf_counter() - start) * 1e3
            for conn in list(rtde.conns):
                conn.flush()


def _flag(req: dict, key: str) -> bool:
    """The boolean ``req[key]`` of a command; ValueError naming the command and the key if it is not one."""
    value = req[key]
    if not isinstance(value, bool):
        raise ValueError(f"{req.get('cmd')}: {key!r} must be true or false, got {value!r}")
    return value


def _commands(core: Core, io, stop: threading.Event, loop: Loop) -> None:
    """JSON commands from the parent on stdin; EOF means the parent is gone."""
    for line in sys.stdin:
        cmd = None
        try:
            req = json.loads(line)
            if not isinstance(req, dict):
                raise ValueError(f"a command is a JSON object, got {line.strip()[:80]!r}")
            cmd = req.get("cmd")
            if cmd == "state":
                with core.lock:
                    loop.rtde.apply_received()  # the state as of now: every RTDE input received so far
                    reply = core.state()
            elif cmd == "set_digital_in":
                io.set_digital_in(int(req["mask"]), int(req["value"]))
                reply = {"ok": True}
            elif cmd == "emergency_stop":
                pressed = _flag(req, "pressed")
                with core.lock:
                    if pressed:
                        core.press_emergency_stop(str(req.get("kind", "robot")))
                        reply = {"ok": True}
                    else:
                        reply = {"ok": core.release_emergency_stop()}
            elif cmd == "speed":
                loop.set_speed(check_speed(req["speed"]))
                reply = {"ok": True}
            elif cmd == "remote_control":
                on = _flag(req, "on")
                with core.lock:
                    core.set_remote_control(on)
                reply = {"ok": True}
            elif cmd == "stop":
                reply = {"ok": True}
                print(json.dumps(reply), flush=True)
                break
            else:
                reply = {"error": f"unknown command {cmd!r}"}
        except KeyError as exc:
            reply = {"error": f"{cmd}: missing field {exc}"}
        except (ValueError, TypeError) as exc:
            reply = {"error": str(exc)}
        print(json.dumps(reply), flush=True)
    stop.set()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sim.server", description=__doc__.split("\n")[0])
    ap.add_argument("--host", default="127.0.0.2")
    ap.add_argument("--model", default="ur5e")
    ap.add_argument("--modbus-port", type=int, default=None)
    ap.add_argument("--speed", type=float, default=1.0)
    ap.add_argument("--record", default=None)
    ap.add_argument("--allow-remote", action="store_true")
    ap.add_argument("--no-realtime", action="store_true", help="no SCHED_FIFO priorities")
    ap.add_argument("--local-control", action="store_true", help="start in local control mode")
    ap.add_argument("--polyscope", default=DEFAULT.text, help="the PolyScope 5 version reported (default 5.11.6)")
    args = ap.parse_args(argv)
    host = check_host(args.host, args.allow_remote)
    try:
        check_speed(args.speed)
        version = parse_polyscope(args.polyscope)
    except ValueError as exc:
        raise SystemExit(f"--{exc}") from None
    sys.setswitchinterval(0.0002)  # bound the GIL hand-over latency seen by the control loop
    if not args.no_realtime:
        # every thread of the process real-time (they inherit it), so that none is preempted by other
        # processes while it holds the GIL the control loop waits for; the loop and the RTDE readers
        # raise themselves above the rest
        set_realtime_priority(6)
    Loop.realtime = not args.no_realtime

    from sim.io_state import IOState

    io = IOState()
    recorder = None
    if args.record:
        from sim.recording import Recorder

        recorder = Recorder(args.record)
    core = Core(args.model, io, recorder, version)
    if args.local_control:
        try:
            core.set_remote_control(False)
        except ValueError as exc:
            raise SystemExit(f"--{exc}") from None
    rtde = RTDEServer(core, host)
    dash = DashboardServer(core, host)
    primary = PrimaryServer(core, host)
    realtime = RealtimeServer(core, host)
    modbus = None
    if args.modbus_port is not None:
        from sim.modbus import ModbusServerThread  # pymodbus: a dependency; asked for Modbus, fail loudly without

        def pose():
            with core.lock:
                return core.tcp_pose().tolist()

        modbus = ModbusServerThread(io, host, args.modbus_port, tcp_pose=pose, allow_remote=args.allow_remote)
        modbus.start()
        modbus.wait_ready(10.0)
    # everything allocated so far (modules, tables) out of the cyclic collector's reach: a full
    # collection over it would stall the 500 Hz loop for milliseconds
    gc.collect()
    gc.freeze()
    loop = Loop(core, rtde, args.speed, realtime)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    for srv in (rtde, dash, primary, realtime):
        srv.start()
    loop.thread.start()
    ports = {"rtde": 30004, "dashboard": 29999, "primary": 30001, "secondary": 30002, "realtime": 30003,
             "script": [30001, 30002, 30003],
             "modbus": modbus.port if modbus else None}
    print("READY " + json.dumps({"host": host, "pid": os.getpid(), "ports": ports}), flush=True)
    # replies to the parent's commands only after READY (the parent reads READY first)
    threading.Thread(target=_commands, args=(core, io, stop, loop), name="commands", daemon=True).start()
    try:
        stop.wait()  # no periodic wake-ups: a woken thread of ours would take the GIL from the loop
    finally:
        loop.stop.set()
        loop.thread.join(2.0)
        for srv in (rtde, dash, primary, realtime):
            srv.close()
        if modbus is not None:
            modbus.stop()
        if recorder is not None:
            with core.lock:
                recorder.save()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
