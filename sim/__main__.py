"""``python -m sim --host 127.0.0.2 --model ur5e [--polyscope 5.11.6] [--modbus-port 5020] [--speed 1.0]
[--record FILE]``.

Runs a simulated UR controller until Ctrl-C (or ``quit``); prints where it serves. Lines typed on stdin
act on the controller as a person at the cell would (:data:`COMMANDS`): press or release the emergency
stop, switch between local and remote control, show the state.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import time

from sim.controller import SimController, SimError
from sim.versions import DEFAULT

COMMANDS = {
    "estop": "press the teach pendant's emergency stop ('estop system': the cell's emergency stop input)",
    "release": "release the emergency stop (then power on and brake release through the dashboard)",
    "local": "switch to local control (the dashboard refuses motion commands, the script ports programs)",
    "remote": "switch to remote control",
    "state": "print the controller's modes, joints and last messages",
    "help": "list the commands",
    "quit": "stop the controller and exit",
}


def command(sim: SimController, line: str) -> str:
    """Carry out one console line on ``sim``; the text to print. Unknown lines get the command list."""
    words = line.split()
    if not words:
        return ""
    name, args = words[0].lower(), words[1:]
    if name == "estop":
        kind = args[0].lower() if args else "robot"
        if kind not in ("robot", "system"):
            return f"estop: say 'estop' or 'estop system', not {line.strip()!r}"
        sim.press_emergency_stop(kind)
        return f"emergency stop pressed ({kind}): the arm is stopped and powered off"
    if name == "release":
        if sim.release_emergency_stop():
            return "emergency stop released: power on and release the brakes (dashboard) to continue"
        return "no emergency stop is pressed"
    if name in ("local", "remote"):
        sim.set_remote_control(name == "remote")
        return f"{name} control"
    if name == "state":
        st = sim.state()
        q = ", ".join(f"{x:.4f}" for x in st["q"])
        msgs = "\n".join(f"  {t:9.3f} {src}: {text}" for t, src, text in st["log"][-5:])
        return (f"robot {st['robot_mode']}, safety {st['safety_mode']}, program {st['runtime_state']} "
                f"({st['program']}), {'remote' if st['remote_control'] else 'local'} control\n"
                f"  joints [{q}] rad" + (f"\n{msgs}" if msgs else ""))
    if name == "quit":
        sim.stop()
        return "stopped"
    return "\n".join(f"  {k:8s} {v}" for k, v in COMMANDS.items())


def _console(sim: SimController) -> None:
    for line in sys.stdin:
        try:
            out = command(sim, line)
        except (SimError, ValueError) as exc:  # ValueError: e.g. local control on a controller older than 5.6
            out = f"error: {exc}"
        if out:
            print(out, flush=True)
        if not sim.running:
            return


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sim", description="Simulated UR e-Series controller on loopback.")
    ap.add_argument("--host", default="127.0.0.2", help="loopback address to serve on (default 127.0.0.2)")
    ap.add_argument("--model", default="ur5e", help="ur3e, ur5e, ur10e, ur16e or ur20")
    ap.add_argument("--modbus-port", type=int, default=5020, help="Modbus TCP port (default 5020)")
    ap.add_argument("--no-modbus", action="store_true", help="do not serve Modbus")
    ap.add_argument("--speed", type=float, default=1.0, help="simulated seconds per wall-clock second")
    ap.add_argument("--record", default=None, help="write a recording (.npz or .csv) when stopped")
    ap.add_argument("--allow-remote", action="store_true", help="allow a non-loopback --host")
    ap.add_argument("--local-control", action="store_true", help="start in local control mode (the pendant's)")
    ap.add_argument("--polyscope", default=DEFAULT.text.rsplit(".", 1)[0],
                    help="the PolyScope 5 version to report and behave as, e.g. 5.4.0 (default 5.11.6): RTDE fields "
                         "and dashboard commands newer than it are unknown")
    args = ap.parse_args(argv)
    # Ctrl-C stops it whatever its parent left it: SIGINT ignored (a shell script's background job) or blocked (a
    # process started from a thread that blocks it) would leave it serving on
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    signal.signal(signal.SIGINT, signal.default_int_handler)
    started = time.time()
    try:
        sim = SimController(args.host, args.model, None if args.no_modbus else args.modbus_port, args.speed,
                            args.record, allow_remote=args.allow_remote,
                            remote_control=not args.local_control, polyscope=args.polyscope).start()
    except (ValueError, SimError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # Ctrl-C while it starts (the child is stopped at exit)
        return 130
    try:
        print(f"simulated {sim.model} on {sim.host} (PolyScope {sim.version.text}): RTDE 30004, dashboard 29999, "
              "primary 30001, secondary 30002, real-time 30003"
              + (f", Modbus {sim.ports.get('modbus')}" if sim.ports.get("modbus") else "")
              + " (Ctrl-C stops; type 'help' for commands)", flush=True)
        signal.signal(signal.SIGTERM, lambda *_: sim.stop())
        threading.Thread(target=_console, args=(sim,), name="console", daemon=True).start()
        while sim.running:
            time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    finally:
        sim.stop()
    if args.record:
        if not (os.path.exists(args.record) and os.path.getmtime(args.record) >= started):
            reason = (sim.stderr().strip().splitlines() or ["no reason given"])[-1]
            print(f"error: the recording was not written to {args.record}: {reason}", file=sys.stderr)
            return 1
        print(f"recording written to {args.record}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
