"""Benchmark: the 3D view's data (issue 31) for the demo job and the whole NX job (12.9 million poses).

Per job, what the service does (the same functions its routes call):
- made: the fine path the planning task stores with the plan (:func:`view_data.fine_path`: poses thinned on the TCP
  and the tool frame, joints solved only at the kept samples and checked between them), s, and its stored bytes;
- first request: the plan and the stored fine path read from their bytes and the scene of a 1000-px view made
  (what the first ``GET /v1/jobs/{id}/view`` of a replica costs), s; in memory: the scene made again from the fine
  path a replica keeps (another view width; the same one is kept as bytes), s; the scene's bytes (JSON, what is
  sent);
- detail: ``GET /view/path`` of 1 % of the job's time (from its middle) at a tenth of the 1000-px tolerance (a view
  zoomed 10x), s and bytes.
The load average (1 min) is printed with each row: the times are wall times on a shared machine.

Run: ``python bench/bench_view.py [--quick] [--nx-job FILE]`` (--quick: the demo job only; --nx-job: a saved plan of
the NX job, ``planner plan NX.cls --robot ur5e --part-frame 697.5mm,804.226mm,-137.689mm,0,0,-0.022816rad
--cut-output standard:0 -o nx.job``; without it the NX job is planned here first, a few minutes).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import print_table  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
DEMO = ROOT / "examples" / "nx_first_pass.cls"
DEMO_SETTINGS = {"robot": "ur5e", "part_frame": [0.4, 0.9965, -0.1, 0.0, 0.0, 0.0], "cut_output": ["standard", 0]}
NX = ROOT.parent / "shared" / "data" / "nx_clsf_variable_contour_ust_a2.cls"
#: The part frame ``part_frame="auto"`` finds for the NX job on a UR5e (bench_memory.py), m and rad.
NX_SETTINGS = {"robot": "ur5e", "part_frame": [0.6975, 0.804226, -0.137689, 0.0, 0.0, -0.022816],
               "cut_output": ["standard", 0]}


def row(name: str, plan_bytes: bytes) -> list[object]:
    from planner.frontends.service import view_data
    from planner.job import load_job

    load = os.getloadavg()[0]
    job = load_job(plan_bytes)
    tic = time.perf_counter()
    fine = view_data.fine_path(job)
    stored = fine.to_bytes()
    made = time.perf_counter() - tic

    tic = time.perf_counter()
    job2 = load_job(plan_bytes)
    fine2 = view_data.ViewPath.from_bytes(stored)
    reach = view_data._reach(job2)
    scene = view_data.scene(job2, fine2, reach, pixels=1000)
    body = json.dumps(scene).encode()
    first = time.perf_counter() - tic
    tic = time.perf_counter()
    json.dumps(view_data.scene(job2, fine2, reach, pixels=1000)).encode()
    cached = time.perf_counter() - tic

    duration = float(fine2.t[-1])
    t0 = 0.5 * duration
    t1 = t0 + 0.01 * duration
    tolerance = max(scene["path"]["tolerance"] / 10, view_data.FINE_TOLERANCE)
    tic = time.perf_counter()
    part = json.dumps(view_data.detail(fine2, reach, t0, t1, tolerance)).encode()
    window = time.perf_counter() - tic
    return [name, f"{job.trajectory().n_samples:,}", f"{len(fine):,}", f"{made:.1f}", f"{len(stored) / 1e3:,.0f} kB",
            f"{first:.2f}", f"{cached:.3f}", f"{scene['path']['n']:,}", f"{len(body) / 1e3:,.1f} kB",
            f"{t1 - t0:.0f} s: {window:.3f} s, {len(part) / 1e3:,.1f} kB", f"{load:.1f}"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the demo job only")
    ap.add_argument("--nx-job", type=Path, help="a saved plan of the NX job (.job)")
    args = ap.parse_args()
    from planner import PlanSettings, plan

    rows = [row("demo (nx_first_pass.cls)", plan(DEMO, PlanSettings.from_dict(DEMO_SETTINGS)).to_bytes())]
    if not args.quick:
        if args.nx_job is not None:
            blob = args.nx_job.read_bytes()
        else:
            blob = plan(NX, PlanSettings.from_dict(NX_SETTINGS)).to_bytes()
        rows.append(row("whole NX job", blob))
    print_table(["job", "poses", "fine samples", "made s", "stored", "first request s", "in memory s",
                 "samples at 1000 px", "scene at 1000 px", "detail (1 % of the job, 10x zoom)", "load 1 min"], rows)


if __name__ == "__main__":
    main()
