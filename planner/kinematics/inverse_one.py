"""The inverse kinematics of one pose on Python floats: the documented exception to the block solver.

:func:`planner.kinematics.inverse` and :func:`planner.kinematics.inverse_nearest` serve a controller
loop (one pose per 2 ms period in the simulated controller). numpy spends about a microsecond on
every operation whatever the array size, so the block solver (``inverse._solve_block``, ~150 array
operations) costs about half a millisecond for one pose. :func:`solve_one` runs the very same
derivation on Python floats with ``math`` (about 15 us): the same formulas written in the same
order, so every sum and product rounds as in the block solver, the same branch order
``b = 4 * i1 + 2 * i5 + i3``, the same thresholds (``_tolerances``), the same wrist-singularity rule
(q6 set to its reference value) and the same forward-kinematics check of candidates computed from
clipped round-off. The one hypot whose result feeds every later quantity (the wrist centre's
distance from the base axis) is numpy's, called on Python floats. Only ``math``'s atan2 / asin / acos
may differ from numpy's vectorized ones by one unit in the last place; their results are only ever
added to other angles, never fed back into a cosine, so the joints agree to ~1e-15 (a hypothesis
property test in tests/test_kinematics_single.py proves equality to 1e-12 on random, near-singular
and boundary poses).

One case is left to the block solver (:func:`solve_one` returns None): next to the wrist
singularity, where the elbow cannot reach with q6 at its reference value and q234, q6 are turned
together (``inverse._reachable_self_motion``), or where the test for that is within round-off of
its threshold (e.g. at q3 = q5 = 0). There the angles feed cosines at a stretched or folded elbow,
where acos is ill-conditioned, and only the one implementation gives identical joints.
"""

from __future__ import annotations

import math
from math import acos, asin, atan2, cos, hypot, sin, sqrt

import numpy as np

from planner.kinematics._tolerances import (
    BOUNDARY_TOL,
    POS_TOL,
    ROT_TOL,
    TWO_PI,
    WRIST_NEAR,
    WRIST_SINGULAR,
    wrap_1,
)
from planner.kinematics.forward import flange_1
from planner.kinematics.ur_models import URModel

__all__ = ["solve_one"]

_PI = math.pi
_SQRT2 = math.sqrt(2.0)
_np_hypot = np.hypot
# Comparisons of the turning test closer than this to their threshold are left to the block solver
# (math and numpy round atan2 and hypot differently by an ulp, ~1e-16 here).
_UNDECIDED = 1e-12


def solve_one(m: URModel, R, p, q6_ref: float) -> list[tuple[float, ...] | None] | None:
    """The 8 branches of one flange target (rotation R: 9 entries row by row, origin p: 3 floats).

    Returns a list of 8 entries in branch order (see :class:`planner.kinematics.IKSolutions`), each a
    tuple of 6 joints (rad, wrapped to (-pi, pi]) or None where the branch does not exist; None
    (instead of the list) where the block solver must decide (see the module docstring).
    """
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
    px, py, pz = p
    d4, d5, d6, a2, a3 = m.d4, m.d5, m.d6, m.a2, m.a3

    # Shoulder: wrist centre p5 . z1 = d4 (as inverse._solve_block).
    p5x, p5y = px - d6 * r02, py - d6 * r12
    r = float(_np_hypot(p5x, p5y))  # numpy's, as the block solver: math.hypot may differ by an ulp
    ratio = d4 / r if r > 0.0 else math.inf
    if not ratio <= 1.0 + BOUNDARY_TOL:
        return [None] * 8
    psi = atan2(p5y, p5x)
    cpsi, spsi = p5x / r, p5y / r
    sb = min(ratio, 1.0)  # sin beta (ratio > 0)
    beta = asin(sb)
    cb = sqrt((1.0 - sb) * (1.0 + sb))
    clipped1 = ratio > 1.0
    pz = pz - m.d1
    a22, a33 = a2**2, a3**2  # as the block solver's m.a2**2, m.a3**2 and 2.0 * m.a2 * m.a3
    den3 = 2.0 * a2 * a3
    if q6_ref is None:
        q6_ref = 0.0
    cref, sref = cos(q6_ref), sin(q6_ref)
    q6_ref_w = wrap_1(q6_ref)

    out: list[tuple[float, ...] | None] = []
    shoulders = (
        (psi + beta, cpsi * cb - spsi * sb, spsi * cb + cpsi * sb),
        (psi + _PI - beta, -(cpsi * cb + spsi * sb), cpsi * sb - spsi * cb),
    )
    for q1, c1, s1 in shoulders:
        q1 = wrap_1(q1)
        # Wrist: z1 in the flange frame is (cos q6 sin q5, -sin q6 sin q5, cos q5).
        u = r00 * s1 - r10 * c1
        v = r01 * s1 - r11 * c1
        w = r02 * s1 - r12 * c1
        h = sqrt(u * u + v * v)
        hw = h / sqrt(h * h + w * w)
        x6x = r00 * c1 + r10 * s1
        y6x = r01 * c1 + r11 * s1
        px1 = px * c1 + py * s1
        for sg in (1.0, -1.0):
            q5 = atan2(sg * h, w)
            if q5 <= -_PI:
                q5 += TWO_PI
            s5 = sg * hw
            if h < WRIST_SINGULAR:
                q6, c6, s6 = q6_ref_w, cref, sref
            else:
                q6 = atan2(-sg * v, sg * u)
                c6 = sg * (u / h)
                s6 = -sg * (v / h)
                if q6 <= -_PI:
                    q6 += TWO_PI
            # Planar 2R arm in frame 1.
            Y = -(s6 * x6x + c6 * y6x)
            X = s6 * r20 + c6 * r21
            q234 = atan2(Y, X)
            nrm = sqrt(X * X + Y * Y)
            c234, s234 = X / nrm, Y / nrm
            if h < WRIST_NEAR and _must_turn(m, q234, s5, px1, pz) is not False:
                return None  # turned, or too close to call: the block solver decides
            x = px1 + d6 * s5 * c234 - d5 * s234
            y = pz + d6 * s5 * s234 + d5 * c234
            cos3 = (x * x + y * y - a22 - a33) / den3
            if not abs(cos3) <= 1.0 + BOUNDARY_TOL:
                out += (None, None)
                continue
            c3 = min(max(cos3, -1.0), 1.0)
            t3 = acos(c3)
            s3 = sqrt((1.0 - c3) * (1.0 + c3))
            phi = atan2(y, x)
            gam = atan2(a3 * s3, a2 + a3 * c3)
            check = clipped1 or abs(cos3) > 1.0
            for q2, q3 in ((phi - gam, t3), (phi + gam, -t3)):
                if q3 <= -_PI:
                    q3 += TWO_PI
                sol = (q1, wrap_1(q2), q3, wrap_1(q234 - q2 - q3), q5, q6)
                out.append(sol if not check or _reproduces(m, sol, R, p) else None)
    return out


def _must_turn(m: URModel, q234: float, s5: float, cx: float, cy: float) -> bool | None:
    """Whether ``inverse._reachable_self_motion`` turns this candidate: the same test on floats, None
    where a comparison lies within round-off (``_UNDECIDED``) of its threshold. math's atan2 and hypot
    may differ from numpy's by an ulp, and at a stretched elbow such a difference changes q3 by 1e-8;
    those candidates are left to the block solver."""
    rc = hypot(cx, cy)
    rho = hypot(m.d5, m.d6 * s5)
    if rc == 0.0:
        return False  # the block solver's bounds are NaN there: not feasible, not turned
    alpha = atan2(cy, cx) - atan2(m.d5, m.d6 * s5)
    reach_in, reach_out = abs(abs(m.a2) - abs(m.a3)), abs(m.a2) + abs(m.a3)
    lo = (reach_in**2 - rc**2 - rho**2) / (2.0 * rho * rc)
    hi = (reach_out**2 - rc**2 - rho**2) / (2.0 * rho * rc)
    k = cos(wrap_1(q234 - alpha))
    gaps = (hi + BOUNDARY_TOL - lo, hi + 1.0 + BOUNDARY_TOL, 1.0 + BOUNDARY_TOL - lo, lo - k, k - hi)
    if min(abs(g) for g in gaps) <= _UNDECIDED:
        return None
    if not (lo <= hi + BOUNDARY_TOL and hi >= -1.0 - BOUNDARY_TOL and lo <= 1.0 + BOUNDARY_TOL):
        return False
    lo = min(max(lo, -1.0), 1.0)
    hi = max(min(max(hi, -1.0), 1.0), lo)
    return k < lo or k > hi


def _reproduces(m: URModel, q, R, p) -> bool:
    """Forward-kinematics check of a candidate from clipped round-off (the block solver's test)."""
    Rc, pc = flange_1(m, q)
    pos = sqrt(sum((a - b) ** 2 for a, b in zip(pc, p, strict=True)))
    rot = sqrt(sum((a - b) ** 2 for a, b in zip(Rc, R, strict=True))) / _SQRT2
    return pos <= POS_TOL and rot <= ROT_TOL
