"""Benchmark: whole real CAM files planned with ``planner.plan`` (the CAM polyline model; issues 6 and 11).

For each file of ``shared/data`` (next to the repository; a missing file is skipped with a message):
parse time, passes, corners found, planning time, largest deviation of the planned path from the CAM
polyline (target <= 0.01 mm), largest tool-axis error at the CAM points (target < 0.05 deg), total
tool spin about the axis against slerping the CAM orientations (tool axis, x along the direction of
travel) point to point, and the time to produce the 500 Hz trajectory of the whole job (its chunks, no joints).
The settings are the defaults (path "auto" = "cam" for these files) except the feed where a file gives none:
10 mm/s, the former CAM default (PlanSettings' default is 50 mm/s), so the durations compare with earlier runs.

Baselines measured in the same run, on the same passes:
- "through pts": a PH quintic spline forced through the CAM points with the tangents of the C2
  cubic spline (``fit_ph_spline(points, continuity="C1")``): its largest deviation from the polyline;
- "C2 axis": the axis interpolation of ``planner.frames.tool_frames`` (C2 cubic spline of the axes,
  normalized): its largest distance from the CAM great-circle arcs between points, against ours.

Run: ``python bench/bench_cam.py`` (about a minute per file on 2 cores; the NX file must plan in
under 30 s).
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import print_table  # noqa: E402

from planner import PlanSettings, plan  # noqa: E402
from planner.cam.axes import arc_departure  # noqa: E402
from planner.cam.fidelity import span_deviation  # noqa: E402
from planner.curves import fit_ph_spline  # noqa: E402
from planner.io import read_toolpath  # noqa: E402

DATA = Path(__file__).resolve().parent.parent.parent / "shared" / "data"
FILES = [
    ("nx_clsf_variable_contour_ust_a2.cls", {}),
    ("nx2022_haas_umc750_5axis_gcode.txt", {"machine": "haas-umc-750"}),
    ("solidworks_cam_apt_boss_3plus2.apt", {}),
]
#: The defaults, with the former CAM default feed (10 mm/s) where a file gives none.
SETTINGS = PlanSettings(feed=0.01)


def through_points_deviation(passes) -> float:
    """Largest deviation from the polyline of PH splines forced through the CAM points (C2 tangents)."""
    worst = 0.0
    for p in passes:
        path = fit_ph_spline(p.points, continuity="C1")
        chord = np.diff(p.points, axis=0)
        chord /= np.linalg.norm(chord, axis=1, keepdims=True)
        dev, _ = span_deviation(path.A, path.starts, chord, 65)
        worst = max(worst, float(dev.max()))
    return worst


def c2_axis_departure(moves) -> float:
    """Largest distance (deg) of tool_frames' C2 cubic axis spline from the CAM great-circle arcs."""
    worst = 0.0
    for m in moves:
        f = m.frames
        if m.kind != "cut" or f.interpolant is None:
            continue
        u = m.path.waypoint_knots
        spline = CubicSpline(u, f.axes) if u.size > 2 else CubicSpline(u, f.axes, bc_type="natural")
        uu = u[:-1, None] + np.diff(u)[:, None] * np.linspace(0.0, 1.0, 17)
        z = spline(uu.ravel())
        z /= np.linalg.norm(z, axis=1, keepdims=True)
        worst = max(worst, float(arc_departure(z.reshape(uu.shape + (3,)), f.axes[:-1], f.axes[1:]).max()))
    return float(np.degrees(worst))


def main() -> None:
    rows_a, rows_b, rows_c = [], [], []
    for name, options in FILES:
        path = DATA / name
        if not path.is_file():
            print(f"skipping {name}: not found in {DATA}")
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tic = time.perf_counter()
            tp = read_toolpath(path, **options)
            parse = time.perf_counter() - tic
        tic = time.perf_counter()
        job = plan(tp, SETTINGS)
        plan_s = time.perf_counter() - tic
        tic = time.perf_counter()
        n = 0
        for chunk in job.trajectory(500.0).chunks():
            n += chunk.times.size
        stream = time.perf_counter() - tic
        base_dev = through_points_deviation(job.segmentation.passes)
        base_axis = c2_axis_departure(job.moves)
        s = job.summary()
        rows_a.append([name, len(tp), f"{parse:.2f}", s["passes"], s["corners"], s["rapids"], s["reorientations"],
                       s["skipped"], f"{plan_s:.2f}", f"{s['duration_s']:.0f}"])
        rows_b.append([name, f"{s['max_deviation_mm']:.5f}", f"{1e3 * base_dev:.4f}", s["knots_added"],
                       f"{s['max_axis_error_deg']:.1e}", f"{s['max_axis_departure_deg']:.3f}", f"{base_axis:.2f}",
                       f"{s['spin_deg']:.3g}", f"{s['slerp_spin_deg']:.4g}"])
        rows_c.append([name, n, f"{stream:.2f}", f"{n / stream:.3g}"])
    print("\nPlanning (plan: everything after parsing: split, fit, frames, time law; duration: motion time)\n")
    print_table(["file", "points", "parse s", "passes", "corners", "rapids", "reorient.", "skipped",
                 "plan s (< 30 for NX)", "duration s"], rows_a)
    print("\nFidelity (deviation from the CAM polyline, mm, target <= 0.01; axis error at the CAM points, deg, "
          "target < 0.05;\naxis departure from the CAM great circles between points, deg; spin about the tool "
          "axis over all cuts, deg)\n")
    print_table(["file", "max dev mm", "through pts mm (baseline)", "knots added", "axis err deg",
                 "axis departure deg", "C2 axis deg (baseline)", "spin deg", "slerp spin deg (baseline)"], rows_b)
    print("\n500 Hz pose stream of the whole job (cuts, rapids, turns), produced move by move\n")
    print_table(["file", "poses", "stream s", "poses/s"], rows_c)


if __name__ == "__main__":
    main()
