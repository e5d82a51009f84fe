"""Benchmark: the simulated UR controller's 500 Hz data stream as ur_rtde's RTDEReceiveInterface sees it.

For 1 and for 4 simulators running at once (each its own child process on 127.x.x.x), one
``rtde_receive.RTDEReceiveInterface`` per simulator (500 Hz, ur_rtde's default recipe of ~56
variables) is polled every 0.1 ms by this process for ``--seconds``. Reported per configuration:

* period: the wall time between the first sightings of consecutive new timestamps (ms): p50, p99,
  max; ``|p99 - 2 ms|`` is the jitter figure (target: within 0.5 ms of 2 ms);
* missed: data packages lost on the way (timestamp steps of more than one 2 ms period, counted in
  periods) as the client saw them, and the periods the simulator's loop itself skipped (late ticks);
* CPU: each simulator process's CPU time over the run, as a share of one core (mean over simulators), with
  all its interfaces connected;
* machine stalls: the periods a SCHED_FIFO probe thread in this process, on the same absolute 2 ms
  schedule, woke more than one period late (a shared virtual machine stalls now and then; the
  simulators cannot do better than that).

Every simulator has all its interfaces connected meanwhile: besides the RTDE receiver, one client on the primary
interface (30001), one on the secondary (30002) and one on the real-time interface (30003), read by one thread of
this process. A second table gives the period of their state packages as those clients see them (p50, p99, max;
targets 100 ms for the 10 Hz robot state packages, 2 ms for the 500 Hz real-time ones) and the bytes per second each
simulator sends them.

The simulator's control loop runs SCHED_FIFO where the system allows it; this process's threads
(the poller and ur_rtde's receive threads) too, as ur_rtde sets itself on a real-time kernel
(``--no-realtime`` leaves them at normal priority: on a loaded machine the client then misses packages
that the simulator sent on time).

The baseline (in the same run): the same poller on a plain Python thread that sets a timestamp every
2 ms by ``time.sleep`` of one period after each step (the drifting schedule the simulator avoids),
i.e. what the measurement itself adds on this machine. ``rows()`` of bench/bench_ik.py (one-pose IK for
the 2 ms loop) is printed too when present.

A second table: the CPU time per 2 ms control period of the simulator's core running the planner's
exported whole-job program (the demo job's ``job_program``: the URScript interpreter, the motion model,
the controller's period bookkeeping; in-process, no sockets), against an idle core (no program) measured
in the same run. It bounds how fast a program runs in fast-forward: ``2 ms / (us per period)`` times
real time on one core (tests/test_whole_job_program.py runs an hour of motion at 150x).

Run: python bench/bench_sim.py [--seconds 60] [--program-only] [--no-state-clients]
"""

from __future__ import annotations

import argparse
import os
import selectors
import socket
import struct
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import print_table  # noqa: E402

from sim import SimController  # noqa: E402

PERIOD = 0.002
REALTIME = True
STATE_CLIENTS = True  # a primary, a secondary and a real-time interface client per simulator during the RTDE run
STATE_PORTS = (30001, 30002, 30003)


def _free_hosts(n: int) -> list[str]:
    import random
    import socket

    rng = random.Random()
    hosts: list[str] = []
    while len(hosts) < n:
        host = f"127.{rng.randint(100, 250)}.{rng.randint(0, 255)}.{rng.randint(2, 254)}"
        try:
            with socket.socket() as s:
                s.bind((host, 30004))
        except OSError:
            continue
        hosts.append(host)
    return hosts


def _cpu_seconds(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _realtime_threads(priority: int = 3) -> bool:
    """SCHED_FIFO for every thread of this process (ur_rtde's receive threads included), as ur_rtde
    does itself on a real-time kernel, below the simulators' control loops (a real controller is
    another machine, which its clients cannot delay); False if the system refuses."""
    ok = True
    for tid in os.listdir("/proc/self/task"):
        try:
            os.sched_setscheduler(int(tid), os.SCHED_FIFO, os.sched_param(priority))
        except (OSError, AttributeError):
            ok = False
    return ok


def _normal_threads() -> None:
    for tid in os.listdir("/proc/self/task"):
        try:
            os.sched_setscheduler(int(tid), os.SCHED_OTHER, os.sched_param(0))
        except (OSError, AttributeError):
            pass


def _poll(getters, seconds: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """First-seen wall times and values of new timestamps, per getter."""
    seen_t = [[] for _ in getters]
    seen_v = [[] for _ in getters]
    last = [None] * len(getters)
    end = time.perf_counter() + seconds
    while True:
        now = time.perf_counter()
        if now > end:
            break
        for i, g in enumerate(getters):
            v = g()
            if v != last[i]:
                last[i] = v
                seen_t[i].append(now)
                seen_v[i].append(v)
        time.sleep(0.0001)
    return [(np.array(t), np.array(v)) for t, v in zip(seen_t, seen_v, strict=True)]


def _stats(series) -> dict:
    periods, missed = [], 0
    for t, v in series:
        if len(t) < 3:
            continue
        periods.append(np.diff(t[1:]))
        steps = np.round(np.diff(v[1:]) / PERIOD).astype(int)
        missed += int(np.clip(steps - 1, 0, None).sum())
    p = np.concatenate(periods) * 1e3 if periods else np.array([np.nan])
    return {"p50": float(np.percentile(p, 50)), "p99": float(np.percentile(p, 99)), "max": float(p.max()),
            "missed": missed, "n": int(sum(len(t) for t, _ in series))}


class StallProbe:
    """A SCHED_FIFO thread on the simulators' absolute 2 ms schedule in this process: the periods it
    wakes more than a period late are the machine's own stalls (what any process would lose)."""

    def __init__(self) -> None:
        self.late = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
        except (OSError, AttributeError):
            pass
        t0, k = time.perf_counter(), 0
        while not self._stop.is_set():
            k += 1
            delay = t0 + k * PERIOD - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            behind = int((time.perf_counter() - t0) / PERIOD) - k
            if behind > 0:
                self.late += behind
                k += behind

    def __enter__(self) -> StallProbe:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


class StateReader:
    """Clients of the primary, secondary and real-time interfaces of some simulators, read by one thread: the arrival
    times (perf_counter) of each client's state packages (robot state, real-time), and the bytes received."""

    def __init__(self, hosts: list[str]) -> None:
        self.ports = [port for _ in hosts for port in STATE_PORTS]
        self.socks = [socket.create_connection((h, port), timeout=5) for h, port in zip(
            [h for h in hosts for _ in STATE_PORTS], self.ports, strict=True)]
        self.arrivals: list[list[float]] = [[] for _ in self.socks]
        self.bytes = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        sel = selectors.DefaultSelector()
        bufs = [bytearray() for _ in self.socks]
        for i, s in enumerate(self.socks):
            s.setblocking(False)
            sel.register(s, selectors.EVENT_READ, i)
        while not self._stop.is_set():
            for key, _ in sel.select(0.05):
                i = key.data
                try:
                    chunk = self.socks[i].recv(65536)
                except BlockingIOError:
                    continue
                now = time.perf_counter()
                self.bytes += len(chunk)
                buf = bufs[i]
                buf += chunk
                while len(buf) >= 5 and len(buf) >= struct.unpack_from(">i", buf)[0]:
                    size, kind = struct.unpack_from(">iB", buf)
                    if kind == 16 or self.ports[i] == 30003:  # a robot state package; every real-time one
                        self.arrivals[i].append(now)
                    del buf[:size]

    def periods(self, port: int, start: float, end: float) -> np.ndarray:
        """Periods (ms) between consecutive state packages received within [start, end] by the clients on ``port``."""
        out = []
        for p, t in zip(self.ports, self.arrivals, strict=True):
            if p == port:
                t = np.array(t)
                out.append(np.diff(t[(t >= start) & (t <= end)]) * 1e3)
        return np.concatenate(out) if out else np.array([np.nan])

    def __enter__(self) -> StateReader:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        for s in self.socks:
            s.close()


def run_sims(n: int, seconds: float) -> dict:
    import rtde_receive

    sims = [SimController(h, modbus_port=None) for h in _free_hosts(n)]
    receivers = []
    try:
        for s in sims:
            s.start()
        receivers = [rtde_receive.RTDEReceiveInterface(s.host) for s in sims]
        with StateReader([s.host for s in sims] if STATE_CLIENTS else []) as reader:
            if REALTIME:
                _realtime_threads()
            time.sleep(0.5)
            late0 = [s.state()["late_ticks"] for s in sims]
            cpu0 = [_cpu_seconds(s.proc.pid) for s in sims]
            w0 = time.perf_counter()
            bytes0 = reader.bytes
            with StallProbe() as probe:
                series = _poll([r.getTimestamp for r in receivers], seconds)
            wall = time.perf_counter() - w0
            sent = (reader.bytes - bytes0) / wall / n
            cpu = [(_cpu_seconds(s.proc.pid) - c) / wall for s, c in zip(sims, cpu0, strict=True)]
            late = sum(s.state()["late_ticks"] - l0 for s, l0 in zip(sims, late0, strict=True))
    finally:
        _normal_threads()
        for r in receivers:
            r.disconnect()
        for s in sims:
            s.stop()
    out = _stats(series)
    out.update(late=late, cpu=100.0 * float(np.mean(cpu)), stalls=probe.late, state_bytes=sent,
               primary=reader.periods(30001, w0, w0 + wall), secondary=reader.periods(30002, w0, w0 + wall),
               realtime=reader.periods(30003, w0, w0 + wall))
    return out


def run_baseline(seconds: float) -> dict:
    """The poller on a Python thread stepping a timestamp by sleeping one period after each step."""
    state = {"t": 0.0}
    stop = threading.Event()

    def ticker():
        while not stop.is_set():
            time.sleep(PERIOD)
            state["t"] = round(state["t"] + PERIOD, 9)

    th = threading.Thread(target=ticker, daemon=True)
    th.start()
    if REALTIME:
        _realtime_threads()
    try:
        series = _poll([lambda: state["t"]], seconds)
    finally:
        _normal_threads()
        stop.set()
        th.join()
    out = _stats(series)
    out.update(late=0, cpu=float("nan"), stalls="")
    return out


def _core_cpu_per_period(text: str | None, periods: int) -> tuple[float, int]:
    """CPU seconds per control period of a fresh Core running ``text`` (None: idle) for up to ``periods``."""
    from sim.core import Core
    from sim.io_state import IOState

    core = Core("ur5e", IOState())
    if text is not None and not core.load_program(text):
        raise RuntimeError(f"the simulator refused the program: {list(core.log)[-1:]}")
    t0 = time.process_time()
    n = 0
    while n < periods and (text is None or core.program is not None):
        core.tick()
        n += 1
    cpu = time.process_time() - t0
    if core.safety_mode != 1:
        raise RuntimeError(f"protective stop while running the program: {list(core.log)[-1:]}")
    return cpu / max(n, 1), n


def run_program() -> list[list[object]]:
    """Rows of the program table: the demo job's whole-job program against an idle core."""
    from planner import PlanSettings, plan
    from planner.export import job_program

    repo = Path(__file__).resolve().parents[1]
    job = plan(repo / "examples" / "nx_first_pass.cls",
               PlanSettings(robot="ur5e", part_frame=(0.4, 0.9965, -0.1, 0.0, 0.0, 0.0), cut_output=("standard", 0)))
    text = job_program(job)
    per, n = _core_cpu_per_period(text, 10**7)
    idle, _ = _core_cpu_per_period(None, 20000)
    return [[f"demo job program ({text.count(chr(10))} lines, {n * PERIOD:.0f} s of motion)", f"{per * 1e6:.1f}",
             f"{PERIOD / per:.0f}", f"{per / idle:.2f}"],
            ["baseline: idle core (no program)", f"{idle * 1e6:.1f}", f"{PERIOD / idle:.0f}", "1.00"]]


PROGRAM_HEADERS = ["core running", "CPU us per 2 ms period", "x real time (one core)", "ratio to idle"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="measurement time per configuration (s)")
    ap.add_argument("--no-realtime", action="store_true",
                    help="leave this process's threads (poller, ur_rtde's receive threads) at normal priority")
    ap.add_argument("--program-only", action="store_true", help="only the program table (no RTDE measurement)")
    ap.add_argument("--no-state-clients", action="store_true",
                    help="no primary / secondary / real-time clients during the RTDE measurement (RTDE alone)")
    args = ap.parse_args(argv)
    if args.program_only:
        print("The simulator's core running the planner's whole-job program (in-process)")
        print_table(PROGRAM_HEADERS, run_program())
        return 0
    global REALTIME, STATE_CLIENTS
    REALTIME = not args.no_realtime
    STATE_CLIENTS = not args.no_state_clients
    rows = []
    base = run_baseline(min(args.seconds, 10.0))
    results = []
    for n in (1, 4):
        r = run_sims(n, args.seconds)
        results.append((n, r))
        jitter = abs(r["p99"] - PERIOD * 1e3)
        rows.append([f"{n} simulator{'s' if n > 1 else ''}", f"{r['p50']:.3f}", f"{r['p99']:.3f}",
                     f"{r['max']:.3f}", f"{jitter:.3f}", "yes" if jitter <= 0.5 else "NO", r["missed"], r["late"],
                     r["stalls"], f"{r['cpu']:.1f}", f"{base['p99'] / r['p99']:.2f}"])
    rows.append(["baseline: sleep(2 ms) loop", f"{base['p50']:.3f}", f"{base['p99']:.3f}", f"{base['max']:.3f}",
                 f"{abs(base['p99'] - 2.0):.3f}", "", base["missed"], "", "", "", "1.00"])
    state_rows = [[f"{n} simulator{'s' if n > 1 else ''}", name, len(p), f"{np.percentile(p, 50):.1f}",
                   f"{np.percentile(p, 99):.1f}", f"{p.max():.1f}", f"{r['state_bytes'] / 1e3:.1f}"]
                  for n, r in results if STATE_CLIENTS
                  for name, p in (("primary 30001", r["primary"]), ("secondary 30002", r["secondary"]),
                                  ("real-time 30003", r["realtime"]))]
    print(f"RTDE data packages seen by RTDEReceiveInterface, {args.seconds:g} s per configuration, "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}, client threads "
          f"{'SCHED_FIFO' if REALTIME else 'normal priority'}, "
          f"{'primary, secondary and real-time clients connected' if STATE_CLIENTS else 'RTDE alone'}")
    print_table(["configuration", "period p50 ms", "p99 ms", "max ms", "|p99 - 2| ms", "<= 0.5 ms",
                 "missed (client)", "late ticks (sim)", "machine stalls (periods)", "CPU % per sim",
                 "baseline p99 / p99"], rows)
    if state_rows:
        print()
        print("State packages of the primary and secondary (10 Hz) and real-time (500 Hz) interfaces seen by their "
              "clients, same runs")
        print_table(["configuration", "interface", "periods", "p50 ms", "p99 ms", "max ms", "kB/s per sim (all three)"],
                    state_rows)
    print()
    print("The simulator's core running the planner's whole-job program (in-process)")
    print_table(PROGRAM_HEADERS, run_program())
    try:
        import bench_ik
    except ImportError:
        return 0
    print()
    print("One-pose kinematics for the 2 ms loop (bench/bench_ik.py)")
    print_table(bench_ik.HEADERS, bench_ik.rows())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
