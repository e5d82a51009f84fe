"""Benchmark: the free spin about an axisymmetric tool (``spin="reach"``, issue 30) against the RMM spin, same run.

Every case is planned twice in this run, with the RMM spin (the default) and with ``spin="reach"``, and both plans
are checked by the planner's own robot check (:func:`planner.cam.reach.check_job`, at ``reach_step``). Printed per
case and spin: moves with problems, stretches of lowered feed and the lowest feed ratio, changes of arm
configuration, job time, the least singularity margin and samples out of reach on the spin's own samples (the
summary's figures), the largest spin rate and acceleration in time at the planned time laws, the time to choose the
spin and the whole planning time.

Cases (files of ``../shared/data`` next to the repository; a missing file is skipped with a message):
- the shared NX job at the README's part frame on a UR5e, the tool on the flange axis (the README's case);
- the same with a nozzle 34 deg off the flange axis (tcp 0,50,120 mm, rx 0.6 rad), where a spin moves every joint;
- ``examples/nx_first_pass.cls``, the SOLIDWORKS and the NX G-code file, and the NX job, at fixed frames where the
  RMM spin of the angled nozzle leaves poses out of reach.

The README's case on the command line (main's convention: a part frame's lengths with their unit)::

    planner plan ../shared/data/nx_clsf_variable_contour_ust_a2.cls --robot ur5e \
        --part-frame 400mm,996.5mm,-100mm,0,0,0 --spin reach

Run: ``python bench/bench_spin.py`` (the NX job twice per case: about 25 minutes on 2 idle cores),
``python bench/bench_spin.py --quick`` (the small cases only), or ``--only TEXT`` (the cases whose name holds
TEXT, e.g. ``--only "tight frame"``). "choose s" is the time to choose the spin, "share" its part of the whole
planning time of that plan ("plan s", wall clock: compare shares within one run; the last line gives the load
average over the run).
"""

from __future__ import annotations

import math
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import print_table  # noqa: E402

from planner import PlanSettings, plan  # noqa: E402
from planner.cam.spin_choice import spin_rates  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"
README_FRAME = (0.4, 0.9965, -0.1, 0.0, 0.0, 0.0)
ANGLED = (0.0, 0.05, 0.12, 0.6, 0.0, 0.0)

CASES = [
    ("nx_first_pass, angled nozzle", REPO / "examples" / "nx_first_pass.cls", (0.3, 0.2, -0.3, 0, 0, 0), ANGLED, {}),
    ("nx_first_pass, flange axis, README frame", REPO / "examples" / "nx_first_pass.cls", README_FRAME, None, {}),
    ("solidworks apt, angled nozzle", DATA / "solidworks_cam_apt_boss_3plus2.apt", (0.3, 0.2, -0.3, 0, 0, 0),
     ANGLED, {}),
    ("nx g-code, angled nozzle", DATA / "nx2022_haas_umc750_5axis_gcode.txt", (0.45, 0.1, -0.05, 0, 0, 0), ANGLED,
     {"machine": "haas-umc-750"}),
    ("NX job, flange axis, README frame", DATA / "nx_clsf_variable_contour_ust_a2.cls", README_FRAME, None, {}),
    ("NX job, angled nozzle, README frame", DATA / "nx_clsf_variable_contour_ust_a2.cls", README_FRAME, ANGLED, {}),
    ("NX job, angled nozzle, tight frame", DATA / "nx_clsf_variable_contour_ust_a2.cls", (0.25, 0.3, -0.25, 0, 0, 0),
     ANGLED, {}),
]


def _row(name: str, spin: str, job, seconds: float) -> list:
    s = job.summary()
    sp = s.get("spin")
    rates = [spin_rates(m) for m in job.moves]
    w = max((r[0] for r in rates), default=0.0)
    a = max((r[1] for r in rates), default=0.0)
    sing = "-" if sp is None else f"{sp['reach' if spin == 'reach' else 'rmm']['singularity_margin']:.3f}"
    out = "-" if sp is None else str(sp["reach" if spin == "reach" else "rmm"]["out_of_reach_samples"])
    lowest = min((float(x.split("lowered to ")[1].split(" %")[0]) for x in job.slowed), default=100.0)
    return [name, spin, len(job.problems), len(job.slowed), f"{lowest:.1f} %", len(s["reconfigurations"]),
            f"{job.duration:.1f}", sing, out, f"{math.degrees(w):.1f}", f"{math.degrees(a):.0f}",
            f"{job.timings.get('spin', 0.0):.2f}", f"{seconds:.1f}",
            f"{100.0 * job.timings.get('spin', 0.0) / seconds:.1f} %" if spin == "reach" else "-"]


def main(argv: list[str]) -> None:
    quick = "--quick" in argv
    only = argv[argv.index("--only") + 1] if "--only" in argv[:-1] else None
    load0 = os.getloadavg()[0]
    rows = []
    for name, src, frame, tcp, read in CASES:
        if only is not None and only not in name:
            continue
        if not src.exists():
            print(f"{name}: {src} not found, skipped")
            continue
        if quick and src.name == "nx_clsf_variable_contour_ust_a2.cls":
            continue
        base = dict(robot="ur5e", part_frame=frame, tcp=tcp)
        jobs = {}
        for spin in ("rmm", "reach"):
            tic = time.perf_counter()
            jobs[spin] = plan(str(src), PlanSettings(spin=spin, **base), read_options=read or None)
            rows.append(_row(name, spin, jobs[spin], time.perf_counter() - tic))
        sp = jobs["reach"].summary()["spin"]
        rows[-1][1] = f"reach ({sp['spun_runs']}/{sp['runs']} runs spun)"
        # the RMM row's margins are the summary's RMM figures of the reach plan (same samples)
        rows[-2][7] = f"{sp['rmm']['singularity_margin']:.3f}"
        rows[-2][8] = str(sp["rmm"]["out_of_reach_samples"])
        print(f"{name}: done", flush=True)
    print_table(["case", "spin", "problems", "slowed", "lowest feed", "reconfig.", "job s", "sing. margin",
                 "out of reach", "spin deg/s", "spin deg/s^2", "choose s", "plan s", "share"], rows)
    print(f"load average (1 min) {load0:.1f} at the start, {os.getloadavg()[0]:.1f} at the end, "
          f"on {os.cpu_count()} cores")


if __name__ == "__main__":
    main(sys.argv[1:])
