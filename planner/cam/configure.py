"""Arm configurations of a CAM job: runs of passes, safe points in the rapids, candidate branches.

A UR arm reaches most poses in 8 ways (shoulder, wrist and elbow solution, see
:class:`planner.kinematics.IKSolutions`) and, its joints turning +-2 pi, with a choice of whole turns.
The arm cannot change configuration along a cut (the tool would leave the path), nor at a corner the
CAM system joins two passes at without a rapid. So the configuration is chosen per *run*: the passes
between two rapids (with the turns in place between them). Between runs, in the *gap* (the rapids and
turns before a run), the arm may change it with a joint move at a safe point of a rapid.

This module holds the geometry of that choice (:func:`groups`, :func:`safe_point`, :func:`candidates`,
:func:`turn_shift`, :func:`describe_change`); :mod:`planner.cam.reach` checks the configurations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.kinematics import forward_matrix, get_model, inverse_batch, wrap_angle
from planner.kinematics.ur_models import JOINT_NAMES

#: The CAM default tool axis (APT: +Z, from the tip towards the spindle), as in planner.cam.job.
_CAM_DEFAULT_AXIS = np.array([0.0, 0.0, 1.0])
#: Two safe points whose heights differ by less than this (m) are equally high: the later one is taken.
_SAME_HEIGHT = 1e-9
#: Fractions of a joint move at which the TCP excursion is measured.
_EXCURSION_SAMPLES = 65


@dataclass(frozen=True)
class Group:
    """The moves of a job between two runs, and the run after them (indices into ``PlannedJob.moves``).

    Attributes
    ----------
    gap : tuple of int
        Rapids, turns in place and skipped records before the run (after the previous run's last cut).
    run : tuple of int
        The run: its first and last moves are cuts, nothing between them is a rapid. Empty for the moves
        after the job's last cut.
    """

    gap: tuple
    run: tuple


def groups(moves) -> list[Group]:
    """The job's moves as (gap, run) groups in order; the last group's run is empty if moves follow the
    last cut. Every move is in exactly one group."""
    out: list[Group] = []
    gap: list[int] = []
    run: list[int] = []
    pending: list[int] = []  # non-cut moves after the run's last cut so far
    for k, m in enumerate(moves):
        if m.kind == "cut":
            if run:
                run += pending + [k]
                pending = []
            else:
                run = [k]
        elif m.kind == "rapid" and run:
            out.append(Group(tuple(gap), tuple(run)))
            gap, run, pending = pending + [k], [], []
        elif run:
            pending.append(k)
        else:
            gap.append(k)
    if run:
        out.append(Group(tuple(gap), tuple(run)))
        gap = pending
    if gap:
        out.append(Group(tuple(gap), ()))
    return out


def _boundary_point(moves, group: Group, s: int) -> np.ndarray:
    """Tool position (part frame) at boundary s of the gap: the start of gap move s, or the run's start."""
    k = group.gap[s] if s < len(group.gap) else group.run[0]
    return np.asarray(moves[k].point, dtype=float)


def _cam_axis(cut) -> np.ndarray:
    """CAM tool axis (tip towards spindle, unit) at the first point of a pass."""
    a = _CAM_DEFAULT_AXIS if cut.axes is None else np.asarray(cut.axes[0], dtype=float)
    return a / np.linalg.norm(a)


def safe_point(moves, group: Group, last: int) -> int | None:
    """The boundary s (0..len(gap)) of the gap where the arm may change configuration, or None.

    Eligible are the ends of the gap's rapids up to boundary ``last`` (the moves before the boundary are
    made on the former configuration). Of these, the one farthest from the part along the CAM tool axis
    of the run's first point (the most retracted) is taken; of equally high ones, the last.
    """
    gap = group.gap
    eligible = [s for s in range(min(last, len(gap)) + 1)
                if (s > 0 and moves[gap[s - 1]].kind == "rapid") or (s < len(gap) and moves[gap[s]].kind == "rapid")]
    if not eligible or not group.run:
        return None
    first = moves[group.run[0]]
    a = _cam_axis(first.item)
    h = np.array([(_boundary_point(moves, group, s) - first.point) @ a for s in eligible])
    top = h.max()
    return max(s for s, x in zip(eligible, h, strict=True) if x >= top - _SAME_HEIGHT)


def where_text(moves, group: Group, s: int) -> tuple[str, int]:
    """Where boundary s of the gap is, for a person, and the source line of its rapid record."""
    gap = group.gap
    before = moves[gap[s - 1]] if s > 0 else None
    after = moves[gap[s]] if s < len(gap) else None
    if before is not None and before.kind == "rapid":
        if after is not None and after.kind == "rapid":
            return f"between the rapids at lines {before.line} and {after.line}", int(before.line)
        return f"at the end of the rapid at line {before.line}", int(before.line)
    assert after is not None, "a gap boundary has a rapid on at least one side"
    return f"at the start of the rapid at line {after.line}", int(after.line)


def candidates(model, pose: np.ndarray, tcp=None) -> np.ndarray:
    """The valid inverse-kinematics branches (k, 6) of one TCP pose (base frame), wrapped to (-pi, pi]."""
    sol = inverse_batch(model, pose, tcp=tcp)
    return sol.q[0][sol.valid[0]]


def turn_shift(model, q_along: np.ndarray, q_ref: np.ndarray | None, q_at: np.ndarray) -> np.ndarray | None:
    """Whole turns (6,) (multiples of 2 pi, rad) to add to a configuration so that it fits the joint limits.

    Parameters
    ----------
    model : str or URModel
    q_along : ndarray (n, 6)
        Joints along everything made on the configuration (rows of NaN ignored).
    q_ref : ndarray (6,) or None
        Where the arm is: of the turns that keep every joint within its limits, the one putting ``q_at``
        nearest to it is taken (None: the one centring the joint's travel in its range).
    q_at : ndarray (6,)
        The configuration's joints at the point compared with ``q_ref``.

    Returns
    -------
    ndarray (6,) or None
        None if some multiturn joint's travel fits no whole turn (it spans more than its range).
    """
    m = get_model(model)
    shift = np.zeros(6)
    lo, hi = np.nanmin(q_along, axis=0), np.nanmax(q_along, axis=0)
    for j in np.flatnonzero(m.multiturn):
        n = np.arange(-3, 4)
        ok = (lo[j] + 2.0 * np.pi * n >= m.lower[j] - 1e-12) & (hi[j] + 2.0 * np.pi * n <= m.upper[j] + 1e-12)
        if not ok.any():
            return None
        n = n[ok]
        if q_ref is None:
            mid = 0.5 * (lo[j] + hi[j]) + 2.0 * np.pi * n
            best = n[np.argmin(np.abs(mid - 0.5 * (m.lower[j] + m.upper[j])))]
        else:
            best = n[np.argmin(np.abs(q_at[j] + 2.0 * np.pi * n - q_ref[j]))]
        shift[j] = 2.0 * np.pi * best
    return shift


def _branch(model, pose: np.ndarray, q: np.ndarray, tcp) -> int:
    """The branch index (see IKSolutions) of joints q at a pose: the nearest solution modulo 2 pi."""
    sol = inverse_batch(model, pose, tcp=tcp)
    d = np.abs(wrap_angle(sol.q[0] - q)).max(axis=1)
    return int(np.nanargmin(np.where(sol.valid[0], d, np.inf)))


def describe_change(model, pose: np.ndarray, q_from: np.ndarray, q_to: np.ndarray, tcp=None) -> str:
    """What a configuration change changes, for a person: the branches flipped, the joints that turn by
    more than half a turn (whole turns beyond the shorter way round, to stay within their limits) and the
    largest joint move, e.g. "wrist flipped; wrist 3 -1 turn; largest joint move 3.14 rad (wrist 1)"."""
    b0, b1 = _branch(model, pose, q_from, tcp), _branch(model, pose, q_to, tcp)
    flips = [name for bit, name in ((4, "shoulder"), (2, "wrist"), (1, "elbow")) if (b0 ^ b1) & bit]
    parts = [" and ".join(flips) + " flipped"] if flips else []
    dq = q_to - q_from
    turns = np.round((dq - wrap_angle(dq)) / (2.0 * np.pi)).astype(int)  # beyond the shorter way round
    parts += [f"{JOINT_NAMES[j]} {int(t):+d} turn{'s' * int(abs(t) > 1)}" for j, t in enumerate(turns) if t]
    j = int(np.argmax(np.abs(q_to - q_from)))
    parts.append(f"largest joint move {abs(q_to[j] - q_from[j]):.3g} rad ({JOINT_NAMES[j]})")
    return "; ".join(parts)


def tcp_excursion(model, q_from: np.ndarray, q_to: np.ndarray, tcp=None) -> float:
    """Largest distance (m) of the TCP from its start during the straight joint move q_from -> q_to."""
    f = np.linspace(0.0, 1.0, _EXCURSION_SAMPLES)
    T = forward_matrix(model, q_from + f[:, None] * (q_to - q_from), tcp=tcp)
    return float(np.linalg.norm(T[:, :3, 3] - T[0, :3, 3], axis=1).max())
