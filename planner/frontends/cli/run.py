"""``planner run FILE --robot ur5e --host 127.0.0.2 [--mode program|stream] [--io rtde|modbus] [--sim]``:
plan a toolpath file (the options of ``planner plan``), execute it on a UR controller with a progress bar,
print the execution report.

``--sim`` starts a simulated controller (:class:`sim.SimController`) on a free loopback address (or on
``--host``) and stops it afterwards. Without ``--sim`` the driver connects to ``--host`` only.
The command line's parser (:mod:`planner.frontends.cli.main`) adds it with :func:`add_run_subcommand`; :func:`main`
runs the subcommand alone. Running the job is :mod:`drivers.execute`'s (the service calls the same functions).
"""

from __future__ import annotations

import argparse
import ipaddress
import math
import os
import sys

from drivers.base import DEFAULT_MODE, MODES, ConnectionLostError, DriverError
from drivers.execute import execute_job, plot_run, start_sim
from drivers.servo import DEFAULT_GAIN, DEFAULT_LOOKAHEAD
from planner.frontends.cli.options import Progress, add_plan_options, settings_from_args
from planner.wording import counted


def _path_tolerance_mm(text: str) -> float:
    """``--path-tolerance``'s value, mm: a number > 0 and at most 1000 (argparse names the option on refusal)."""
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a distance in mm, got {text!r}") from None
    if not (math.isfinite(x) and 0 < x <= 1000.0):
        raise argparse.ArgumentTypeError(f"must be > 0 mm and at most 1000 mm, got {text!r}")
    return x


def add_run_subcommand(subparsers) -> argparse.ArgumentParser:
    """Add ``run`` to an argparse subparsers object (``planner``'s); returns its parser."""
    r = subparsers.add_parser("run", help="plan a toolpath file and execute it on a UR robot (or --sim), "
                                          "with a progress bar and the execution report")
    add_plan_options(r, outputs=False)
    r.add_argument("--host", help="the controller's address (the only host the driver connects to)")
    r.add_argument("--mode", choices=MODES, default=DEFAULT_MODE,
                   help="program: send the job's URScript program to the script port and watch it run; stream: "
                        "servoJ with the planner's joints at the job's rate, sent from this machine every control "
                        f"period (default {DEFAULT_MODE})")
    r.add_argument("--io", choices=["rtde", "modbus"], default="rtde",
                   help="switch the job's outputs through RTDE (default) or the controller's Modbus server")
    r.add_argument("--modbus-port", type=int, default=None,
                   help="Modbus TCP port (default 502; with --sim a free port)")
    r.add_argument("--sim", action="store_true", help="start a simulated controller on a free loopback address")
    r.add_argument("--sim-speed", type=float, default=1.0,
                   help="--sim: simulated seconds per second (program mode only; streaming runs in real time)")
    r.add_argument("--lookahead", type=float, default=DEFAULT_LOOKAHEAD,
                   help=f"stream: servoJ lookahead time, s, 0.03..0.2 (default {DEFAULT_LOOKAHEAD:g})")
    r.add_argument("--gain", type=float, default=DEFAULT_GAIN,
                   help=f"stream: servoJ gain, 100..2000 (default {DEFAULT_GAIN:g})")
    r.add_argument("--no-compensation", dest="compensate", action="store_false",
                   help="stream: send the planned joints as servoJ targets as they are (default: targets shaped by "
                        "the servo model so that the arm runs on the planned path)")
    r.add_argument("--path-tolerance", type=_path_tolerance_mm, default=None, metavar="MM",
                   help="path tolerance, mm: the report lists where (time, source line) and why (servo lag, missed "
                        "control periods, a stop) the tracked TCP left the planned path by more")
    r.add_argument("--fail-on-deviation", action="store_true",
                   help="with --path-tolerance: a run beyond it fails (exit status 1)")
    r.add_argument("--progress", action="store_true", help="show the progress bar even when not on a terminal")
    r.add_argument("--plot", help="write the picture of the job with the run drawn over it (.png, .svg, .pdf): the "
                                  "actual against the planned TCP path and speed, the I/O stations and the switches")
    r.set_defaults(func=cmd_run, robot="ur5e")
    return r


def cmd_run(args: argparse.Namespace) -> int:
    from planner import plan

    if args.robot in (None, "none"):
        print("planner run: error: --robot MODEL is needed to execute a job", file=sys.stderr)
        return 2
    if not args.sim and not args.host:
        print("planner run: error: give the controller's address with --host (or --sim)", file=sys.stderr)
        return 2
    if args.host:
        try:
            ipaddress.ip_address(args.host)
        except ValueError:
            print(f"planner run: error: --host must be an IP address, got {args.host!r}", file=sys.stderr)
            return 2
    if args.sim and args.mode == "stream" and args.sim_speed != 1.0:
        print("planner run: error: --sim-speed works in program mode only (streaming runs in real time)",
              file=sys.stderr)
        return 2
    if args.fail_on_deviation and args.path_tolerance is None:
        print("planner run: error: --fail-on-deviation needs --path-tolerance MM", file=sys.stderr)
        return 2
    if args.plot:
        from planner.export.plot import check_plot_target

        check_plot_target(args.plot, args.input)  # before planning and moving: a PlannerError (exit 2)
    settings = settings_from_args(args)
    robot = settings.robot
    if robot is None:  # (--robot none is refused above)
        print("planner run: error: --robot MODEL is needed to execute a job", file=sys.stderr)
        return 2
    bars = Progress(args.progress or sys.stderr.isatty())
    read_options = {k: v for k, v in (("units", args.units), ("machine", args.machine)) if v} or None
    try:
        job = plan(args.input, settings, read_options=read_options, progress=bars)
    finally:
        bars.close()
    print(f"planned {args.input}: {job.duration:.2f} s, {counted(len(job.passes), 'pass')}", flush=True)
    if job.not_executable is not None:  # refused before a controller is started or a robot is reached
        for line in job.describe():
            print(line)
        print(f"planner run: error: {job.not_executable}", file=sys.stderr)
        return 2
    sim = None
    try:
        if args.sim:
            try:
                sim = start_sim(robot, host=args.host, modbus=args.io == "modbus", speed=args.sim_speed)
            except DriverError as exc:
                print(f"planner run: error: {exc}", file=sys.stderr)
                return 1
            host, modbus_port = sim.host, sim.modbus_port or 502  # no Modbus server without --io modbus
            print(f"simulated {robot} controller on {host}", flush=True)
        else:
            host, modbus_port = args.host, 502
        if args.modbus_port is not None:
            modbus_port = args.modbus_port
        bars = Progress(args.progress or sys.stderr.isatty())
        try:
            report = execute_job(job, host, mode=args.mode, io=args.io, modbus_port=modbus_port,
                                 progress=bars.job_time(job),
                                 lookahead=args.lookahead, gain=args.gain, compensate=args.compensate,
                                 path_tolerance=None if args.path_tolerance is None else args.path_tolerance * 1e-3,
                                 fail_on_deviation=args.fail_on_deviation, max_program_bytes=args.max_program_bytes)
        except DriverError as exc:  # refused before the run (not ready, no connection): the robot's reason
            print(f"planner run: robot error ({exc.kind}): {exc}", file=sys.stderr)
            return 1
        finally:
            bars.close()
    finally:
        if sim is not None:
            sim.stop()
    for line in report.describe():
        print(line)
    if args.plot:
        plot_run(job, report, args.plot)
        print(f"wrote {args.plot}", flush=True)
    if isinstance(report.failure, ConnectionLostError):
        # ur_rtde 1.6.5 aborts the interpreter when it destroys interfaces whose connection dropped (an
        # uncaught boost exception): end here, with the report printed and the exit status of a failed run
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(1)
    return 0 if report.ok else 1


def main(argv: list[str] | None = None) -> int:
    """``planner run ...`` alone: ``main(["run", FILE, ...])`` (or without the leading "run")."""
    from planner.errors import PlannerError

    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["run"]:
        argv = argv[1:]
    ap = argparse.ArgumentParser(prog="planner")
    sub = ap.add_subparsers(dest="command", required=True)
    add_run_subcommand(sub)
    args = ap.parse_args(["run", *argv])
    try:
        return args.func(args)
    except (PlannerError, ValueError) as exc:
        print(f"planner run: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"planner run: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
