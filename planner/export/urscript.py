"""URScript programs a UR controller runs as they are: a ``servoj`` stream or ``movep`` moves.

Facts used (shared/UR-PROTOCOLS.md): a program is ``def name(): ... end``; sent whole to the script
port (30002/30003) the controller runs it at once (that is how ur_rtde uploads ``rtde_control``);
``servoj`` takes t, lookahead_time and gain. Where UR-PROTOCOLS.md is silent this follows the UR Script
Manual (e-Series, as the author knows it), and the program says so in its comments:

- ``servoj(q, a, v, t, lookahead_time, gain)``: joint target q (rad), a and v unused; blocks for t
  seconds (>= 0.002 on e-Series, 0.008 on CB-Series); lookahead_time in [0.03, 0.2] s; gain in
  [100, 2000]. One call per sample at t = 1 / rate makes sample i's target current from i / rate on.
- ``stopj(a)`` ends the servo stream, decelerating the joints at a rad/s^2.
- ``movej(q, a, v)`` with a pose target solves the inverse kinematics on the controller.
- ``movep(pose, a, v, r)``: linear moves at constant tool speed v (m/s), circular blends of radius r;
  statements after a blended move run when the blend starts.
- ``set_tcp(pose)``; the output setters of the UR output table (:mod:`planner.kinematics.ur_outputs`),
  ``set_standard_digital_out(n, b)`` and the like; booleans ``True``/``False``; ``#`` comments.

Numbers are written in fixed point with 12 decimals (no exponents), far below the robot's resolution.
"""

from __future__ import annotations

import numpy as np

from planner.errors import PlannerError
from planner.export.files import text_target
from planner.export.movep import MovePPlan
from planner.export.script_text import io_line, num, pose
from planner.motion.limits import positive

#: servoj parameter ranges (UR Script Manual, e-Series).
SERVOJ_MIN_T = 0.002
LOOKAHEAD_RANGE = (0.03, 0.2)
GAIN_RANGE = (100.0, 2000.0)


def movep_lines(plan: MovePPlan, acceleration: float) -> list[str]:
    """The body lines that follow a plan from its first target (where the tool is) to its last.

    One ``movep(p[...], a, v, r)`` per target after the first (speed and blend radius of the plan; ``a`` the
    plan's where it has its own, see :attr:`MovePPlan.accelerations`),
    each target's I/O switches after its move; the switches at the first target come first.
    """
    a = positive(acceleration, "acceleration")
    by_target: dict[int, list] = {}
    for e in plan.events:
        by_target.setdefault(e.index, []).append(e)
    lines = [io_line(e) for e in by_target.get(0, [])]
    acc = np.full(plan.s.size, a) if plan.accelerations is None else plan.accelerations
    for i in range(1, plan.s.size):
        lines.append(f"  movep({pose(plan.poses[i])}, a={num(acc[i])}, v={num(plan.speeds[i])}, "
                     f"r={num(plan.radii[i])})")
        lines += [io_line(e) for e in by_target.get(i, [])]
    return lines


def write_script(program: str, target) -> None:
    """Write a program text to a path (atomically) or a text file."""
    if not isinstance(program, str):
        raise PlannerError(f"program must be the program's text (str), got {type(program).__name__}")
    with text_target(target) as f:
        f.write(program)

