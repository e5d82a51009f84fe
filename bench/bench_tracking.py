"""Benchmark: how closely the tracked TCP follows the planned path on bends, stream mode against program mode.

An S-shaped glue bead (CSV waypoints: straight runs joined by two half-circle bends of radius R, the tool axis
down; tests/bead_job.py), planned for a UR5e (part placed by ``part_frame="auto"``, the output standard[0] on
during the bead) at each bend radius and feed, is executed on the simulated controller through real ur_rtde by
:class:`drivers.ur.URDriver` in

* ``stream old``: servoJ with the planned joints as they are, lookahead 0.1 s, gain 300 (the former defaults);
* ``stream new``: the drivers' defaults (lookahead 0.03 s, gain 2000, targets shaped by the servo model:
  :mod:`drivers.servo`);
* ``program``: the job's URScript program (movep blends), the simulator in fast-forward.

Reported per run, from the execution report: the largest distance of the tracked TCP from the planned path (mm),
the largest distance of an output switch from its station (mm) and the largest difference between a switch's
planned and actual job time (ms), the planned feed along the bends (mm/s: the planner may lower it on a tight
bend) and the streaming loop's missed periods (a loaded machine; each stalls the targets).

Run: python bench/bench_tracking.py [--radii 50,20,10,5,2] [--feeds 25,50] [--configs old,new,program]
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import print_table  # noqa: E402

CONFIGS = {
    "old": {"mode": "stream", "lookahead": 0.1, "gain": 300.0, "compensate": False},
    "new": {"mode": "stream"},
    "program": {"mode": "program"},
}
FAST = {"approach_speed": 2.0, "approach_acceleration": 3.0}


def bead_job(radius_mm: float, feed_mm_s: float, tmp: Path):
    from planner import PlanSettings, plan
    from tests.bead_job import write_s_bead

    path = write_s_bead(tmp / f"bead_r{radius_mm:g}.csv", radius=radius_mm)
    return plan(str(path), PlanSettings(robot="ur5e", part_frame="auto", feed=feed_mm_s * 1e-3,
                                        cut_output=("standard", 0)))


def bend_feed(job) -> float:
    """The planned TCP speed's median over the job's moving samples, mm/s."""
    from drivers.report import planned_path

    t, p, _, _, _ = planned_path(job)
    v = np.linalg.norm(np.diff(p[:, :3], axis=0), axis=1) / np.diff(t)
    return float(np.median(v[v > 1e-4]) * 1e3) if (v > 1e-4).any() else math.nan


def run(job, host: str, cfg: dict):
    from drivers.ur import URDriver

    opts = {k: v for k, v in cfg.items() if k != "mode"}
    with URDriver(host, "ur5e", **opts, **FAST) as d:
        return d.execute(job, mode=cfg["mode"])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--radii", default="50,20,10,5,2", help="bend radii, mm")
    ap.add_argument("--feeds", default="25,50", help="feeds, mm/s")
    ap.add_argument("--configs", default="old,new,program", help=f"of {','.join(CONFIGS)}")
    args = ap.parse_args(argv)
    from drivers.execute import start_sim

    radii = [float(x) for x in args.radii.split(",")]
    feeds = [float(x) for x in args.feeds.split(",")]
    configs = args.configs.split(",")
    rows = []
    live = start_sim("ur5e") if any(CONFIGS[c]["mode"] == "stream" for c in configs) else None
    fast = start_sim("ur5e", speed=10.0) if "program" in configs else None
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for r in radii:
                for f in feeds:
                    job = bead_job(r, f, Path(tmp))
                    for c in configs:
                        cfg = CONFIGS[c]
                        sim = fast if cfg["mode"] == "program" else live
                        assert sim is not None
                        rep = run(job, sim.host, cfg)
                        ev = [e for e in rep.io_events if e.switched]
                        dist = max((e.distance_mm for e in ev), default=math.nan)
                        late = max((abs(e.actual_t - e.planned_t) * 1e3 for e in ev), default=math.nan)
                        missed = rep.loop.missed if rep.loop is not None else "-"
                        rows.append([f"{r:g}", f"{f:g}", f"{bend_feed(job):.1f}", c,
                                     "ok" if rep.ok else f"FAILED: {rep.reason[:90]}",
                                     f"{rep.max_path_error * 1e3:.3f}", f"{dist:.3f}", f"{late:.1f}", missed])
                        print(" | ".join(str(x) for x in rows[-1]), flush=True)
    finally:
        for s in (live, fast):
            if s is not None:
                s.stop()
    print()
    print_table(["bend radius mm", "feed mm/s", "planned feed mm/s", "config", "run", "path error mm",
                 "switch from station mm", "switch late ms", "missed periods"], rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
