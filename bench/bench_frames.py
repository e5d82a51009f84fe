"""Benchmark: tool-frame methods on one path, timed and measured against the exact RMF.

Table 1: a C2 PH quintic spline through 1000 waypoints (a wavy helix, bench_paths.waypoints), sampled at
10^5 points equally spaced in arc length. For each method: build and evaluation time and the largest
twist (degrees) against the exact RMF from the same start frame:
  exact RMF (ours), GRM (ours, per-segment rational), Jüttler's rational RMM (on the G1 PH cubic spline
  through the same waypoints, against that spline's exact RMF), double reflection at 10^3, 10^4,
  10^5 samples, Frenet frames and slerp between the end frames (what common toolboxes do).
Table 2: the GRM seed example (Peng, Pang, Pan 2023; A0=(0,1,0,2), A1=(0,2,1,-1), A2=(0,3,-2,-1)): every
weight side by side with the paper's printed solutions: objective, residual of eq. (24), max twist.

Table 3: the rotation conversions of planner.rotations at 10^5 random rotations, against the route they
replace or the one they avoid, timed in the same run (best of 5): scipy-based functions against the
hand-written formulas the planner had before (Shepperd's method, the unit-quaternion matrix), and the
two documented hand-written exceptions (quaternion -> UR rotation vector keeping the sign, angle between
rotations) against the scipy route with its largest difference.

Table 4: the float path of the kinematics (planner.rotations' *_1 on Python floats and their numpy twins *_n,
identical results) against scipy: one rotation per call (us) and 10^5 at once (ms), with the largest difference.
It is kept where one pose and a batch holding it must give the same joints bit for bit (forward and inverse
kinematics); everything else converts through scipy.

Targets (issue 3): exact RMF at 10^5 samples within 2x of double reflection's time; GRM median under
10 ms per segment; GRM on the seed example satisfies (24) below 1e-9 with a twist no worse than the
paper's.

Run: python bench/bench_frames.py [--waypoints 1000] [--samples 100000] [--rotations-only]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import best_time, print_table  # noqa: E402
from bench_paths import waypoints  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from planner import rotations  # noqa: E402
from planner.curves import PHQuintic, fit_ph_cubic_spline, fit_ph_spline  # noqa: E402
from planner.frames import (  # noqa: E402
    double_reflection_frames,
    frame_field,
    frenet_frames,
    grm,
    grm_from_coefficients,
    max_twist_deg,
    ph_cubic_spline_rmm,
    slerp_frames,
    twist_angles,
)


def timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def path_table(n_way: int, n_samples: int) -> None:
    p = waypoints(n_way)
    path = fit_ph_spline(p)
    s = np.linspace(0.0, path.length, n_samples)
    u = path.parameter_at_length(s)
    rows = []

    rmf, t_build = timed(lambda: frame_field(path, "rmf"))
    ref, t_eval = timed(lambda: rmf.frames(u))
    rows.append(["exact RMF (ours)", n_samples, f"{t_build * 1e3:.1f}", f"{t_eval * 1e3:.1f}", "0 (reference)"])
    t_rmf = t_eval

    g, t_build = timed(lambda: frame_field(path, "grm"))
    F, t_eval = timed(lambda: g.frames(u))
    per_seg = np.array([x.seconds for x in g.grm_frames]) * 1e3
    rows.append([f"GRM twist weight (median {np.median(per_seg):.1f} ms/segment)", n_samples, f"{t_build * 1e3:.0f}",
                 f"{t_eval * 1e3:.1f}", f"{max_twist_deg(F, ref):.3g}"])

    cubic = fit_ph_cubic_spline(p)
    uc = cubic.parameter_at_length(np.linspace(0.0, cubic.length, n_samples))
    cref = frame_field(cubic, "rmf")
    start = cref.frames(uc[:1])[0]
    hod = np.diff(cubic.control_points, axis=1) * 3.0  # quadratic hodograph control vectors (m, 3, 3)
    motion, t_build = timed(lambda: ph_cubic_spline_rmm(hod, cubic.knots, start))
    F, t_eval = timed(lambda: motion.frames(uc))
    rows.append([f"Jüttler rational RMM ({cubic.n_segments} PH cubics)", n_samples, f"{t_build * 1e3:.1f}",
                 f"{t_eval * 1e3:.1f}", f"{max_twist_deg(F, cref.frames(uc)):.3g}"])

    t_dr = None
    for n in (1_000, 10_000, n_samples):
        un = path.parameter_at_length(np.linspace(0.0, path.length, n))
        pts, tan = path.points(un), path.tangent(un)
        R = ref if n == n_samples else rmf.frames(un)
        D, t = timed(lambda pts=pts, tan=tan, R=R: double_reflection_frames(pts, tan, R[0]))
        if n == n_samples:
            t_dr = t
        rows.append([f"double reflection, {n} samples", n, "-", f"{t * 1e3:.1f}", f"{max_twist_deg(D, R):.3g}"])

    F, t = timed(lambda: frenet_frames(path.derivative(u), path.derivative(u, 2)))
    tw = twist_angles(F, ref)
    turns = np.unwrap(tw)
    worst = np.degrees(np.abs(np.angle(np.exp(1j * (tw - tw[0])))).max())
    rows.append([f"Frenet frames (start aligned; {abs(turns[-1] - turns[0]) / (2 * np.pi):.1f} turns of spin)",
                 n_samples, "-", f"{t * 1e3:.1f}", f"{worst:.3g}"])
    F, t = timed(lambda: slerp_frames(ref[0], ref[-1], s / path.length))
    rows.append(["slerp between end frames", n_samples, "-", f"{t * 1e3:.1f}", f"{max_twist_deg(F, ref):.3g}"])

    print(f"Path: C2 PH quintic spline through {n_way} waypoints, length {path.length:.4f} m, "
          f"{n_samples} samples; max twist against the exact RMF from the same start frame")
    print_table(["method", "samples", "build ms", "eval ms", "max twist deg"], rows)
    print(f"exact RMF / double reflection time at {n_samples} samples: {t_rmf / t_dr:.2f}x (target <= 2x)")
    print(f"GRM per segment: median {np.median(per_seg):.2f} ms, max {per_seg.max():.1f} ms (target median < 10 ms)")
    seg_twist = np.array([x.max_twist_deg for x in g.grm_frames])
    seg_resid = np.array([x.constraint_residual for x in g.grm_frames])
    print(f"GRM per segment vs exact RMF: max twist worst {seg_twist.max():.3g} deg, "
          f"median {np.median(seg_twist):.3g} deg; residual of (24) max {seg_resid.max():.1e}")
    print()


PAPER = {
    "paper printed, rho=1": ([6.5789, 3.1495, -2.1811, 15.3863, 17.1115],
                             [-0.8943, 1.0685, -0.6119, 1.1118, 3.9292], "1"),
    "paper printed, rho=|tau kappa|": ([9.8125, 1.1353, -1.1893, 15.1672, 9.1231],
                                       [-1.4645, 0.8832, -0.4792, -0.0104, 2.7759], "tau_kappa"),
}


def seed_table() -> None:
    c = PHQuintic.from_quaternions((0, 1, 0, 2), (0, 2, 1, -1), (0, 3, -2, -1))
    rows = []
    for w in ("twist", "1", "sigma", "tau_kappa"):
        r = grm(c, w)
        rows.append([f"ours, weight={w}", f"{r.objective:.5g}", f"{r.constraint_residual:.1e}",
                     f"{r.max_twist_deg:.4f}", f"{r.seconds * 1e3:.1f}"])
    for name, (a, b, _weight) in PAPER.items():
        r = grm_from_coefficients(c, a, b)
        rows.append([name, "-", f"{r.constraint_residual:.1e}", f"{r.max_twist_deg:.4f}", "-"])
    print(f"GRM on the seed example (arc length {c.length:.15f} = 17/3): a^2+b^2 ~ 2 sigma^2 per weight")
    print_table(["solution", "objective", "residual of (24)", "max twist deg", "ms"], rows)


def _shepperd(R: np.ndarray) -> np.ndarray:
    """The hand-written matrix -> quaternion the planner used before planner.rotations (baseline)."""
    r00, r01, r02 = R[:, 0, 0], R[:, 0, 1], R[:, 0, 2]
    r10, r11, r12 = R[:, 1, 0], R[:, 1, 1], R[:, 1, 2]
    r20, r21, r22 = R[:, 2, 0], R[:, 2, 1], R[:, 2, 2]
    tr = r00 + r11 + r22
    case = np.argmax(np.stack((tr, r00, r11, r22), axis=1), axis=1)
    d21, d02, d10 = r21 - r12, r02 - r20, r10 - r01
    s01, s02, s12 = r01 + r10, r02 + r20, r12 + r21
    c0, c1, c2 = case == 0, case == 1, case == 2
    q = np.empty((R.shape[0], 4))
    q[:, 0] = np.where(c0, 1.0 + tr, np.where(c1, d21, np.where(c2, d02, d10)))
    q[:, 1] = np.where(c0, d21, np.where(c1, 1.0 + r00 - r11 - r22, np.where(c2, s01, s02)))
    q[:, 2] = np.where(c0, d02, np.where(c1, s01, np.where(c2, 1.0 - r00 + r11 - r22, s12)))
    q[:, 3] = np.where(c0, d10, np.where(c1, s02, np.where(c2, s12, 1.0 - r00 - r11 + r22)))
    return q / np.sqrt(np.einsum("ni,ni->n", q, q))[:, None]


def _unit_quaternion_matrix(q: np.ndarray) -> np.ndarray:
    """The hand-written unit quaternion -> matrix the planner used before planner.rotations (baseline)."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    R = np.empty((q.shape[0], 3, 3))
    R[:, 0, 0] = 1.0 - 2.0 * (y * y + z * z)
    R[:, 0, 1] = 2.0 * (x * y - w * z)
    R[:, 0, 2] = 2.0 * (x * z + w * y)
    R[:, 1, 0] = 2.0 * (x * y + w * z)
    R[:, 1, 1] = 1.0 - 2.0 * (x * x + z * z)
    R[:, 1, 2] = 2.0 * (y * z - w * x)
    R[:, 2, 0] = 2.0 * (x * z - w * y)
    R[:, 2, 1] = 2.0 * (y * z + w * x)
    R[:, 2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return R


def rotations_table(n: int) -> None:
    R1 = Rotation.random(n, random_state=1).as_matrix()
    R2 = Rotation.random(n, random_state=2).as_matrix()
    q = Rotation.random(n, random_state=3).as_quat(scalar_first=True)  # either sign of w
    rows = []

    def row(what, ours, base, base_name, diff):
        t_ours, t_base = best_time(ours), best_time(base)
        rows.append([what, f"{t_ours * 1e3:.2f}", base_name, f"{t_base * 1e3:.2f}", f"{t_base / t_ours:.2f}",
                     f"{diff:.1e}"])

    canon = np.sign(_shepperd(R1)[:, :1])
    row("matrix -> quaternion (scipy)", lambda: rotations.matrix_to_quaternion(R1), lambda: _shepperd(R1),
        "hand-written Shepperd", np.abs(rotations.matrix_to_quaternion(R1) - canon * _shepperd(R1)).max())
    row("quaternion -> matrix (scipy)", lambda: rotations.quaternion_to_matrix(q), lambda: _unit_quaternion_matrix(q),
        "hand-written unit formula", np.abs(rotations.quaternion_to_matrix(q) - _unit_quaternion_matrix(q)).max())
    qc = q * np.sign(q[:, :1])
    row("quaternion -> rotvec, sign kept (hand-written)", lambda: rotations.quaternion_to_rotvec(q),
        lambda: Rotation.from_quat(q, scalar_first=True).as_rotvec(), "scipy as_rotvec (w >= 0 only)",
        np.abs(rotations.quaternion_to_rotvec(qc) - Rotation.from_quat(qc, scalar_first=True).as_rotvec()).max())
    away = Rotation.from_matrix(np.einsum("nji,njk->nik", R1, R2)).magnitude() < np.pi - 1e-3
    row("angle between rotations (hand-written)", lambda: rotations.rotation_angle(R1, R2),
        lambda: Rotation.from_matrix(np.einsum("nji,njk->nik", R1, R2), assume_valid=True).magnitude(),
        "scipy magnitude of R1^T R2",
        np.abs(rotations.rotation_angle(R1, R2) - Rotation.from_matrix(np.einsum("nji,njk->nik", R1, R2))
               .magnitude())[away].max())
    print(f"Rotation conversions of planner.rotations, {n} rotations (ratio = other / ours; difference up to "
          "pi - 1e-3 for the angle)")
    print_table(["planner.rotations", "ms", "other route", "other ms", "ratio", "max |difference|"], rows)


def float_path_table(n: int) -> None:
    r = Rotation.random(n, random_state=4).as_rotvec()
    R = Rotation.from_rotvec(r).as_matrix()
    r1, R1 = r[0].tolist(), R[0]
    e1 = R1.ravel().tolist()
    rows = []

    def row(what, one, one_scipy, many, many_scipy, diff):
        t1, s1, tn, sn = (best_time(f) for f in (one, one_scipy, many, many_scipy))
        rows.append([what, f"{t1 * 1e6:.1f}", f"{s1 * 1e6:.1f}", f"{tn * 1e3:.2f}", f"{sn * 1e3:.2f}", f"{diff:.1e}"])

    row("rotvec -> matrix", lambda: rotations.rotvec_to_matrix_1(*r1),
        lambda: Rotation.from_rotvec(r[0]).as_matrix(), lambda: rotations.rotvec_to_matrix_n(r),
        lambda: Rotation.from_rotvec(r).as_matrix(),
        np.abs(rotations.rotvec_to_matrix_n(r) - Rotation.from_rotvec(r).as_matrix()).max())
    row("matrix -> rotvec", lambda: rotations.matrix_to_rotvec_1(*e1),
        lambda: Rotation.from_matrix(R1).as_rotvec(), lambda: rotations.matrix_to_rotvec_n(R),
        lambda: Rotation.from_matrix(R).as_rotvec(),
        np.abs(rotations.matrix_to_rotvec_n(R) - Rotation.from_matrix(R).as_rotvec()).max())
    print(f"The float path of the kinematics (planner.rotations *_1, *_n) against scipy: one rotation, and {n}")
    print_table(["conversion", "*_1 us", "scipy one us", "*_n ms", "scipy n ms", "max |difference|"], rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--waypoints", type=int, default=1000)
    ap.add_argument("--samples", type=int, default=100_000)
    ap.add_argument("--rotations-only", action="store_true", help="print table 3 only")
    args = ap.parse_args()
    rotations_table(args.samples)
    print()
    float_path_table(args.samples)
    print()
    if args.rotations_only:
        return
    seed_table()
    print()
    path_table(args.waypoints, args.samples)


if __name__ == "__main__":
    main()
