"""Parse time and peak memory of the toolpath readers (planner.io).

Rows: the three real CAM files in ../shared/data (when present) and a synthetic APT file of 10^6
lines written by this script (NX-style: GOTOs with modal tool axes every 4th point, RAPID, FEDRAT,
PAINT and comment lines). Baseline, measured in the same run: reading the same bytes line by line
and splitting them on commas without interpreting anything (the floor for any streaming parser in
Python). Peak memory is traced with tracemalloc during the read only.

Dialect rows (``--dialect-lines``, default 10^5, written by this script): an NX NURBS CLSF (cubic
``NURBS/`` records of 8 control points), an APT drill job (``CYCLE/DRILL,DEEP`` holes), a G-code G83
job, and one Sinumerik program with its ISO equivalent (the same moves; the ratio Sinumerik/ISO is
the cost of the dialect's expressions). A second table times the sampling of the NURBS records
within 1 um (:func:`planner.io.linearize_arcs`) against the read itself.

Run:  python bench/bench_io.py [--lines 1000000] [--dialect-lines 100000]
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

from planner.io import linearize_arcs, read_toolpath  # noqa: E402

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


def write_nurbs(path: Path, n_lines: int) -> None:
    """NX-style NURBS/ records: cubic, 8 control points (7 CNTRL lines + 1 KNOT line), on a wavy surface."""
    with open(path, "w") as fh:
        fh.write("TOOL PATH/FIXED_CONTOUR,TOOL,BALL_MILL\nFEDRAT/MMPM,250.0000\nGOTO/0.0000,0.0000,0.0000\n")
        x, written = 0.0, 3
        while written < n_lines - 10:
            fh.write("NURBS/\nKNOT/0.2000000,0.4000000,0.6000000,0.8000000,1.0000000\n")
            for j in range(1, 8):
                xx = x + j * 2.0
                fh.write(f"CNTRL/{xx:.4f},{10 * math.sin(xx / 17):.4f},{3 * math.cos(xx / 11):.4f}\n")
            x += 14.0
            written += 9
        fh.write("END-OF-PATH\n")


def write_drill_apt(path: Path, n_lines: int) -> None:
    """An APT drill job: CYCLE/DRILL,DEEP with pecks, one GOTO a hole."""
    with open(path, "w") as fh:
        fh.write("FEDRAT/MMPM,500\nGOTO/0,0,50\nCYCLE/DRILL,DEEP,FEDTO,-12,RAPTO,3,RTRCTO,5,STEP,4,MMPM,120\n")
        for k in range(n_lines - 4):
            fh.write(f"GOTO/{(k % 100) * 5.0:.4f},{(k // 100) * 5.0:.4f},0.0000\n")
        fh.write("CYCLE/OFF\n")


def write_drill_gcode(path: Path, n_lines: int) -> None:
    """A G-code G83 job, one X/Y block a hole."""
    with open(path, "w") as fh:
        fh.write("G90 G17 G21 G94\nG00 X0 Y0 Z50\nG98 G83 X0 Y0 Z-12 R3 Q4 F120\n")
        for k in range(1, n_lines - 4):
            fh.write(f"X{(k % 100) * 5.0:.3f} Y{(k // 100) * 5.0:.3f}\n")
        fh.write("G80\nM30\n")


def write_sinumerik_pair(sin: Path, iso: Path, n_lines: int) -> None:
    """The same zig-zag moves as a Sinumerik program (variables, expressions) and as ISO G-code."""
    with open(sin, "w") as fs, open(iso, "w") as fi:
        fs.write("DEF REAL _X0=5, _DY=0.8\n_camtolerance=.01\nG17 G710 G94 G90 FNORM\nCYCLE832(_camtolerance,1,1)\n"
                 "T=\"BALL10\"\nM6\nG0 X=_X0 Y0 Z5\nG1 Z0 F=1200\n")
        fi.write("G17 G21 G94 G90\nM6\nG0 X5 Y0 Z5\nG1 Z0 F1200\n")
        for k in range(n_lines - 8):
            row, col = divmod(k, 200)
            x = col * 0.5 if row % 2 == 0 else (199 - col) * 0.5
            fs.write(f"N{k + 10} X=_X0+{x:.3f} Y=R1+{row}*_DY Z=SIN({x:.3f})\n")
            fi.write(f"N{k + 10} X{5 + x:.3f} Y{row * 0.8:.3f} Z{math.sin(math.radians(x)):.6f}\n")
        fs.write("M30\n")
        fi.write("M30\n")


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
    ap.add_argument("--dialect-lines", type=int, default=100_000, help="lines of each dialect file")
    args = ap.parse_args()
    rows = []
    nurbs_rows = []
    with tempfile.TemporaryDirectory() as tmp:
        synth = Path(tmp) / "synthetic.cls"
        write_synthetic(synth, args.lines)
        m = args.dialect_lines
        nurbs, drill_apt, drill_nc = Path(tmp) / "nurbs.cls", Path(tmp) / "drill.cls", Path(tmp) / "drill_g83.nc"
        sin, iso = Path(tmp) / "zigzag.mpf", Path(tmp) / "zigzag_iso.nc"
        write_nurbs(nurbs, m)
        write_drill_apt(drill_apt, m)
        write_drill_gcode(drill_nc, m)
        write_sinumerik_pair(sin, iso, m)
        cases = [(DATA / f, opt) for f, opt in FILES if (DATA / f).exists()] + [(synth, {})]
        cases += [(nurbs, {}), (drill_apt, {}), (drill_nc, {}), (iso, {}), (sin, {})]
        if len(cases) == 1:
            print(f"note: {DATA} not found, only the synthetic file is measured")
        for path, opt in cases:
            dt, peak, n_lines, n_pts = measure(path, opt)
            base = baseline(path)
            size = os.path.getsize(path) / 2**20
            rows.append((path.name, n_lines, n_pts, size, dt, n_lines / dt, peak, base))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tp = read_toolpath(nurbs)
        for tol in (1e-5, 1e-6):
            t0 = time.perf_counter()
            lin = linearize_arcs(tp, tol)
            nurbs_rows.append((tol, len(tp.nurbs), len(lin) - len(tp), time.perf_counter() - t0))
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
    times = {name: dt for name, _, _, _, dt, *_ in rows}
    print(f"Sinumerik / ISO parse time of the same moves: {times['zigzag.mpf'] / times['zigzag_iso.nc']:.2f}")
    print()
    read_s = times["nurbs.cls"]
    print(f"{'NURBS sampling tol':>18s} {'records':>8s} {'points added':>13s} {'time s':>8s} {'/ read':>7s}")
    for tol, n_rec, added, dt in nurbs_rows:
        print(f"{tol:18.0e} {n_rec:8d} {added:13d} {dt:8.3f} {dt / read_s:7.2f}")


if __name__ == "__main__":
    main()
