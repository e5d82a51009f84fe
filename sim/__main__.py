"""``python -m sim --host 127.0.0.2 --model ur5e [--modbus-port 5020] [--speed 1.0] [--record FILE]``.

Runs a simulated UR controller until Ctrl-C; prints where it serves.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time

from sim.controller import SimController, SimError


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sim", description="Simulated UR e-Series controller on loopback.")
    ap.add_argument("--host", default="127.0.0.2", help="loopback address to serve on (default 127.0.0.2)")
    ap.add_argument("--model", default="ur5e", help="ur3e, ur5e, ur10e, ur16e or ur20")
    ap.add_argument("--modbus-port", type=int, default=5020, help="Modbus TCP port (default 5020)")
    ap.add_argument("--no-modbus", action="store_true", help="do not serve Modbus")
    ap.add_argument("--speed", type=float, default=1.0, help="simulated seconds per wall-clock second")
    ap.add_argument("--record", default=None, help="write a recording (.npz or .csv) when stopped")
    ap.add_argument("--allow-remote", action="store_true", help="allow a non-loopback --host")
    args = ap.parse_args(argv)
    try:
        sim = SimController(args.host, args.model, None if args.no_modbus else args.modbus_port, args.speed,
                            args.record, allow_remote=args.allow_remote).start()
    except (ValueError, SimError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"simulated {sim.model} on {sim.host}: RTDE 30004, dashboard 29999, script 30001-30003"
          + (f", Modbus {sim.ports.get('modbus')}" if sim.ports.get("modbus") else "") + " (Ctrl-C stops)")
    signal.signal(signal.SIGTERM, lambda *_: sim.stop())
    try:
        while sim.running:
            time.sleep(0.5)
    except KeyboardInterrupt:
        pass
    finally:
        sim.stop()
        if args.record:
            print(f"recording written to {args.record}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
