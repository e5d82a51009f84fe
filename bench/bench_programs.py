"""Benchmark: the whole NX job of ``../shared/data`` in program mode, as programs a controller takes (issue 29).

The job (every pass, a UR5e at the demo's part frame, the cut output standard 0; the CAM tolerance 0.01 mm) is
planned, its whole-job program made once in one piece and once cut into pieces of at most
``planner.export.MAX_PROGRAM_BYTES`` (:func:`planner.export.job_program_pieces`), and the pieces run one after the
other by the simulated controller's core in this process (the interpreter and motion model of ``SimController``,
without sockets; each piece loaded in the period after the one before ended, as fast as the core goes). The
baseline in the same run: the whole program, which the core refuses as a controller would (too large).

Printed: the program's size whole and in pieces (count, largest, smallest), the time to make them; then the run:
its duration against the planned one, the largest distance of the TCP (every 10th control period, 20 ms) from the
planned path (:func:`thinned`, :func:`subdivided`) over the whole job and within 1 s of job time around the seams,
the joint speed and the output bits at every seam (the arm must be at rest, the outputs off), the switches made
against the planned ones.

Run: ``python bench/bench_programs.py [--gotos N] [--save FOLDER]`` (N: the job's first N GOTO records only; default
the whole file: about 30 min of CPU on this machine; FOLDER: keep the planned job and the run's checked samples).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(ROOT))

from _common import print_table  # noqa: E402

NX = ROOT.parent / "shared" / "data" / "nx_clsf_variable_contour_ust_a2.cls"
EVERY = 10  # control periods between the checked TCP samples


#: Samples of the planned path between two kept ones, and the largest distance of a left-out sample from its chord,
#: m (see :func:`thinned`).
THIN, CHORD = 10, 5e-7


def thinned(x: np.ndarray, every: int = THIN, chord: float = CHORD) -> np.ndarray:
    """Indices of the samples ``x`` (n, 3) of a planned path to measure the TCP against: every ``every``-th and the
    last, and all of a stretch between two of those where a sample left out is more than ``chord`` (m) from their
    chord. (Every 10th alone cut the bend of pass 116 at line 4704, where the tool axis turns by 82 deg: a TCP on
    the path was measured 0.0125 mm from the chord, 0.0014 mm from the path at 500 Hz.)"""
    n = x.shape[0]
    ends = np.r_[np.arange(0, n - 1, every), n - 1] if n > 1 else np.zeros(1, np.int64)
    if ends.size < 2:
        return ends
    seg = np.minimum(np.arange(n) // every, ends.size - 2)  # the stretch of each sample
    a, b = x[ends[seg]], x[ends[seg + 1]]
    d = b - a
    lam = np.clip(np.einsum("ij,ij->i", x - a, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-300), 0.0, 1.0)
    off = np.linalg.norm(x - a - lam[:, None] * d, axis=1) > chord
    bent = np.zeros(ends.size - 1, bool)
    bent[seg[off]] = True
    return np.flatnonzero(np.isin(np.arange(n), ends) | bent[seg])


#: Longest segment of the planned polyline the TCP is measured against, m (see :func:`subdivided`).
SEGMENT = 1e-4


def subdivided(pp: np.ndarray, where: np.ndarray, longest: float = SEGMENT) -> tuple[np.ndarray, np.ndarray]:
    """The polyline ``pp`` (n, 3) with points added on its segments so that none is longer than ``longest`` (the same
    line; ``where`` (n, k) repeated for the added points). The distance search (drivers.geometry.PolylineIndex) looks
    at the segments of the 8 vertices nearest a point: on a rapid's 5 mm segments (every 10th sample at 250 mm/s)
    beside a pass's vertices 0.08 mm apart those 8 were all the pass's, and a TCP on the rapid was measured 0.46 mm
    from the path."""
    step = np.linalg.norm(np.diff(pp, axis=0), axis=1)
    n = np.maximum(1, np.ceil(step / longest).astype(np.int64))  # pieces per segment
    seg = np.repeat(np.arange(step.size), n)
    u = (np.arange(seg.size) - np.repeat(np.cumsum(n) - n, n)) / n[seg]
    out = np.concatenate((pp[seg] + u[:, None] * (pp[seg + 1] - pp[seg]), pp[-1:]))
    return out, np.concatenate((where[seg], where[-1:]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--gotos", type=int, default=0, help="only the file's first N GOTO records (0: the whole job)")
    ap.add_argument("--save", default="", help="folder to keep the planned job (job.job) and the run's checked samples "
                                             "(run.npz: time s, TCP m, distance m, pass and line) in, for a look after")
    args = ap.parse_args()
    if not NX.is_file():
        sys.exit(f"{NX} is not there (the shared data beside the repository)")
    from drivers.geometry import PolylineIndex
    from planner import PlanSettings, plan
    from planner.export import MAX_PROGRAM_BYTES, job_program, job_program_pieces, plan_job_program
    from planner.frontends.cli.main import DEMO_PART
    from planner.kinematics import forward
    from sim.core import Core
    from sim.io_state import IOState

    src = NX
    if args.gotos:
        from tests.test_whole_job_program import first_gotos

        src = Path("/tmp") / f"bench_programs_{args.gotos}.cls"
        src.write_text(first_gotos(NX.read_text(), args.gotos))
    part = DEMO_PART
    t0 = time.perf_counter()
    job = plan(src, PlanSettings(path="cam", part_frame=part, robot="ur5e", cut_output=("standard", 0)))
    t_plan = time.perf_counter() - t0
    t0 = time.perf_counter()
    moves = plan_job_program(job)
    t_moves = time.perf_counter() - t0
    t0 = time.perf_counter()
    whole = job_program(job, moves)
    t_whole = time.perf_counter() - t0
    t0 = time.perf_counter()
    pieces = job_program_pieces(job, moves)
    t_pieces = time.perf_counter() - t0
    sizes = [p.size for p in pieces]
    print(f"{src.name}: {len(job.passes)} passes, planned {job.duration:.1f} s ({t_plan:.0f} s to plan, "
          f"{t_moves:.0f} s for the movep targets)\n")
    print_table(["program", "programs", "bytes (largest)", "bytes (smallest)", "bytes in all", "limit", "make s"], [
        ["whole (baseline)", 1, len(whole.encode()), len(whole.encode()), len(whole.encode()), "-", f"{t_whole:.1f}"],
        ["pieces", len(pieces), max(sizes), min(sizes), sum(sizes), MAX_PROGRAM_BYTES, f"{t_pieces:.1f}"],
    ])

    # the planned path, every 10th sample and every sample where such a chord leaves the path by more than CHORD
    # (thinned), and its output switches: read a move at a time (the whole path at 500 Hz would not fit in this
    # machine's memory with its search tree)
    keep, where, n_switch, last_io, duration = [], [], 0, None, 0.0
    for c in job.trajectory().chunks(joints=False):
        if not len(c):
            continue
        k = thinned(c.poses[:, :3])
        keep.append(c.poses[k, :3])
        where.append(np.column_stack([np.full(k.size, c.pass_index), np.asarray(c.lines)[k]]))
        io = np.asarray(c.io)
        n_switch += int(np.count_nonzero(np.diff(io))) + int(last_io is not None and io[0] != last_io)
        last_io = io[-1]
        duration = float(c.times[-1])
    pp, where_pp = subdivided(np.concatenate(keep), np.concatenate(where))
    core = Core("ur5e", IOState())
    core.motion.q = np.array(job.start_joints, dtype=float)
    refused = not core.load_program(whole)
    qs, ts, switches, seams = [], [], [], []
    out = core.io.digital_out
    stopped = "no"
    t0 = time.perf_counter()
    for n, piece in enumerate(pieces):
        if n:
            seams.append((core.time, float(np.abs(core.motion.qd).max()), core.io.digital_out))
        if not core.load_program(piece.text):  # a stop in the piece before: reported with where it was
            prev = pieces[n - 1]
            stopped = (f"program {n} of {len(pieces)} (passes {prev.passes[0]}-{prev.passes[-1]}, from line "
                       f"{prev.line}) at t = {core.time:.1f} s: "
                       + "; ".join(m[2] for m in core.log if m[1] == "Safety")[:200])
            break
        while core.program is not None:
            core.tick()
            if core.steps % EVERY == 0:
                qs.append(core.motion.q)
                ts.append(core.time)
            if core.io.digital_out != out:
                out = core.io.digital_out
                switches.append(out)
    t_run = time.perf_counter() - t0
    tcp = forward("ur5e", np.array(qs))[:, :3]
    d, seg = PolylineIndex(pp).distance(tcp)
    worst = int(np.argmax(d))
    w_pass, w_line = (int(x) for x in where_pp[min(int(seg[worst]), len(where_pp) - 1)])
    slowed = [m.slowed for m in moves if m.slowed]
    t = np.array(ts)
    near = np.zeros(t.size, dtype=bool)
    for ts_seam, _, _ in seams:
        near |= np.abs(t - ts_seam) <= 1.0
    if args.save:
        folder = Path(args.save)
        folder.mkdir(parents=True, exist_ok=True)
        job.save(folder / "job.job")
        np.savez(folder / "run.npz", t=t, tcp=tcp, d=d, where=where_pp[np.minimum(seg, len(where_pp) - 1)],
                 seams=np.array([s[0] for s in seams]))
    print()
    print_table(["run in the core", "value"], [
        ["whole program refused (too large)", refused],
        ["duration s (planned)", f"{core.time:.1f} ({duration:.1f})"],
        ["largest path error mm (tolerance 0.01)", f"{1e3 * d.max():.4f}"],
        ["  where (job time s, pass, source line)", f"{ts[worst]:.2f}, {w_pass}, {w_line}"],
        ["largest path error within 1 s of a seam mm", f"{1e3 * d[near].max():.4f}" if near.any() else "-"],
        ["seams", len(seams)],
        ["largest joint speed at a seam rad/s", f"{max((s[1] for s in seams), default=0.0):.2e}"],
        ["output bits at the seams", sorted({s[2] for s in seams})],
        ["switches made (planned)", f"{len(switches)} ({n_switch})"],
        ["protective stops", sum(1 for m in core.log if m[1] == "Safety")],
        ["run stopped", stopped],
        ["core wall time s", f"{t_run:.0f}"],
        ["moves slowed for the joint limits", len(slowed)],
    ])
    for x in slowed[:20]:
        print("  slowed:", x)


if __name__ == "__main__":
    main()
