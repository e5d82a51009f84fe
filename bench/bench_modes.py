"""Benchmark: the execution modes on a quiet and on a loaded machine, the measurement the default mode is chosen by.

Two jobs, each executed on the simulated controller through real ur_rtde by :class:`drivers.ur.URDriver` (its
defaults, the simulator in real time for every mode) in

* ``stream``: servoJ from this machine, one target every 2 ms, the loop's thread SCHED_FIFO where the system allows it
  (root, or a real-time limit: the header line says whether it does here);
* ``stream-ordinary``: the same with an ordinary thread (``realtime=False``: what a user without real-time
  privileges, or a container without CAP_SYS_NICE, gets);
* ``program``: the job's URScript program, run by the controller;

on

* ``demo``: the demo's job (``planner demo``: the first pass of the bundled Siemens NX CLSF, 62 s, spray output on
  standard DO 0 during the cut);
* ``bend``: the S-shaped glue bead of tests/bead_job.py with 5 mm bends at 50 mm/s (the output on along the bead).

Each at every load level: that many busy processes (``python -c "while 1: pass"``) started beside the run and ended
after it (the machine's other work comes on top: the 1-minute load average at the run's end is printed).

Reported per run: success (or the failure's reason), the streaming loop's missed control periods (each holds the arm
on its last target and delays the rest of the job by a period; program mode has no loop on this machine: "-"), the
longest stall of the loop, the largest distance of the tracked TCP from the planned path (drivers.report, um), the
largest distance of an output switch from its station and the run's duration against the planned one.

Run: python bench/bench_modes.py [--jobs demo,bend] [--modes stream,program] [--loads 0,4] [--repeat 1]
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import print_table  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
#: The demo's part frame (m, rad): the pass in front of a UR5e (planner demo's).
DEMO_PART = (0.4, 0.9965, -0.1, 0.0, 0.0, 0.0)
#: A quicker approach to the start joints than the driver's careful default (the approach is not measured).
FAST = {"approach_speed": 2.0, "approach_acceleration": 3.0}
#: The modes measured: (URDriver.execute's mode, URDriver's options).
MODES = {"stream": ("stream", {}), "stream-ordinary": ("stream", {"realtime": False}), "program": ("program", {})}


def make_job(name: str, tmp: Path):
    from planner import PlanSettings, plan

    if name == "demo":
        return plan(str(REPO / "examples" / "nx_first_pass.cls"),
                    PlanSettings(robot="ur5e", part_frame=DEMO_PART, cut_output=("standard", 0)))
    if name == "bend":
        from tests.bead_job import write_s_bead

        path = write_s_bead(tmp / "bead_r5.csv", radius=5.0)
        return plan(str(path), PlanSettings(robot="ur5e", part_frame="auto", feed=0.05, cut_output=("standard", 0)))
    raise SystemExit(f"bench_modes: unknown job {name!r} (demo, bend)")


class Load:
    """``n`` busy processes for the duration of a ``with`` block (ended by their own ids afterwards)."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.procs: list[subprocess.Popen] = []

    def __enter__(self) -> Load:
        self.procs = [subprocess.Popen([sys.executable, "-c", "while 1: pass"]) for _ in range(self.n)]
        return self

    def __exit__(self, *exc) -> None:
        for p in self.procs:
            p.kill()
        for p in self.procs:
            p.wait()


def fifo_allowed() -> bool:
    """Whether this process may make a thread SCHED_FIFO (what URDriver's streaming loop asks for)."""
    from drivers.ur import _realtime_loop, _restore_scheduling

    before = _realtime_loop()
    if before is None:
        return False
    _restore_scheduling(before)
    return True


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", default="demo,bend", help="of demo, bend")
    ap.add_argument("--modes", default="stream,stream-ordinary,program", help=f"of {', '.join(MODES)}")
    ap.add_argument("--loads", default="0,4", help="busy processes beside the run, per load level")
    ap.add_argument("--repeat", type=int, default=1, help="runs per job, mode and load")
    args = ap.parse_args(argv)
    from drivers.execute import start_sim
    from drivers.ur import URDriver

    loads = [int(x) for x in args.loads.split(",")]
    modes = args.modes.split(",")
    for m in modes:
        if m not in MODES:
            raise SystemExit(f"bench_modes: unknown mode {m!r} ({', '.join(MODES)})")
    print(f"SCHED_FIFO for the streaming loop: {'allowed' if fifo_allowed() else 'refused'} here; "
          f"{os.cpu_count()} CPUs", flush=True)
    rows = []
    sim = start_sim("ur5e")
    try:
        with tempfile.TemporaryDirectory() as tmp:
            jobs = {name: make_job(name, Path(tmp)) for name in args.jobs.split(",")}
            for n in loads:
                for name, job in jobs.items():
                    for mode in modes:
                        for _ in range(args.repeat):
                            run_mode, options = MODES[mode]
                            with Load(n), URDriver(sim.host, "ur5e", **options, **FAST) as d:
                                rep = d.execute(job, mode=run_mode)
                                load = os.getloadavg()[0]
                            loop = rep.loop
                            ev = [e for e in rep.io_events if e.switched]
                            dist = max((e.distance_mm for e in ev), default=math.nan)
                            rows.append([n, f"{load:.1f}", name, mode,
                                         "ok" if rep.ok else f"FAILED: {rep.reason[:80]}",
                                         loop.missed if loop is not None else "-",
                                         f"{1e3 * loop.max:.1f}" if loop is not None else "-",
                                         f"{rep.max_path_error * 1e6:.2f}", f"{dist:.3f}",
                                         f"{rep.duration:.2f} / {rep.planned_duration:.2f}"])
                            print(" | ".join(str(x) for x in rows[-1]), flush=True)
    finally:
        sim.stop()
    print()
    print_table(["busy processes", "load avg", "job", "mode", "run", "missed periods", "longest period ms",
                 "path error um", "switch from station mm", "duration / planned s"], rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
