"""Benchmark: the 500 Hz servoJ streaming loop of :class:`drivers.ur.URDriver` through real ur_rtde against the
simulated controller.

The demo job (the first pass of the real NX file, placed for a UR5e as ``planner demo`` places it; about
62 s of motion) is executed by ``URDriver.execute(job, mode="stream")`` itself: the approach onto the start
joints, then one ``servoJ`` with the planner's joints per 2 ms sample, paced on the absolute schedule
t0 + k * 2 ms (:class:`drivers.pacing.Schedule`: sleep to 0.3 ms before the deadline, then spin), with the
targets produced ahead by the driver's feed thread and the RTDE receive reads the driver makes every period;
``--seconds`` streams only the job's first seconds (the run is then cancelled there). The simulated controller (a
:class:`sim.SimController` child process) records what it executed. Reported:

* period: the driver's own figures (``report.loop``): wall time between the starts of consecutive loop
  iterations, p50, p99, max, ``|p99 - 2 ms|`` (target: within 0.5 ms) and the loop's mean rate (Hz);
* missed periods: loop iterations that started a whole period or more late (counted in periods), and on the
  controller's side the control periods in which no new target had arrived (the recording's commanded joints
  repeat) and the targets it never executed (two arrived within one period), and the periods the controller's
  own loop skipped (late ticks); target: not one;
* tracking: the controller's actual joints against the commanded ones (largest, rad, and against the motion
  model's servo following-error bound), and the report's largest distance of the actual TCP from the planned path;
* CPU: this client process (the approach included) and the simulator process, each as a share of one core;
* machine stalls: periods a SCHED_FIFO probe thread in this process, on the same absolute 2 ms schedule, woke
  more than a period late (a shared virtual machine stalls now and then; no loop can do better).

Baseline, in the same run: a plain Python loop sleeping to the same absolute 2 ms schedule with no client and
no controller (what the machine and the measurement give by themselves); the last column is its p99 over the
stream's.

The client's threads run SCHED_FIFO where the system allows it (as ur_rtde does on a real-time kernel; the
simulator's control loop above them); ``--no-realtime`` leaves them at normal priority.

Run: python bench/bench_streaming.py [--seconds 60] [--no-realtime]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import print_table  # noqa: E402
from bench_sim import StallProbe, _cpu_seconds, _free_hosts, _normal_threads, _realtime_threads  # noqa: E402

PERIOD = 0.002
LOOKAHEAD, GAIN = 0.1, 300.0


def demo_job():
    from planner import PlanSettings, plan
    from planner.frontends.cli.main import DEMO_PART_FRAME, EXAMPLE_CLS, example_path

    part = tuple(float(x) for x in DEMO_PART_FRAME.split(","))
    return plan(example_path(EXAMPLE_CLS), PlanSettings(robot="ur5e", part_frame=part, cut_output=("tool", 0)))


def _period_stats(starts: np.ndarray) -> dict:
    d = np.diff(starts) * 1e3
    missed = int(np.clip(np.floor(d / (PERIOD * 1e3) + 1e-9) - 1, 0, None).sum())
    return {"rate": float(1e3 / d.mean()),
            "p50": float(np.percentile(d, 50)), "p99": float(np.percentile(d, 99)), "max": float(d.max()),
            "missed": missed, "n": int(d.size)}


def run_stream(job, seconds: float, realtime: bool) -> dict:
    import threading

    from drivers.ur import URDriver
    from sim import SimController, recording
    from sim.motion import servo_following_error

    Q = np.concatenate([c.joints for c in job.trajectory().chunks()])
    n = min(len(Q), int(round(seconds / PERIOD)))
    cut = n < len(Q)
    Q = Q[:n]
    cancel = threading.Event()

    def progress(stage, done, total):
        if done >= n - 1 and cut:
            cancel.set()  # --seconds: the job's first seconds only

    with tempfile.TemporaryDirectory(prefix="bench-stream-") as tmp:
        rec_path = Path(tmp) / "stream.npz"
        sim = SimController(_free_hosts(1)[0], modbus_port=None, record=rec_path)
        sim.start()
        try:
            with URDriver(sim.host, "ur5e", lookahead=LOOKAHEAD, gain=GAIN) as d:
                if realtime:
                    _realtime_threads()
                late0 = sim.state()["late_ticks"]
                try:
                    cpu_sim0, cpu0, w0 = _cpu_seconds(sim.proc.pid), time.process_time(), time.perf_counter()
                    with StallProbe() as probe:
                        rep = d.execute(job, mode="stream", progress=progress, cancel=cancel)
                    wall = time.perf_counter() - w0
                    cpu_client = (time.process_time() - cpu0) / wall
                    cpu_sim = (_cpu_seconds(sim.proc.pid) - cpu_sim0) / wall
                finally:
                    _normal_threads()
                late = sim.state()["late_ticks"] - late0
        finally:
            sim.stop()
        rec = recording.load(rec_path)
    if rep.failure is not None and not (cut and cancel.is_set()):
        raise RuntimeError(f"the stream failed: {rep.failure}")
    loop = rep.loop
    out = {"rate": loop.rate, "p50": 1e3 * loop.p50, "p99": 1e3 * loop.p99, "max": 1e3 * loop.max,
           "missed": loop.missed, "n": loop.n}
    # the controller's side: each control period's commanded joints, matched to the sample sent
    index = {q.tobytes(): k for k, q in enumerate(Q)}
    ks = np.array([index.get(q.tobytes(), -1) for q in rec.target_q])
    rows = np.flatnonzero(ks >= 0)
    rows = rows[rows >= np.flatnonzero(ks == 1)[0]]
    last = np.flatnonzero(ks[rows] == ks[rows].max())[0]
    rows = rows[: last + 1]
    # a period in which the target did not advance while the stream went on: a command that came late
    stalled = int(np.count_nonzero(np.diff(ks[rows]) == 0))
    skipped = int(np.clip(np.diff(ks[rows]) - 1, 0, None).sum())
    err = np.abs(rec.actual_q[rows] - Q[ks[rows]]).max()
    v = float(np.abs(np.diff(Q, axis=0)).max() / PERIOD)
    bound = servo_following_error(v, LOOKAHEAD, GAIN)
    out.update(stalled=stalled, skipped=skipped, late=late, stalls=probe.late, cpu_client=100 * cpu_client,
               cpu_sim=100 * cpu_sim, joint_err=float(err), bound=bound, path_mm=rep.max_path_error * 1e3)
    return out


def run_baseline(seconds: float, realtime: bool) -> dict:
    """A plain Python loop sleeping to the absolute 2 ms schedule (no client, no controller)."""
    n = int(round(seconds / PERIOD))
    starts = np.empty(n)
    if realtime:
        _realtime_threads()
    try:
        t0 = time.perf_counter()
        for k in range(n):
            due = t0 + k * PERIOD
            delay = due - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            starts[k] = time.perf_counter()
    finally:
        _normal_threads()
    return _period_stats(starts)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="seconds of the demo job to stream (default 60)")
    ap.add_argument("--no-realtime", action="store_true", help="leave the client's threads at normal priority")
    args = ap.parse_args(argv)
    if not args.seconds > 0:
        ap.error(f"--seconds must be > 0, got {args.seconds}")
    realtime = not args.no_realtime
    job = demo_job()
    base = run_baseline(min(args.seconds, 10.0), realtime)
    r = run_stream(job, args.seconds, realtime)
    jitter = abs(r["p99"] - PERIOD * 1e3)
    ok = jitter <= 0.5 and r["missed"] == 0  # the target: the loop's p99 and its missed periods
    print(f"URDriver's servoJ stream of the demo job through ur_rtde into the simulated controller: {r['n'] + 1} "
          f"periods ({(r['n'] + 1) * PERIOD:.1f} s), {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}, "
          f"client threads {'SCHED_FIFO' if realtime else 'normal priority'}")
    print_table(["loop", "rate Hz", "period p50 ms", "p99 ms", "max ms", "|p99 - 2| ms", "missed periods (client)",
                 "targets late / lost (controller)", "late ticks (sim)", "machine stalls (periods)",
                 "CPU % client / sim", "target met", "baseline p99 / p99"],
                [["URDriver stream", f"{r['rate']:.2f}",
                  f"{r['p50']:.3f}", f"{r['p99']:.3f}", f"{r['max']:.3f}", f"{jitter:.3f}",
                  r["missed"], f"{r['stalled']} / {r['skipped']}", r["late"], r["stalls"],
                  f"{r['cpu_client']:.1f} / {r['cpu_sim']:.1f}", "yes" if ok else "NO",
                  f"{base['p99'] / r['p99']:.2f}"],
                 ["baseline: sleep to schedule", f"{base['rate']:.2f}",
                  f"{base['p50']:.3f}", f"{base['p99']:.3f}", f"{base['max']:.3f}",
                  f"{abs(base['p99'] - 2.0):.3f}", base["missed"], "", "", "", "", "", "1.00"]])
    print()
    print("Tracking (the controller's recording)")
    print_table(["figure", "value"], [
        ["largest |actual - commanded| joint, rad", f"{r['joint_err']:.2e}"],
        ["servo following-error bound, rad", f"{r['bound']:.2e}"],
        ["ratio", f"{r['joint_err'] / r['bound']:.2f}"],
        ["actual TCP's largest distance from the planned path, mm", f"{r['path_mm']:.4f}"],
    ])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
