"""Parse time and peak memory of the toolpath readers (planner.io).

Rows: the three real CAM files in ../shared/data (when present) and a synthetic APT file of 10^6
lines written by this script (NX-style: GOTOs with modal tool axes every 4th point, RAPID, FEDRAT,
PAINT and comment lines). Baseline, measured in the same run: reading the same bytes line by line
and splitting them on commas without interpreting anything (the floor for any streaming parser in
Python). Peak memory is traced with tracemalloc during the read only.

Run:  python bench/bench_io.py [--lines 1000000]
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
import tracemalloc
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from planner.io import read_toolpath  # noqa: E402

DATA = ROOT.parent / "shared" / "data"
FILES = [
    ("nx_clsf_variable_contour_ust_a2.cls", {}),
    ("solidworks_cam_apt_boss_3plus2.apt", {}),
    ("nx2022_haas_umc750_5axis_gcode.txt", {"machine": "haas-umc-750"}),
]


def write_synthetic(path: Path, n_lines: int) -> None:
    """An NX-like CLSF with ``n_lines`` lines: zig-zag passes on a tilted, curved surface."""
    with open(path, "w") as fh:
        fh.write("TOOL PATH/SYNTHETIC,TOOL,BALL10\nTLDATA/MILL,10.0000,5.0000,75.0000,0.0000,0.0000\n")
        fh.write("MSYS/0.0000,0.0000,0.0000,1.0000000,0.0000000,0.0000000,0.0000000,1.0000000,0.0000000\n")
        fh.write("$$ centerline data\nLOAD/TOOL,1,ADJUST,1\nFEDRAT/MMPM,1200.0000\n")
        written, k = 6, 0
        while written < n_lines - 1:
            row, col = divmod(k, 200)
            if col == 0:
                fh.write("PAINT/COLOR,211\nRAPID\n")
                written += 2
            x = col * 0.5 if row % 2 == 0 else (199 - col) * 0.5
            y = row * 0.8
            z = 5.0 * math.sin(x / 20.0) * math.cos(y / 30.0)
            if k % 4 == 0:
                tilt = 0.3 * math.sin(x / 15.0)
                fh.write(f"GOTO/{x:.4f},{y:.4f},{z:.4f},{math.sin(tilt):.7f},0.0000000,{math.cos(tilt):.7f}\n")
            else:
                fh.write(f"GOTO/{x:.4f},{y:.4f},{z:.4f}\n")
            written += 1
            k += 1
        fh.write("END-OF-PATH\n")


def baseline(path: Path) -> float:
    t0 = time.perf_counter()
    n = 0
    with open(path, encoding="utf-8-sig", errors="replace") as fh:
        for line in fh:
            n += len(line.split(","))
    return time.perf_counter() - t0


def measure(path: Path, options: dict) -> tuple[float, float, int, int]:
    """Parse time (best of a few runs, no tracing) and tracemalloc peak (a separate traced run)."""
    with open(path, "rb") as fh:
        n_lines = sum(1 for _ in fh)
    repeats = 3 if n_lines < 100_000 else 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        read_toolpath(path, **options)  # warm-up (imports, caches)
        best = math.inf
        for _ in range(repeats):
            t0 = time.perf_counter()
            tp = read_toolpath(path, **options)
            best = min(best, time.perf_counter() - t0)
        n_pts = len(tp)
        del tp
        tracemalloc.start()
        read_toolpath(path, **options)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    return best, peak / 2**20, n_lines, n_pts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lines", type=int, default=1_000_000, help="lines of the synthetic APT file")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        synth = Path(tmp) / "synthetic.cls"
        write_synthetic(synth, args.lines)
        cases = [(DATA / f, opt) for f, opt in FILES if (DATA / f).exists()] + [(synth, {})]
        if len(cases) == 1:
            print(f"note: {DATA} not found, only the synthetic file is measured")
        for path, opt in cases:
            dt, peak, n_lines, n_pts = measure(path, opt)
            base = baseline(path)
            size = os.path.getsize(path) / 2**20
            rows.append((path.name, n_lines, n_pts, size, dt, n_lines / dt, peak, base))
    head = f"{'file':40s} {'lines':>9s} {'points':>9s} {'MiB':>6s} {'parse s':>8s} {'lines/s':>10s} "
    head += f"{'peak MiB':>9s} {'split-only s':>12s} {'ratio':>6s}"
    print(head)
    print("-" * len(head))
    for name, n_lines, n_pts, size, dt, rate, peak, base in rows:
        print(
            f"{name[:40]:40s} {n_lines:9d} {n_pts:9d} {size:6.1f} {dt:8.3f} {rate:10.0f} "
            f"{peak:9.1f} {base:12.3f} {dt / base:6.1f}"
        )
    print("parse s: best wall time of the read, untraced; peak MiB: tracemalloc peak of a separate traced")
    print("read (output arrays included; the file itself is streamed, never held whole).")
    print("split-only: the same file read line by line and split on commas, nothing else (baseline).")


if __name__ == "__main__":
    main()
