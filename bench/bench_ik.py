"""Benchmark: one-pose inverse and forward kinematics for a 2 ms control loop (issue 13).

The simulated UR controller needs one IK per 2 ms period (servoL, moveL, getInverseKinematics).
Prints, per call: ``inverse`` (all 8 branches of one pose), ``inverse_nearest`` (the branch nearest to
the current joints), ``forward`` for one joint vector, on regular poses and at the wrist singularity;
per pose: ``inverse_batch`` on a batch of 10^4 poses. The baselines are measured in the same run:
the block solver on one pose (``inverse_batch(model, pose)``, the path ``inverse`` took before), and
``forward`` on one row through the batch path (``forward(model, q[None])``).

Each of ``--poses`` poses (random joints in (-pi, pi]) is timed ``--repeat`` times and its best time
kept (robust to preemption on a shared machine); the table gives the median and the maximum over the
poses, and the speed-up of the medians. Target: inverse <= 50 us per call.

Run: python bench/bench_ik.py [--model ur5e] [--poses 200] [--repeat 15]
``rows()`` returns the table rows (bench/bench_sim.py prints them too).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import best_time, print_table  # noqa: E402

from planner.kinematics import forward, inverse, inverse_batch, inverse_nearest  # noqa: E402

HEADERS = ["kinematics call", "median us", "max us", "baseline median us", "speed-up", "target"]
TARGET_US = 50.0
BATCH = 10_000


def _per_item(fn, items, repeat: int) -> np.ndarray:
    """Time (us) of one call of ``fn`` on each item: the best of ``repeat`` calls (robust to preemption
    on a shared machine), so the median and the maximum over the items say how the time varies."""
    out = []
    for x in items:
        best = np.inf
        for _ in range(repeat):
            t0 = time.perf_counter()
            fn(x)
            best = min(best, time.perf_counter() - t0)
        out.append(best * 1e6)
    return np.array(out)


def rows(model: str = "ur5e", poses: int = 200, repeat: int = 15, seed: int = 0) -> list[list[str]]:
    """The benchmark's table rows (see ``HEADERS``): one-pose calls against their baselines."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(-np.pi, np.pi, (poses, 6))
    P = forward(model, q)
    q_near = q + rng.uniform(-0.01, 0.01, q.shape)  # a controller's current joints, next to the target
    q_sing = q.copy()
    q_sing[:, 4] = 0.0  # wrist singularity: q6 held at q_near's value
    P_sing = forward(model, q_sing)
    q_turn = q_sing.copy()
    q_turn[:, 2] = 0.0  # ... with the elbow stretched and q6_ref 1 rad away: q234, q6 turn together,
    P_turn = forward(model, q_turn)  # which the one-pose solver leaves to the block solver
    ref_turn = q_turn[:, 5] - 1.0
    idx = range(poses)
    target = f"<= {TARGET_US:.0f}"
    out = []

    def row(what: str, t: np.ndarray, base: np.ndarray, goal: str = "") -> None:
        med, ref = float(np.median(t)), float(np.median(base))
        out.append([what, f"{med:.1f}", f"{t.max():.1f}", f"{ref:.1f}", f"{ref / med:.1f}x", goal])

    base_inv = _per_item(lambda p: inverse_batch(model, p), P, repeat)
    row("inverse: all branches, one pose", _per_item(lambda p: inverse(model, p), P, repeat), base_inv, target)
    row("inverse_nearest: one pose", _per_item(lambda i: inverse_nearest(model, P[i], q_near[i]), idx, repeat),
        base_inv, target)
    base = _per_item(lambda p: inverse_batch(model, p, q6_ref=0.0), P_sing, repeat)
    t = _per_item(lambda i: inverse_nearest(model, P_sing[i], q_near[i]), idx, repeat)
    row("inverse_nearest at the wrist singularity (q5 = 0)", t, base, target)
    base = _per_item(lambda i: inverse_batch(model, P_turn[i], q6_ref=ref_turn[i]), idx, repeat)
    t = _per_item(lambda i: inverse(model, P_turn[i], q6_ref=ref_turn[i]), idx, repeat)
    row("inverse, q3 = q5 = 0, q6_ref off by 1 rad (block solver)", t, base)
    base = _per_item(lambda x: forward(model, x[None]), q, repeat)
    row("forward: one joint vector", _per_item(lambda x: forward(model, x), q, repeat), base)
    Pb = forward(model, rng.uniform(-np.pi, np.pi, (BATCH, 6)))
    t_batch = np.array([best_time(lambda: inverse_batch(model, Pb), repeat=3) / BATCH * 1e6])
    row(f"inverse_batch: per pose of {BATCH}", t_batch, base_inv)
    out[-1][1] = out[-1][2] = f"{t_batch[0]:.2f}"
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", default="ur5e")
    ap.add_argument("--poses", type=int, default=200, help="different poses per timing round")
    ap.add_argument("--repeat", type=int, default=15, help="calls per pose (the best one kept)")
    args = ap.parse_args()
    load = os.getloadavg()
    table = rows(args.model, args.poses, args.repeat)
    print(f"model {args.model}; load average before / after: {load[0]:.2f} / {os.getloadavg()[0]:.2f} "
          f"({os.cpu_count()} cpus)")
    print("baseline: the block solver on one pose (inverse_batch(model, pose)), forward on one row via the batch path")
    print_table(HEADERS, table)


if __name__ == "__main__":
    main()
