"""Tolerances and constants shared by the block (numpy) and one-pose (Python float) IK solvers."""

from __future__ import annotations

import math

# Acceptance of round-off at the workspace boundary: |d4 / r| and |cos q3| may exceed 1 by this much.
BOUNDARY_TOL = 1e-9
# |sin q5| below WRIST_SINGULAR is the wrist singularity (q6 then set to its reference value);
# below WRIST_NEAR, q234 and q6 are turned together where the elbow cannot reach otherwise.
WRIST_SINGULAR = 1e-12
WRIST_NEAR = 1e-6
# A checked candidate is kept only if it reproduces the pose to these tolerances (m, rad).
POS_TOL = 1e-9
ROT_TOL = 1e-9
# Joint-space distance below which two solutions of one pose count as the same one.
SAME_SOLUTION = 1e-9
TWO_PI = 2.0 * math.pi
INV_TWO_PI = 1.0 / TWO_PI


def wrap_1(x: float) -> float:
    """One angle wrapped into (-pi, pi]: the operations of ``inverse.wrap_angle`` on a Python float."""
    w = x - TWO_PI * round(x * INV_TWO_PI)
    if w <= -math.pi:
        return w + TWO_PI
    if w > math.pi:
        return w - TWO_PI
    return w
