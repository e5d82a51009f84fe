"""Benchmark: size, save and load time of a saved job (``.job``, planner.jobfile) against the former pickle file.

For the demo job (examples/nx_first_pass.cls on a UR5e) and the whole shared NX job
(``../shared/data/nx_clsf_variable_contour_ust_a2.cls``, 867 passes, on a UR5e at part frame (0.4, 0.9965, -0.1,
0, 0, 0); skipped when the folder is absent), each planned once, then saved and loaded:
- baseline, in the same run: the former file, format version 1 (pickle of the job, gzip level 6, magic and
  version in front), written and read the way ``PlannedJob.save`` / ``load_job`` did before;
- the saved-job file of this version (format 2: a ZIP archive of the JSON manifest and the array pools).
Columns: file size; save (serialize, compress, write); load (read, check, rebuild the job); the memory the loaded
job holds and the peak while loading (tracemalloc, MB); and load plus a pass over every move (the trajectory at
1 Hz with the robot's joints, CSV text): what a consumer pays before its first export, since a loaded job builds
its evaluation caches (PCHIP interpolants, arc-length tables) when first used, where the pickle restored those it
held (and held their memory). Times are the best of 3.

Run: ``python bench/bench_jobfile.py [--quick]`` (--quick: the demo job only).
"""

from __future__ import annotations

import gzip
import pickle
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import print_table  # noqa: E402

from planner import PlanSettings, load_job, plan  # noqa: E402
from planner.export.tables import csv_text  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
NX = ROOT.parent / "shared" / "data" / "nx_clsf_variable_contour_ust_a2.cls"
NX_PART = (0.4, 0.9965, -0.1, 0.0, 0.0, 0.0)
PICKLE_MAGIC = b"planner-job\n"


def pickle_save(job, path: Path) -> int:
    """The former ``PlannedJob.save``: pickle, gzip level 6, magic and version 1 in front."""
    data = pickle.dumps(job, protocol=pickle.HIGHEST_PROTOCOL)
    blob = PICKLE_MAGIC + (1).to_bytes(2, "big") + gzip.compress(data, compresslevel=6, mtime=0)
    path.write_bytes(blob)
    return len(blob)


def pickle_load(path: Path):
    """The former ``load_job`` (a file this process wrote: never load a pickle from anyone else)."""
    blob = path.read_bytes()
    return pickle.loads(gzip.decompress(blob[len(PICKLE_MAGIC) + 2:]))  # noqa: S301 - the baseline being replaced


def every_move(job) -> int:
    """The trajectory at 1 Hz with joints as CSV text: every move's frames and time law evaluated once."""
    return sum(len(piece) for piece in csv_text(job.trajectory(1.0)))


def best(fn, repeat: int = 3) -> tuple[float, object]:
    out, t_best = None, float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        t_best = min(t_best, time.perf_counter() - t0)
    return t_best, out


def rows_for(name: str, job, folder: Path) -> list[list[object]]:
    rows = []
    for fmt, save, load in (("pickle (format 1, baseline)", pickle_save, pickle_load),
                            ("planner-job 2 (this version)", lambda j, p: j.save(p), load_job)):
        path = folder / f"{name}-{fmt[:6]}.job"
        t_save, size = best(lambda s=save, p=path: s(job, p))
        t_load, _ = best(lambda ld=load, p=path: ld(p))
        t_use, _ = best(lambda ld=load, p=path: every_move(ld(p)))
        tracemalloc.start()
        kept = load(path)
        held, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        del kept
        memory = f"{held / 2**20:.0f} / {peak / 2**20:.0f}"
        rows.append([name, fmt, f"{size:,}", f"{t_save:.3f}", f"{t_load:.3f}", memory, f"{t_use:.3f}"])
    return rows


def main() -> None:
    quick = "--quick" in sys.argv[1:]
    jobs = [("demo", lambda: plan(ROOT / "examples" / "nx_first_pass.cls",
                                   PlanSettings(robot="ur5e", cut_output=("standard", 0), part_frame=NX_PART)))]
    if not quick and NX.exists():
        jobs.append(("NX whole job", lambda: plan(NX, PlanSettings(robot="ur5e", part_frame=NX_PART))))
    elif not quick:
        print(f"(no {NX}: the demo job only)")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, make in jobs:
            t0 = time.perf_counter()
            job = make()
            print(f"planned {name}: {len(job.moves)} moves, {job.n_samples():,} poses at 500 Hz, "
                  f"in {time.perf_counter() - t0:.1f} s", flush=True)
            rows += rows_for(name, job, Path(tmp))
    print_table(["job", "file", "bytes", "save s", "load s", "held / peak MB", "load + every move at 1 Hz s"], rows)


if __name__ == "__main__":
    main()
