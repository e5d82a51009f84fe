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

from planner.errors import PlannerError

#: The bundled example the demo runs on (first pass of a real Siemens NX toolpath).
EXAMPLE_NAME = "nx_first_pass.csv"


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


def cmd_demo(args: argparse.Namespace) -> None:
    print("Demo: PH spline paths through the first pass of a real Siemens NX toolpath (bundled example).")
    example = example_path()
    points = _read_points(example, "mm")
    _print_fit(example, points, ["C1", "C2", "cubic"])


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
    d = sub.add_parser("demo", help="run the main job on the bundled example")
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
