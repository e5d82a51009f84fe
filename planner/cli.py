"""Command line: ``planner fit`` (PH path through a waypoint file) and ``planner demo``.

Errors in the user's data are printed as one line naming the file, line or waypoint, with exit code 2;
no traceback.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from planner.errors import PlannerError

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
        spline = fit_ph_spline(points, continuity=method)
    elapsed = time.perf_counter() - t0
    return {
        "method": {"cubic": "G1 PH cubic spline"}.get(method, f"{method} PH quintic spline"),
        "segments": spline.n_segments,
        "length_mm": spline.length * 1e3,
        "max_waypoint_error_mm": float(spline.interpolation_errors(points).max()) * 1e3,
        "max_tangent_angle_deg": float(np.degrees(spline.tangent_angles().max(initial=0.0))),
        "max_curvature_jump_per_m": float(spline.curvature_jumps().max(initial=0.0)),
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
        )


def cmd_fit(args: argparse.Namespace) -> None:
    points = _read_points(Path(args.input), args.units)
    methods = ["C1", "C2", "cubic"] if args.method == "all" else [args.method]
    _print_fit(Path(args.input), points, methods)


def _pose(text: str | None, name: str):
    if text is None:
        return None
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        raise PlannerError(f"{name} must be six numbers x,y,z,rx,ry,rz (m, rad), got {text!r}") from None
    if len(v) != 6 or not np.isfinite(v).all():
        raise PlannerError(f"{name} must be six finite numbers x,y,z,rx,ry,rz (m, rad), got {text!r}")
    return tuple(v)


def cmd_plan(args: argparse.Namespace) -> None:
    from planner.io import detect_format, read_toolpath
    from planner.job import JobSettings, plan_job

    path_in = Path(args.input)
    options = {}
    if args.units:
        options["units"] = args.units
    if args.machine:
        options["machine"] = args.machine
    tp = read_toolpath(path_in, **options)
    from planner.cam import CutPass, split_passes

    passes = [m for m in split_passes(tp, corner_deg=args.corner).moves if isinstance(m, CutPass)]
    if not passes:
        raise PlannerError(f"{path_in.name}: no cutting motion with at least two points")
    if args.pass_index == "all" or (args.pass_index is None and len(passes) > 1):
        _plan_whole_job(args, path_in, tp, options)
        return
    if args.pass_index == "longest":
        k = int(np.argmax([np.linalg.norm(np.diff(p.points, axis=0), axis=1).sum() for p in passes]))
    else:
        try:
            k = int(args.pass_index or 0)
        except ValueError:
            raise PlannerError(f"--pass must be a pass number, 'longest' or 'all', got {args.pass_index!r}") from None
    if not 0 <= k < len(passes):
        raise PlannerError(f"--pass {k}: {path_in.name} has passes 0..{len(passes) - 1}")
    cut = passes[k]
    points = cut.points
    axes = None
    if cut.axes is not None and not args.ignore_axes:
        # CAM tool vectors point from the tool tip to the spindle; the robot tool z approaches the part
        cam_format = detect_format(path_in) in ("apt", "gcode")
        axes = -cut.axes if (cam_format or args.axes == "normal") else cut.axes
    feeds = np.asarray(cut.feeds, dtype=float)
    span_feeds = feeds[1:] if np.isfinite(feeds[1:]).any() else None
    settings = JobSettings(
        frame=args.frame, feed=args.feed / 1e3, rate=args.rate,
        robot=None if args.robot == "none" else args.robot,
        base=_pose(args.part_frame, "--part-frame"), tcp=_pose(args.tcp, "--tcp"), tolerance=args.tolerance / 1e3,
    )
    first, last = int(cut.lines[0]), int(cut.lines[-1])
    print(f"{path_in.name}: pass {k} of {len(passes)} (lines {first}-{last}, {len(points)} points"
          f"{', tool axes from the file' if axes is not None else ''}); planning ...", flush=True)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        job = plan_job(points, axes, settings, span_feeds=span_feeds)
    for w in caught:  # the job's warnings name waypoints of the pass: say which file lines they are
        print(f"  warning   {w.message} (pass {k} starts at line {first})")
    r = job.summary()
    print(f"  path      {r['segments']} PH segments, length {r['length_mm']:.3f} mm (exact), "
          f"waypoint error {r['max_waypoint_error_mm']:.1e} mm"
          + (f", largest deviation from the CAM polyline {r['max_deviation_mm']:.4f} mm" if "max_deviation_mm" in r
             else ""))
    print(f"  frames    {r['frame']}: max twist against the exact RMF {r['max_twist_vs_exact_rmf_deg']:.3g} deg")
    n_slow = len(job.feed_caps)
    print(f"  motion    {r['duration_s']:.3f} s, {r['samples']} poses at {settings.rate:g} Hz"
          + (f"; feed lowered for the joint speed limits on {n_slow} stretch{'es' * (n_slow > 1)}" if n_slow else ""))
    for w, text in list(zip(job.feed_caps, r["feed_lowered"], strict=True))[:10]:  # spans -> file lines
        a, b = int(cut.lines[w.first_span + 1]), int(cut.lines[w.last_span + 1])
        print(f"  slowed    {text}, {f'line {a}' if a == b else f'lines {a}-{b}'}")
    if n_slow > 10:
        print(f"  slowed    ... {n_slow - 10} more stretches")
    if "reachable" in r:
        print(f"  robot     {r['reachability']}")  # the message names the model
    if args.output:
        _export(job, Path(args.output), path_in)
        print(f"  wrote     {args.output}")
    if args.plot:
        from planner.plot import plot_job

        Path(args.plot).parent.mkdir(parents=True, exist_ok=True)
        plot_job(job, args.plot, title=f"{path_in.name}, pass {k}: {r['length_mm']:.1f} mm, {r['duration_s']:.2f} s")
        print(f"  wrote     {args.plot}")


class _ProgressBar:
    """A one-line text progress bar on stderr for long jobs (only when stderr is a terminal or forced)."""

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.last = ""

    def __call__(self, stage: str, done: int, total: int) -> None:
        if not self.enabled:
            return
        frac = done / total if total else 1.0
        bar = "#" * int(30 * frac)
        line = f"\r  {stage:<6} [{bar:<30}] {100 * frac:5.1f} % ({done}/{total})"
        if line != self.last:
            sys.stderr.write(line)
            sys.stderr.flush()
            self.last = line

    def close(self) -> None:
        if self.enabled and self.last:
            sys.stderr.write("\n")
            sys.stderr.flush()
        self.last = ""


#: Output types of a whole multi-pass job (``-o``).
WHOLE_JOB_OUTPUTS = (".csv", ".json", ".script", ".urscript")


def _whole_job_output(args) -> Path | None:
    """The ``-o`` file of a whole job, checked before the (long) planning."""
    if not args.output:
        return None
    out = Path(args.output)
    if out.suffix.lower() not in WHOLE_JOB_OUTPUTS:
        raise PlannerError(f"-o {out.name}: unknown output type for a whole job (use .csv or .json for the pose "
                           "stream, .script for the URScript program)")
    if out.suffix.lower() in (".script", ".urscript") and args.robot == "none":
        raise PlannerError(f"-o {out.name}: a whole-job URScript program starts on the robot's planned joint "
                           "branch and needs the reachability check: give --robot MODEL")
    return out


def _plan_whole_job(args, path_in: Path, tp, read_options: dict) -> None:
    """Every pass, rapid and reorientation of a CAM file (planner.cam), with its figures and exports."""
    from planner.cam import plan_cam_job

    out = _whole_job_output(args)
    print(f"{path_in.name}: {len(tp)} points; planning every pass (tolerance {args.tolerance:g} mm) ...", flush=True)
    bar = _ProgressBar(args.progress or sys.stderr.isatty())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            job = plan_cam_job(
                tp, tolerance=args.tolerance / 1e3, corner_deg=args.corner,
                part_frame=_pose(args.part_frame, "--part-frame"), tcp=_pose(args.tcp, "--tcp"),
                robot=None if args.robot == "none" else args.robot, feed=args.feed / 1e3, rate=args.rate,
                progress=bar,
            )
        finally:
            bar.close()
    for line in job.describe():
        print(line)
    for w in caught[:10]:
        print(f"  warning   {w.message}")
    if args.plot:  # first: it shows where the robot has problems when the program is refused
        from planner.plot_cam import plot_cam_job

        Path(args.plot).parent.mkdir(parents=True, exist_ok=True)
        s = job.summary()
        digest = plot_cam_job(job, args.plot, rate=args.rate, title=(
            f"{path_in.name}: {s['passes']} passes, {s['cut_length_mm']:.0f} mm of cut, {s['duration_s']:.1f} s"))
        print(f"  wrote     {args.plot} (speeds from all {digest.samples} poses, joints from 1 in {digest.step})")
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        try:
            print(f"  wrote     {out} ({_export_whole_job(job, out, path_in, args.rate, bar)})")
        finally:
            bar.close()


def _counted(chunks, total: int, bar: _ProgressBar):
    """The chunks, reporting the poses passed on to ``bar``."""
    done = 0
    for item in chunks:
        yield item
        done += (item[0] if isinstance(item, tuple) else item).times.size
        bar("write", done, total)


def _export_whole_job(job, out: Path, source: Path, rate: float, bar: _ProgressBar) -> str:
    """Write a whole job to ``out`` (.csv / .json pose stream, .script program); what was written."""
    from planner.export import job_program, write_job_csv, write_job_json, write_script

    params = {"input": source.name}
    suffix = out.suffix.lower()
    if suffix in (".script", ".urscript"):
        try:
            text = job_program(job, parameters=params, progress=bar)
        except PlannerError as exc:
            raise PlannerError(f"not writing {out.name}: {exc}") from None
        write_script(text, out)
        counts = {cmd: text.count(f"\n  {cmd}(") for cmd in ("movep", "movel", "movej")}
        return ", ".join(f"{n} {cmd}" for cmd, n in counts.items() if n)
    chunks = job.iter_stream(rate)
    if job.settings.robot is not None and suffix == ".json":
        from planner.cam.stream import track_joints

        chunks = track_joints(job, chunks)
        if job.problems:
            print(f"  warning   {job.settings.robot}: {len(job.problems)} moves with problems; joints without an "
                  "inverse kinematics solution are null", flush=True)
    writer = write_job_json if suffix == ".json" else write_job_csv
    n = writer(job, _counted(chunks, job.n_samples(rate), bar), out, rate=rate, parameters=params)
    return f"{n} poses" + (", with joints" if job.settings.robot is not None and suffix == ".json" else "")


def _export(job, out: Path, source: Path) -> None:
    from planner.export import servoj_program, write_csv, write_json, write_script

    out.parent.mkdir(parents=True, exist_ok=True)
    params = {"input": source.name, "frame": job.settings.frame, "feed_m_per_s": job.settings.feed,
              "feed_scale": job.feed_scale, "robot": job.settings.robot}
    suffix = out.suffix.lower()
    if suffix == ".csv":
        write_csv(job.stream, out, joints=job.joints, parameters=params)
    elif suffix == ".json":
        write_json(job.stream, out, joints=job.joints, parameters=params)
    elif suffix in (".script", ".urscript"):
        if job.joints is None:
            raise PlannerError("a servoj URScript program needs joint targets: give --robot MODEL")
        if not job.reachability.ok:  # unreachable, outside joint limits, or too fast even at the feed floor
            raise PlannerError(f"not writing {out.name}: {job.reachability.message}")
        write_script(servoj_program(job.stream, job.joints, model=job.settings.robot, parameters=params), out)
    else:
        raise PlannerError(f"-o {out.name}: unknown output type (use .csv, .json or .script)")


def cmd_demo(args: argparse.Namespace) -> None:
    """Fit, plan and export the bundled example: a real Siemens NX CLSF pass, placed in a UR5e cell."""
    out = Path(args.out)
    print("Demo 1/2: PH spline fits through the first pass of a real Siemens NX toolpath (CSV waypoints)")
    example = example_path()
    _print_fit(example, _read_points(example, "mm"), ["C1", "C2", "cubic"])
    print()
    print("Demo 2/2: plan the same pass from the NX CL data file for a UR5e: tool frames about the NX tool")
    print("axes, jerk-limited feed along the exact arc length, 500 Hz poses, inverse kinematics, URScript")
    plan_args = build_parser().parse_args([
        "plan", str(example_path(EXAMPLE_CLS)), "--pass", "longest", "--robot", "ur5e",
        "--part-frame", DEMO_PART_FRAME, "-o", str(out / "demo.script"), "--plot", str(out / "demo.png"),
    ])
    cmd_plan(plan_args)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="planner", description="Robot tool-path planning with PH curves.")
    sub = ap.add_subparsers(dest="command", required=True)
    f = sub.add_parser("fit", help="fit PH spline paths through a waypoint file and report their figures")
    f.add_argument("input", help="waypoint file: CSV, JSON, APT/CL data or G-code")
    f.add_argument("--method", choices=["C1", "C2", "cubic", "all"], default="all",
                   help="C1/C2 PH quintic spline, G1 PH cubic spline, or all three (default)")
    f.add_argument("--units", choices=["mm", "m", "inch"], default=None,
                   help="units of a CSV/JSON file (default: mm)")
    f.set_defaults(func=cmd_fit)
    p = sub.add_parser("plan", help="plan a toolpath file (every pass, or one with --pass): PH paths within "
                       "tolerance, tool frames, timing, poses, robot check, export")
    p.add_argument("input", help="toolpath: APT/CL data, CSV, JSON or 5-axis G-code")
    p.add_argument("--frame", choices=["rmf", "grm", "juttler", "er", "double-reflection"], default="rmf")
    p.add_argument("--feed", type=float, default=50.0, help="TCP feed in mm/s where the file gives none (default 50)")
    p.add_argument("--rate", type=float, default=500.0, help="controller rate in Hz (500 e-Series, 125 CB)")
    p.add_argument("--robot", default="ur5e", help="ur3e, ur5e, ur10e, ur16e, ur20, or none")
    p.add_argument("--part-frame", help="part frame in the robot base: x,y,z,rx,ry,rz (m, rad)")
    p.add_argument("--tcp", help="tool centre point in the flange frame: x,y,z,rx,ry,rz (m, rad)")
    p.add_argument("--pass", dest="pass_index",
                   help="plan only pass K (or 'longest'): servoj program, exact pose stream; 'all' plans the whole "
                        "job even when the file has one pass (default with several)")
    p.add_argument("--corner", type=float, default=60.0, help="corners sharper than this (deg) split passes")
    p.add_argument("--tolerance", type=float, default=0.01,
                   help="largest distance of the path from the CAM polyline, mm (whole jobs; default 0.01)")
    p.add_argument("--units", choices=["mm", "m", "inch"], help="units of a CSV/JSON file (default mm)")
    p.add_argument("--machine", help="machine kinematics for 5-axis G-code (e.g. haas-umc-750)")
    p.add_argument("--axes", choices=["tool", "normal"], default="tool",
                   help="CSV/JSON i,j,k: the tool approach axis (default) or the surface normal")
    p.add_argument("--ignore-axes", action="store_true", help="ignore tool axes in the file")
    p.add_argument("--progress", action="store_true", help="show the progress bar even when not on a terminal")
    p.add_argument("-o", "--output", help="write the job: .csv / .json pose stream or .script URScript program "
                   "(one pass: servoj stream; whole job: movep along the passes within --tolerance, movel between)")
    p.add_argument("--plot", help="write a PNG: paths and tool axes, twist or spin, TCP speed, joints")
    p.set_defaults(func=cmd_plan)
    d = sub.add_parser("demo", help="run the main job on the bundled example")
    d.add_argument("--out", default="out", help="folder for the program and the plot (default: out)")
    d.set_defaults(func=cmd_demo)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        args.func(args)
    except PlannerError as exc:
        print(f"planner: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"planner: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
