"""Benchmark: peak memory of building a run's execution report against the job's length (issue 14).

A synthetic recording of the whole job (the plan's own TCP samples at 500 Hz plus 5 um of Gaussian noise on the
position, joints zero, the planned output bits) is fed chunk by chunk into the run's
:class:`drivers.recording.Recording`, as a driver does, and the report is built from it, two ways in one run:

- "before": against the planned path as whole arrays (:func:`drivers.report.planned_path`, ~80 B a sample, and a
  k-d tree of all of it: the code path the drivers used before this issue, still callable by passing the arrays);
- "after": against :class:`drivers.plan_window.PlannedPath` (summarized in one pass, searched a window of a few
  pieces at a time: what the drivers use now).

Each runs in a fresh process: the peak of Python's traced allocations (``tracemalloc``, numpy included) from the
start of the report's work (the job planned before) and the process's peak RSS (``ru_maxrss``: includes
planning). The figures of both must agree: the largest distance and its time exactly, every switch (its distance
from its station exactly, its arc lengths to 1e-9 of the path's length: the plan's arc length is summed piece by
piece, ~2e-10 apart over the NX job's 110 m).

Jobs: a synthetic straight pass (2 m at 1 mm/s: 10^6 samples; with ``--long``, at 0.1 mm/s: 10^7), and the
whole NX job of ``../shared/data`` (12.9 million samples, outputs on during its cuts) when it is there.

Run: ``python bench/bench_report.py [--quick] [--long]`` (--quick: the synthetic pass only).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import print_table  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
NX = ROOT.parent / "shared" / "data" / "nx_clsf_variable_contour_ust_a2.cls"
NX_AUTO_FRAME = "697.5mm,804.226mm,-137.689mm,0,0,-0.022816rad"  # as bench_memory.py (every move reachable on a UR5e)

CHILD = r"""
import json, resource, sys, time, tracemalloc
import numpy as np
from planner import PlanSettings, plan
from drivers.report import execution_report, new_recording, planned_path

src, way, frame, path = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4]
part = tuple(float(x) for x in frame.split(","))
job = plan(src, PlanSettings(robot="ur5e", part_frame=part, cut_output=("standard", 0),
                             **({"path": path} if path != "-" else {})))
rss_planned = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
tracemalloc.start()
t0 = time.perf_counter()
planned = planned_path(job) if way == "before" else None
rec = new_recording(job, planned)
rng = np.random.default_rng(1)
n = 0
for c in job.trajectory().chunks(joints=False):
    x = c.poses.copy()
    x[:, :3] += rng.normal(scale=5e-6, size=(len(c), 3))
    rec.extend(c.times, x, np.zeros((len(c), 6)), c.io)
    n += len(c)
rep = execution_report(job, rec, mode="bench", planned=planned)
wall = time.perf_counter() - t0
peak = tracemalloc.get_traced_memory()[1] / 2**20
print("RESULT", json.dumps({"n": n, "peak": peak, "wall": wall, "rss_planned": rss_planned,
      "rss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "err": rep.max_path_error,
      "err_t": rep.max_path_error_t, "events": [[e.bit, e.value, e.planned_s, e.actual_s, e.distance_mm]
                                                for e in rep.io_events], "trace": len(rep.trace)}))
"""


def run(src: Path, way: str, frame: str, path: str) -> dict:
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", CHILD, str(src), way, frame, path], cwd=ROOT, capture_output=True,
                         text=True)
    line = next((ln for ln in out.stdout.splitlines() if ln.startswith("RESULT ")), None)
    if out.returncode != 0 or line is None:
        print(out.stdout[-2000:], out.stderr[-3000:], file=sys.stderr)
        raise SystemExit(f"{src.name} {way}: the child process failed (exit {out.returncode})")
    res = json.loads(line[7:])
    res["process_wall"] = time.perf_counter() - t0
    return res


def main() -> None:
    quick, long = "--quick" in sys.argv, "--long" in sys.argv
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        line = Path(tmp) / "pass.csv"
        feed = 0.1 if long else 1.0  # mm/s
        line.write_text(f"x,y,z,feed\n0,0,0,\n2000,0,0,{60.0 * feed:.3f}\n")
        jobs = [(f"one 2 m pass at {feed:g} mm/s", line, "0.4,0.1,0.2,0,0,0", "cam")]
        if "--nx-only" in sys.argv:
            jobs = []
        if NX.is_file() and not quick:
            jobs.append(("NX job (shared/data)", NX, NX_AUTO_FRAME, "-"))
        for name, src, frame, path in jobs:
            res = {way: run(src, way, frame, path) for way in ("before", "after")}
            b, a = res["before"], res["after"]
            ds = [abs(x[k] - y[k]) for x, y in zip(b["events"], a["events"], strict=False) for k in (2, 3)
                  if x[k] == x[k]]
            ds_rel = max((d / max(abs(x[2]), 1.0) for d, x in zip(ds[::2], b["events"], strict=False)), default=0.0)
            same = (b["err"] == a["err"] and b["err_t"] == a["err_t"] and len(b["events"]) == len(a["events"])
                    and all(x[:2] == y[:2] and x[4] == y[4] for x, y in zip(b["events"], a["events"], strict=True))
                    and max(ds, default=0.0) <= 1e-9 * max(1.0, max((abs(x[2]) for x in b["events"]), default=0.0)))
            print(f"{name}: largest distance {b['err']!r} m at {b['err_t']!r} s before, {a['err']!r} m at "
                  f"{a['err_t']!r} s after; switches' arc lengths differ by at most {max(ds, default=0.0):.2e} m "
                  f"({ds_rel:.1e} of the arc length)", file=sys.stderr)
            for way in ("before", "after"):
                r = res[way]
                rows.append([name, way, f"{r['n']:,}", f"{r['peak']:.0f}", f"{r['rss']:.0f}", f"{r['rss_planned']:.0f}",
                             f"{1e3 * r['err']:.4f}", len(r["events"]), f"{r['wall']:.0f}",
                             "yes" if same else "NO"])
    with open("/proc/loadavg") as f:
        load = " ".join(f.read().split()[:3])
    print(f"Peak memory of building the execution report of a whole-job recording (load average {load})\n")
    print_table(["job", "plan searched", "samples", "report peak MB (tracemalloc)", "process peak RSS MB",
                 "RSS after planning MB", "largest distance mm", "switches", "wall s", "same figures"], rows)


if __name__ == "__main__":
    main()
