"""Command line: ``planner fit`` (PH path through a waypoint file) and ``planner demo``.

Errors in the user's data are printed as one line naming the file, line or waypoint, with exit code 2;
no traceback.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from planner import __version__
from planner.errors import NumericalError, PlannerError
from planner.export.job_script import MAX_PROGRAM_BYTES
from planner.frontends.cli.options import (
    Parser,
    Progress,
    add_plan_options,
    settings_from_args,
    unusual_values,
)
from planner.wording import counted, pose_option

#: The bundled example the demo runs on (first pass of a real Siemens NX toolpath).
EXAMPLE_NAME = "nx_first_pass.csv"
#: The same pass as NX wrote it (CLSF excerpt with MSYS and modal tool axes).
EXAMPLE_CLS = "nx_first_pass.cls"
#: Where the demo places the NX part frame in the UR5e base frame (m, rad): the pass in front of the robot.
#: The demo's part frame (m, rad) and as typed on the command line (mm, deg)
DEMO_PART = (0.4, 0.9965, -0.1, 0.0, 0.0, 0.0)
DEMO_PART_FRAME = pose_option(DEMO_PART)  # "400mm,996.5mm,-100mm,0,0,0"


def example_path(name: str = EXAMPLE_NAME) -> Path:
    """A file of the repository's ``examples/`` folder (source checkout, or the working directory)."""
    for root in (Path(__file__).resolve().parents[3], Path.cwd()):  # the checkout holding planner/
        if (root / "examples" / name).is_file():
            return root / "examples" / name
    raise PlannerError(f"example file examples/{name} not found (run from the repository root)")


def _read_points(path: Path, units: str | None) -> np.ndarray:
    from planner.io import read_toolpath

    options = {} if units is None else {"units": units}
    return read_toolpath(path, **options).points


def _fit_report(points: np.ndarray, method: str) -> dict:
    from planner.curves.ph_cubic_spline import fit_ph_cubic_spline
    from planner.curves.spline import fit_ph_spline

    t0 = time.perf_counter()
    if method == "cubic":
        spline = fit_ph_cubic_spline(points)
    else:
        spline = fit_ph_spline(points, continuity="C1" if method == "C1" else "C2")
    elapsed = time.perf_counter() - t0
    jumps = spline.curvature_jumps()
    return {
        "method": {"cubic": "G1 PH cubic spline"}.get(method, f"{method} PH quintic spline"),
        "segments": spline.n_segments,
        "length_mm": spline.length * 1e3,
        "max_waypoint_error_mm": float(spline.interpolation_errors(points).max()) * 1e3,
        "max_tangent_angle_deg": float(np.degrees(spline.tangent_angles().max(initial=0.0))),
        "max_curvature_jump_per_m": float(jumps[~np.isnan(jumps)].max(initial=0.0)),  # (not where it stops)
        "stops": [int(k) + 1 for k in np.flatnonzero(spline.stops())] if spline.n_segments > 1 else [],
        "newton_iterations": spline.iterations,
        "fit_ms": elapsed * 1e3,
    }


def _print_fit(path: Path, points: np.ndarray, methods: list[str]) -> None:
    print(f"{path.name}: {len(points)} waypoints")
    for m in methods:
        r = _fit_report(points, m)
        print(
            f"  {r['method']:<24} {r['segments']:>5} segments  length {r['length_mm']:.6f} mm (exact)  "
            f"waypoint error {r['max_waypoint_error_mm']:.1e} mm  tangent kink {r['max_tangent_angle_deg']:.1e} deg  "
            f"curvature jump {r['max_curvature_jump_per_m']:.2e} 1/m  fit {r['fit_ms']:.1f} ms"
            + (f"  stops and turns back at {_waypoints(r['stops'])}" if r["stops"] else "")
        )


def _waypoints(index: list[int]) -> str:
    """'waypoint 3' or 'waypoints 1, 4, 7' (the first 8, then how many more)."""
    shown = ", ".join(str(k) for k in index[:8]) + (f" and {len(index) - 8} more" if len(index) > 8 else "")
    return f"waypoint {shown}" if len(index) == 1 else f"waypoints {shown}"


def cmd_fit(args: argparse.Namespace) -> None:
    points = _read_points(Path(args.input), args.units)
    methods = ["C1", "C2", "cubic"] if args.method == "all" else [args.method]
    _print_fit(Path(args.input), points, methods)


#: Output types of ``-o``.
OUTPUTS = (".csv", ".json", ".script", ".urscript", ".job")


def _check_output(args, path_in: Path) -> Path | None:
    """The ``-o`` file, checked before the (long) planning."""
    if not args.output:
        return None
    from planner.export import check_output

    try:
        out = check_output(args.output, path_in)
    except PlannerError as exc:
        raise PlannerError(f"-o {exc}") from None
    if out.suffix.lower() not in OUTPUTS:
        raise PlannerError(f"-o {out.name}: unknown output type (use .csv or .json for the trajectory, .script for "
                           "the URScript program, .job for the saved plan)")
    if out.suffix.lower() in (".script", ".urscript") and args.robot in (None, "none"):
        raise PlannerError(f"-o {out.name}: a URScript program starts on the robot's planned joint configuration "
                           "and needs the reachability check: give --robot MODEL")
    return out


def cmd_plan(args: argparse.Namespace):
    """Plan a toolpath file (every pass, or those of --pass) and print its figures; export and plot it.
    Returns the PlannedJob."""
    from planner.plan import plan

    path_in = Path(args.input)
    settings = settings_from_args(args)
    out = _check_output(args, path_in)
    if args.plot:
        from planner.export.plot import check_plot_target

        check_plot_target(args.plot, path_in)
    options = {k: v for k, v in (("units", args.units), ("machine", args.machine)) if v}
    for line in unusual_values(args):
        print(f"  warning   {line}")
    print(f"{path_in.name}: planning ...", flush=True)
    bar = Progress(args.progress or sys.stderr.isatty())
    try:
        job = plan(path_in, settings, read_options=options, progress=bar)
    finally:
        bar.close()
    program = None
    if out is not None and out.suffix.lower() in (".script", ".urscript") and job.not_executable is None:
        from planner.export import plan_job_program

        try:  # the program's moves, checked for the joint limits: what they slowed is part of the job's figures
            program = plan_job_program(job, progress=bar)
        except PlannerError:  # refused with the file's name by the export below
            program = None
        finally:
            bar.close()
    for line in job.describe(program=program):
        print(line)
    for line in warning_lines(job.warnings):
        print(line)
    if args.plot:  # first: it shows where the robot has problems when the program is refused
        from planner.export import write

        print(f"  wrote     {args.plot} ({write(job, args.plot, parameters={'input': path_in.name})})")
    if out is not None:
        try:
            what = export(job, out, {"input": path_in.name}, bar, args.max_program_bytes, program)
            print(f"  wrote     {out} ({what})")
        finally:
            bar.close()
    return job


def warning_lines(warnings: tuple, limit: int = 10) -> list[str]:
    """One line per distinct warning (in order of first occurrence, with a count when it repeats)."""
    counts: dict[str, int] = {}
    for w in warnings:
        counts[w] = counts.get(w, 0) + 1
    out = [f"  warning   {w}" + (f" ({n} times)" if n > 1 else "") for w, n in list(counts.items())[:limit]]
    if len(counts) > limit:
        out.append(f"  warning   ... {len(counts) - limit} more kinds of warning")
    return out


def export(job, out: Path, parameters: dict, progress=None, max_program_bytes: int | None = MAX_PROGRAM_BYTES,
           program=None) -> str:
    """Write a job to ``out`` by its suffix (.csv / .json trajectory, .script program, .job saved plan) with the
    export verb (:func:`planner.export.write`; ``program``: the program's moves if made already); what was written,
    for a person."""
    from planner.export import write

    suffix = out.suffix.lower()
    if suffix not in OUTPUTS:
        raise PlannerError(f"-o {out.name}: unknown output type (use .csv, .json, .script or .job)")
    if suffix in (".csv", ".json") and job.settings.robot is not None and job.problems:
        print(f"  warning   {job.settings.robot}: {counted(len(job.problems), 'move')} with problems; joints without "
              "an inverse kinematics solution are left empty", flush=True)
    return write(job, out, parameters=parameters, progress=progress, max_program_bytes=max_program_bytes,
                 program=program)


def cmd_demo(args: argparse.Namespace) -> None:
    """Fit, plan and export the bundled example: a real Siemens NX CLSF pass, placed in a UR5e cell."""
    out = Path(args.out)
    print("Demo 1/3: PH spline fits through the first pass of a real Siemens NX toolpath (CSV waypoints)")
    example = example_path()
    _print_fit(example, _read_points(example, "mm"), ["C1", "C2", "cubic"])
    print()
    print("Demo 2/3: plan the same pass from the NX CL data file for a UR5e: tool frames about the NX tool")
    print("axes, jerk-limited feed along the exact arc length, 500 Hz poses, inverse kinematics, URScript")
    plan_args = build_parser().parse_args([
        "plan", str(example_path(EXAMPLE_CLS)), "--robot", "ur5e", "--cut-output", "standard:0",
        "--part-frame", DEMO_PART_FRAME, "-o", str(out / "demo.script"), "--plot", str(out / "demo.png"),
    ])
    job = cmd_plan(plan_args)
    print()
    print("Demo 3/3: execute the job on a simulated UR5e controller (started on a free loopback address)")
    print("through the real ur_rtde client: its URScript program in fast-forward, the spray output on")
    print("standard DO 0 during the cut; the execution report compares the tracked path with the plan")
    from drivers.execute import run_demo_on_sim

    report = run_demo_on_sim(job, plot=out / "demo.png")  # the picture again, with the run drawn over it
    for line in report.describe():
        print(f"  {line}")
    if not report.ok:
        raise SystemExit(1)


def build_parser() -> argparse.ArgumentParser:
    ap = Parser(prog="planner", description="Robot tool-path planning with PH curves.")
    ap.add_argument("--version", action="version", version=f"planner {__version__} (ph-toolpath-planner)")
    sub = ap.add_subparsers(dest="command", required=True)
    f = sub.add_parser("fit", help="fit PH spline paths through a waypoint file and report their figures")
    f.add_argument("input", help="waypoint file: CSV, JSON, APT/CL data or G-code")
    f.add_argument("--method", choices=["C1", "C2", "cubic", "all"], default="all",
                   help="C1/C2 PH quintic spline, G1 PH cubic spline, or all three (default)")
    f.add_argument("--units", choices=["mm", "m", "inch"], default=None,
                   help="units of a CSV/JSON file (default: mm)")
    f.set_defaults(func=cmd_fit)
    p = sub.add_parser("plan", help="plan a toolpath file: PH paths, tool frames, timing, robot check, export")
    add_plan_options(p)
    p.set_defaults(func=cmd_plan)
    sub.add_parser("sim", help="run the simulated UR controller on a loopback address (planner sim --help)")
    from planner.frontends.service.cli import add_subcommands  # serve, keys (no web imports until they run)

    add_subcommands(sub)
    from planner.frontends.cli.run import add_run_subcommand  # run: plan and execute on a robot (or --sim)

    add_run_subcommand(sub)
    d = sub.add_parser("demo", help="run the main job on the bundled example")
    d.add_argument("--out", default="out", help="folder for the program and the plot (default: out)")
    d.set_defaults(func=cmd_demo)
    return ap


def _one_line(exc: BaseException) -> str:
    """An error's message on one line (a reader's message may quote a line of the file with its breaks)."""
    return " ".join(str(exc).split())


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["sim"]:  # every option after "sim" is the simulator's (python -m sim --help)
        try:
            from sim.__main__ import main as sim_main
        except ImportError as exc:
            print(f"planner: error: the simulated controller is not available ({exc})", file=sys.stderr)
            return 2
        return sim_main(argv[1:])
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # --help (0) or a usage error (2, one line already printed)
        return exc.code if isinstance(exc.code, int) else 2
    try:
        code = args.func(args)  # a handler may return its exit status (planner run: 1 for a failed execution)
    except (PlannerError, OSError) as exc:
        print(f"planner: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except NumericalError as exc:
        print(f"planner: internal error: {_one_line(exc)}", file=sys.stderr)
        return 3
    return code if isinstance(code, int) else 0


if __name__ == "__main__":
    sys.exit(main())
