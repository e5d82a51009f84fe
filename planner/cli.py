"""Command line: ``planner fit`` (PH path through a waypoint file) and ``planner demo``.

Errors in the user's data are printed as one line naming the file, line or waypoint, with exit code 2;
no traceback.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from planner.errors import NumericalError, PlannerError
from planner.settings import AXIS_SOURCES, FRAME_METHODS, PATH_MODELS, PlanSettings
from planner.wording import counted

#: The bundled example the demo runs on (first pass of a real Siemens NX toolpath).
EXAMPLE_NAME = "nx_first_pass.csv"
#: The same pass as NX wrote it (CLSF excerpt with MSYS and modal tool axes).
EXAMPLE_CLS = "nx_first_pass.cls"
#: Where the demo places the NX part frame in the UR5e base frame (m, rad): the pass in front of the robot.
DEMO_PART_FRAME = "0.4,0.9965,-0.1,0,0,0"


def example_path(name: str = EXAMPLE_NAME) -> Path:
    """A file of the repository's ``examples/`` folder (source checkout, or the working directory)."""
    for root in (Path(__file__).resolve().parent.parent, Path.cwd()):
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


#: Largest rotation vector of --part-frame / --tcp, rad (any angle is reachable below 2 pi; beyond this it is a
#: typing mistake, and beyond ~1e16 rad no angle is left in the float at all).
MAX_ROTVEC = 100.0


def _pose(text: str | None, name: str):
    """``--part-frame`` / ``--tcp`` text -> 6 floats (m, rad), or PlannerError naming the option."""
    if text is None:
        return None
    if name == "--part-frame" and text.strip().lower() == "auto":
        return "auto"  # placed for the robot by the planner (PlanSettings.part_frame = "auto")
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        raise PlannerError(f"{name} {text}: must be six numbers x,y,z,rx,ry,rz (m, rad)") from None
    if len(v) != 6:
        raise PlannerError(f"{name} {text}: must be six numbers x,y,z,rx,ry,rz (m, rad), got {len(v)}")
    from planner.budget import MAX_COORDINATE

    for i, (x, what) in enumerate(zip(v, ("x", "y", "z", "rx", "ry", "rz"), strict=True)):
        if not np.isfinite(x):
            raise PlannerError(f"{name} {text}: {what} (number {i + 1}) must be finite")
        if i < 3 and abs(x) > MAX_COORDINATE:
            raise PlannerError(f"{name} {text}: {what} = {x:g} m is beyond any robot cell (at most "
                               f"{MAX_COORDINATE:g} m; the pose is in metres)")
    if math.hypot(*v[3:]) > MAX_ROTVEC:
        raise PlannerError(f"{name} {text}: the rotation vector rx,ry,rz is longer than {MAX_ROTVEC:g} rad "
                           "(it is in radians: an angle of at most pi is enough)")
    return tuple(v)


def _output(text: str | None):
    """``--cut-output KIND:PIN`` -> (kind, pin), or PlannerError naming the option."""
    if text is None:
        return None
    from planner.settings import OUTPUT_KINDS

    kind, _, pin = text.partition(":")
    usage = "KIND:PIN with standard:0..7, configurable:0..7 or tool:0..1"
    try:
        k = int(pin)
    except ValueError:
        raise PlannerError(f"--cut-output {text}: must be {usage}") from None
    if kind not in OUTPUT_KINDS:
        raise PlannerError(f"--cut-output {text}: unknown output kind {kind!r} (must be {usage})")
    if not 0 <= k < OUTPUT_KINDS[kind]:
        raise PlannerError(f"--cut-output {text}: {kind} outputs have pins 0..{OUTPUT_KINDS[kind] - 1}")
    return (kind, k)


class Number(float):
    """A float option's value that remembers the text the user typed (for messages that quote it)."""

    text: str

    def __new__(cls, text: str):
        x = super().__new__(cls, text)
        x.text = text.strip()
        return x

    def __reduce__(self):  # pickled (a saved job's settings) as the plain float it is
        return (float, (float(self),))


Number.__name__ = "number"  # argparse: "invalid number value: 'abc'"


@dataclass(frozen=True)
class NumericOption:
    """A numeric command-line option and its range in the user's units (the PlanSettings range, converted).

    ``lo`` is exclusive unless ``lo_closed``; ``hi`` is inclusive (None: no upper bound, only finite)."""

    flag: str
    dest: str
    unit: str
    lo: float
    hi: float | None
    lo_closed: bool = False

    def check(self, value) -> None:
        """PlannerError ``--flag TEXT: must be ...`` unless ``value`` is in range."""
        if value is None:
            return
        x = float(value)
        if math.isfinite(x) and (x >= self.lo if self.lo_closed else x > self.lo) and (
                self.hi is None or x <= self.hi):
            return
        unit = f" {self.unit}" if self.unit else ""
        rule = f"{'at least' if self.lo_closed else '>'} {self.lo:g}{unit}"
        rule += f" and at most {self.hi:g}{unit}" if self.hi is not None else " and finite"
        text = getattr(value, "text", None) or f"{x:g}"
        raise PlannerError(f"{self.flag} {text}: must be {rule}")


def _numeric_options() -> tuple[NumericOption, ...]:
    from planner.budget import MAX_FEED, MIN_FEED

    mm_s = (MIN_FEED * 1e3, MAX_FEED * 1e3)  # the budget's plausible feeds (settings: (0, 10] m/s)
    return (
        NumericOption("--tolerance", "tolerance", "mm", 0.0, 1000.0),
        NumericOption("--corner", "corner", "deg", 0.0, 180.0),
        NumericOption("--axis-jump", "axis_jump", "deg", 0.0, 90.0),
        NumericOption("--feed", "feed", "mm/s", *mm_s, lo_closed=True),
        NumericOption("--feed-override", "feed_override", "", 0.0, 10.0),
        NumericOption("--rapid-speed", "rapid_speed", "mm/s", *mm_s, lo_closed=True),
        NumericOption("--rate", "rate", "Hz", 0.0, 10_000.0),
        NumericOption("--max-poses", "max_poses", "", 0.0, 1e12),
        # planner run's own (drivers.cli): URDriver's servoJ ranges, the simulator's speed, a TCP port
        NumericOption("--lookahead", "lookahead", "s", 0.03, 0.2, lo_closed=True),
        NumericOption("--gain", "gain", "", 100.0, 2000.0, lo_closed=True),
        NumericOption("--sim-speed", "sim_speed", "", 0.0, None),
        NumericOption("--modbus-port", "modbus_port", "", 1.0, 65535.0, lo_closed=True),
    )


def check_numeric_options(args: argparse.Namespace) -> None:
    """Every numeric option of ``planner plan`` / ``run`` that ``args`` has, in the user's units, before any file
    is read: PlannerError ``--feed -5: must be at least 0.001 mm/s and at most 10000 mm/s``."""
    for opt in _numeric_options():
        if hasattr(args, opt.dest):
            opt.check(getattr(args, opt.dest))


def settings_from_args(args: argparse.Namespace) -> PlanSettings:
    """The PlanSettings of ``planner plan``'s options (mm and mm/s on the command line, SI in the settings).

    Every option is checked first in the user's units and named as typed (:func:`check_numeric_options`)."""
    check_numeric_options(args)
    _check_machine(getattr(args, "machine", None))
    d = PlanSettings()
    return PlanSettings(
        path=args.path, tolerance=args.tolerance / 1e3, corner_deg=float(args.corner),
        axis_jump_deg=float(args.axis_jump), axes=args.axes, frame=args.frame, feed=args.feed / 1e3,
        feed_override=float(args.feed_override), rapid_speed=args.rapid_speed / 1e3, rate=float(args.rate),
        robot=None if args.robot in (None, "none") else args.robot,
        part_frame=_pose(args.part_frame, "--part-frame"), tcp=_pose(args.tcp, "--tcp"),
        feed_floor=d.feed_floor, cut_output=_output(args.cut_output), passes=_passes(args.pass_index),
        max_poses=float(args.max_poses),
    ).checked()


def _check_machine(name: str | None) -> None:
    """``--machine NAME`` names a known machine preset (checked before the file is read)."""
    if name is None:
        return
    from planner.io.machines import machine_kinematics

    try:
        machine_kinematics(name)
    except (ValueError, TypeError):
        raise PlannerError(f"--machine {name}: unknown machine (known: haas-umc-750)") from None


def _passes(text: str | None):
    if text is None or text == "all":
        return None
    if text == "longest":
        return "longest"
    try:
        passes = tuple(int(x) for x in text.split(","))
    except ValueError:
        raise PlannerError(f"--pass {text}: must be pass numbers K[,K...], 'longest' or 'all'") from None
    if any(k < 0 for k in passes):
        raise PlannerError(f"--pass {text}: pass numbers start at 0")
    return passes


#: Output types of ``-o``.
OUTPUTS = (".csv", ".json", ".script", ".urscript", ".job")


def _check_output(args, path_in: Path) -> Path | None:
    """The ``-o`` file, checked before the (long) planning."""
    if not args.output:
        return None
    from planner.export import check_output

    out = check_output(args.output, path_in)
    if out.suffix.lower() not in OUTPUTS:
        raise PlannerError(f"-o {out.name}: unknown output type (use .csv or .json for the trajectory, .script for "
                           "the URScript program, .job for the saved plan)")
    if out.suffix.lower() in (".script", ".urscript") and args.robot in (None, "none"):
        raise PlannerError(f"-o {out.name}: a URScript program starts on the robot's planned joint configuration "
                           "and needs the reachability check: give --robot MODEL")
    return out


class _Progress:
    """tqdm bars on stderr, one per stage (the callback the service uses too): (stage, done, total)."""

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.bars: dict = {}

    def __call__(self, stage: str, done: int, total: int) -> None:
        if not self.enabled:
            return
        from tqdm import tqdm

        bar = self.bars.get(stage)
        if bar is None:
            bar = self.bars[stage] = tqdm(total=total, desc=f"  {stage}", unit=" poses" if stage == "samples" else "",
                                          file=sys.stderr, leave=False, dynamic_ncols=True)
        bar.total = total
        bar.n = done
        bar.refresh()

    def close(self) -> None:
        for bar in self.bars.values():
            bar.close()
        self.bars.clear()


def cmd_plan(args: argparse.Namespace):
    """Plan a toolpath file (every pass, or those of --pass) and print its figures; export and plot it.
    Returns the PlannedJob."""
    from planner.plan import plan

    path_in = Path(args.input)
    settings = settings_from_args(args)
    out = _check_output(args, path_in)
    if args.plot:
        from planner.plot import check_plot_target

        check_plot_target(args.plot)
    options = {k: v for k, v in (("units", args.units), ("machine", args.machine)) if v}
    print(f"{path_in.name}: planning ...", flush=True)
    bar = _Progress(args.progress or sys.stderr.isatty())
    try:
        job = plan(path_in, settings, read_options=options, progress=bar)
    finally:
        bar.close()
    for line in job.describe():
        print(line)
    for line in warning_lines(job.warnings):
        print(line)
    if args.plot:  # first: it shows where the robot has problems when the program is refused
        from planner.plot import plot_job

        s = job.summary()
        dg = plot_job(job, args.plot, title=(f"{path_in.name}: {counted(s['passes'], 'pass')}, "
                                             f"{s['cut_length_mm']:.0f} mm of cut, {s['duration_s']:.1f} s"))
        print(f"  wrote     {args.plot} (speeds from all {dg.samples} poses, joints from 1 in {dg.step})")
    if out is not None:
        try:
            print(f"  wrote     {out} ({export(job, out, {'input': path_in.name}, bar)})")
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


def export(job, out: Path, parameters: dict, progress=None) -> str:
    """Write a job to ``out`` by its suffix (.csv / .json trajectory, .script program, .job saved plan); what
    was written, for a person."""
    from planner.export import job_program, write_csv, write_json, write_script

    suffix = out.suffix.lower()
    if suffix == ".job":
        return f"{job.save(out)} bytes"
    if suffix in (".script", ".urscript"):
        try:
            text = job_program(job, parameters=parameters, progress=progress)
        except PlannerError as exc:
            raise PlannerError(f"not writing {out.name}: {exc}") from None
        write_script(text, out)
        counts = {cmd: text.count(f"\n  {cmd}(") for cmd in ("movep", "movel", "movej")}
        return ", ".join(f"{n} {cmd}" for cmd, n in counts.items() if n)
    if suffix not in (".csv", ".json"):
        raise PlannerError(f"-o {out.name}: unknown output type (use .csv, .json, .script or .job)")
    tr = job.trajectory()
    if job.settings.robot is not None and job.problems:
        print(f"  warning   {job.settings.robot}: {counted(len(job.problems), 'move')} with problems; joints without "
              "an inverse kinematics solution are left empty", flush=True)
    writer = write_json if suffix == ".json" else write_csv
    n = writer(tr, out, parameters=parameters, progress=progress)
    return f"{n} poses" + (", with joints" if job.settings.robot is not None else "")


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
    from drivers.cli import run_demo_on_sim

    report = run_demo_on_sim(job, plot=out / "demo.png")  # the picture again, with the run drawn over it
    for line in report.describe():
        print(f"  {line}")
    if not report.ok:
        raise SystemExit(1)


def add_plan_options(p: argparse.ArgumentParser, *, outputs: bool = True) -> None:
    """The options of ``planner plan`` (the PlanSettings fields in mm and mm/s, reader options, and with
    ``outputs`` -o/--plot/--progress) on a parser: ``planner run`` takes the same ones."""
    D = PlanSettings()
    p.add_argument("input", help="toolpath: APT/CL data, CSV, JSON or 5-axis G-code")
    p.add_argument("--path", choices=list(PATH_MODELS), default=D.path,
                   help="path model: interpolate (C2 PH spline through the points), cam (within --tolerance of the "
                        "polyline), auto (default: interpolate CSV/JSON, cam for APT/CLSF/G-code)")
    p.add_argument("--axes", choices=list(AXIS_SOURCES), default=D.axes,
                   help="tool axis: file (the file's CAM axes, tip to spindle), approach (the file's vectors are the "
                        "approach axis), fixed (CAM default +Z), path (tool normal to the path, spin by --frame), "
                        "auto (default: file if it has axes, else path for interpolate and fixed for cam)")
    p.add_argument("--frame", choices=list(FRAME_METHODS), default=D.frame,
                   help="spin method about the tool axis (methods other than rmf need --axes path)")
    p.add_argument("--tolerance", type=Number, default=D.tolerance * 1e3,
                   help=f"cam model: largest distance from the polyline, mm (default {D.tolerance * 1e3:g})")
    p.add_argument("--corner", type=Number, default=D.corner_deg,
                   help=f"corners sharper than this (deg) split passes (default {D.corner_deg:g})")
    p.add_argument("--axis-jump", type=Number, default=D.axis_jump_deg,
                   help=f"tool-axis jumps larger than this (deg) turn in place (default {D.axis_jump_deg:g})")
    p.add_argument("--feed", type=Number, default=D.feed * 1e3,
                   help=f"feed where the file gives none, mm/s (default {D.feed * 1e3:g})")
    p.add_argument("--feed-override", type=Number, default=D.feed_override, help="factor on every cutting feed")
    p.add_argument("--rapid-speed", type=Number, default=D.rapid_speed * 1e3,
                   help=f"speed of rapid moves, mm/s (default {D.rapid_speed * 1e3:g})")
    p.add_argument("--rate", type=Number, default=D.rate, help="controller rate in Hz (500 e-Series, 125 CB)")
    p.add_argument("--robot", default="none", help="ur3e, ur5e, ur10e, ur16e, ur20, or none (default)")
    p.add_argument("--part-frame", help="part frame in the robot base: x,y,z,rx,ry,rz (m, rad), or auto (the part "
                                        "placed for the robot with the largest joint-limit and singularity margins)")
    p.add_argument("--tcp", help="tool centre point in the flange frame: x,y,z,rx,ry,rz (m, rad)")
    p.add_argument("--cut-output", help="digital output on during every cut, KIND:PIN (standard:0, tool:1, ...)")
    p.add_argument("--pass", dest="pass_index", help="plan only passes K[,K...] or 'longest' (default: all)")
    p.add_argument("--max-poses", type=Number, default=D.max_poses,
                   help=f"refuse jobs whose trajectory would exceed this many poses (default {D.max_poses:g})")
    p.add_argument("--units", choices=["mm", "m", "inch"], help="units of a CSV/JSON file (default mm)")
    p.add_argument("--machine", help="machine kinematics for 5-axis G-code (e.g. haas-umc-750)")
    if outputs:
        p.add_argument("--progress", action="store_true", help="show progress bars even when not on a terminal")
        p.add_argument("-o", "--output", help="write the job: .csv / .json trajectory, .script URScript program "
                       "(movep along the passes within --tolerance, movel between), .job saved plan")
        p.add_argument("--plot", help="write a picture (.png, .svg, .pdf): paths and tool axes, frames, speed, "
                       "joints, fit")


class Parser(argparse.ArgumentParser):
    """argparse with one line on stderr for a usage error (``planner plan: error: argument --feed: ...``, exit 2),
    not the usage block; ``--help`` is unchanged. Subcommand parsers (``plan``, ``run``, ...) inherit it."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    ap = Parser(prog="planner", description="Robot tool-path planning with PH curves.")
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
    from planner.service.cli import add_subcommands  # serve, keys (no web imports until they run)

    add_subcommands(sub)
    from drivers.cli import add_run_subcommand  # run: plan and execute on a robot (or --sim)

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
