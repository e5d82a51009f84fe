"""Benchmark: peak resident memory of ``planner plan`` against the number of poses (issue 16, bounded memory).

Each row runs ``planner plan FILE [-o OUT]`` in a fresh Python process and reads its peak RSS
(``resource.getrusage``): with no output and with every output format (a CSV and a JSON trajectory, a saved
``.job``; with a robot also the whole-job URScript program). The files:
- a synthetic NX-style face-milling CLSF: 300 CIRCLE records (half circles of 100 mm radius at 100 mm/min,
  about 100,000 points after the arcs, about 28 million poses at 500 Hz), written here;
- a synthetic 10^7-pose job: one straight 2 m pass at 0.1 mm/s (one move of 10^7 samples);
- the real NX job of ``../shared/data`` (12.9 million poses), when it is there, without a robot and on a UR5e
  at the part frame ``part_frame="auto"`` finds for it (joints in the CSV, the program as ``.script``).
Baseline in the same run: the process's RSS after importing the planner and reading the file (what every
run pays before planning). Target: under 300 MB for 13.5 million poses in every output format and with none.

Run: ``python bench/bench_memory.py [--quick]`` (--quick: the 10^7-pose job only, CSV only).
"""

from __future__ import annotations

import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import print_table  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
NX = ROOT.parent / "shared" / "data" / "nx_clsf_variable_contour_ust_a2.cls"
#: The part frame ``plan(NX, PlanSettings(robot="ur5e", part_frame="auto"))`` printed (every move reachable).
NX_AUTO_FRAME = "697.5mm,804.226mm,-137.689mm,0,0,-0.022816rad"

RUNNER = """
import resource, sys
sys.argv = ["planner"] + sys.argv[1:]
if sys.argv[1] == "--baseline":
    import planner.plan, planner.io
    planner.io.read_toolpath(sys.argv[2])
    code = 0
else:
    from planner.frontends.cli.main import main
    code = main(sys.argv[1:])
print("PEAK_KB", resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr)
sys.exit(code)
"""


def face_milling(path: Path, arcs: int = 300, radius: float = 100.0, feed: float = 100.0) -> None:
    """A CLSF of ``arcs`` half circles (mm, mm/min), joined by short feeds, tool axis +Z."""
    lines = ["TOOL PATH/FACE_MILLING,TOOL,EM20", "UNITS/MM", "MULTAX/ON", "RAPID", "GOTO/0.0,0.0,5.0,0.0,0.0,1.0",
             f"FEDRAT/MMPM,{feed:.1f}", "GOTO/0.0,0.0,0.0"]
    x = 0.0
    for k in range(arcs):
        sign = 1.0 if k % 2 == 0 else -1.0
        cx = x + radius
        lines.append(f"CIRCLE/{cx:.4f},0.0000,0.0000,0.0,0.0,{sign:.1f},{radius:.4f}")
        x += 2.0 * radius
        lines.append(f"GOTO/{x:.4f},0.0000,0.0000")
        lines.append(f"GOTO/{x + 1.0:.4f},0.0000,0.0000")
        x += 1.0
    lines += ["RAPID", f"GOTO/{x:.4f},0.0,5.0", "END-OF-PATH", "FINI"]
    path.write_text("\n".join(lines) + "\n")


def long_pass(path: Path, length_m: float = 2.0, feed_mm_s: float = 0.1) -> None:
    """One straight pass as a CSV (mm, feed in mm/s): length / feed * 500 poses."""
    path.write_text("x,y,z,feed\n0,0,0,\n" + f"{1e3 * length_m:.1f},0,0,{60.0 * feed_mm_s:.3f}\n")


def peak(args: list[str]) -> tuple[float, float, int]:
    """(peak RSS in MB, wall time in s, exit code) of one run in a fresh process."""
    t0 = time.perf_counter()
    run = subprocess.run([sys.executable, "-c", RUNNER, *args], cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    kb = next((int(line.split()[1]) for line in run.stderr.splitlines() if line.startswith("PEAK_KB")), -1)
    if run.returncode != 0:
        print(run.stdout[-2000:], run.stderr[-2000:], file=sys.stderr)
    return kb / 1024.0, wall, run.returncode


def main() -> None:
    quick = "--quick" in sys.argv
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        jobs = []
        long_csv = t / "long_pass.csv"
        long_pass(long_csv)
        every = [None, ".csv", ".json", ".job"]
        if not quick:
            face = t / "face_milling.cls"
            face_milling(face)
            jobs.append(("face milling, 300 arcs", face, [], every))
        jobs.append(("one 2 m pass at 0.1 mm/s", long_csv, ["--path", "cam"], [None, ".csv"] if quick else every))
        if NX.is_file() and not quick:
            jobs.append(("NX job (shared/data)", NX, [], every))
            jobs.append(("NX job on a UR5e", NX, ["--robot", "ur5e", "--part-frame", NX_AUTO_FRAME],
                         [None, ".csv", ".script"]))
        for name, src, extra, outputs in jobs:
            base, _, _ = peak(["--baseline", str(src)])
            first = len(rows)
            poses = "-"
            for suffix in outputs:
                out = [] if suffix is None else ["-o", str(t / f"out{suffix}")]
                if suffix == ".script":  # the whole job as one program, over the 250 kB a controller takes at once
                    out += ["--max-program-bytes", "100000000"]
                mb, wall, code = peak(["plan", str(src), *extra, *out])
                if suffix == ".csv" and code == 0:
                    with open(t / "out.csv", encoding="utf-8") as f:
                        poses = next(int(line.split(": ")[1]) for line in f if line.startswith("# samples: "))
                size = (t / f"out{suffix}").stat().st_size / 1e6 if suffix and code == 0 else math.nan
                rows.append([name, suffix or "(none)", poses, f"{base:.0f}", f"{mb:.0f}", f"{mb - base:.0f}",
                             f"{size:.0f}" if size == size else "-", f"{wall:.1f}", code])
                for f in t.glob("out.*"):
                    f.unlink()
            for row in rows[first:]:
                row[2] = poses  # the job's poses (counted from its CSV)
    print("Peak resident memory of `planner plan` (MB); baseline: import + read the file in the same kind of process\n")
    print_table(["job", "output", "poses", "baseline MB", "peak MB (target < 300)", "above baseline MB", "output MB",
                 "wall s", "exit"], rows)


if __name__ == "__main__":
    main()
