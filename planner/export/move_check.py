"""The joints of a program's moves as the controller samples them, and moves slowed where a joint would go too fast.

``movel``/``movep`` hold the tool to the move's speed ``v`` and acceleration ``a``; near the elbow, wrist and shoulder
singularities a small tool acceleration needs a large joint acceleration (a 1.98 mm rapid of the shared NX job that
ends with the elbow nearly stretched, q3 = 0.010 rad, needs 154 rad/s^2 on the elbow at a = 0.5 m/s^2). The
controller samples every move every control period and stops the arm with a protective stop on a sample beyond the
joint speed limits or :data:`~planner.kinematics.ur_moves.JOINT_ACCEL_MAX` (:mod:`planner.kinematics.ur_moves`,
which the simulated controller runs programs on: the same samples, the same limits). So every move of a program is
checked on those samples before it is written:

- first every :data:`COARSE`-th control period (speeds and accelerations from differences over that spacing, which
  smooths a peak a few periods wide: on the shared NX job it sees a quarter to a third of the peaks of short blends
  and of a move that ends next to a singularity); a move whose joints reach :data:`SCREEN` of a limit there is
  sampled at every control period, as the controller samples it;
- a move with a sample beyond :data:`LOWER_ABOVE` of a limit is slowed to :data:`TARGET` of it by stretching its time
  law: v over c, a over c^2 (and a timed move's t times c), which scales every joint speed of a single move by 1 / c
  and every joint acceleration by 1 / c^2; on a pass of blended ``movep`` moves only the moves with samples that
  high are slowed (the blends before and after follow, as the time law slows down into them at the move's ``a``),
  round by round until no sample is, at most :data:`ROUNDS` rounds.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from planner.export.header import ExportError
from planner.export.script_text import as_written
from planner.kinematics.ur_models import JOINT_NAMES
from planner.kinematics.ur_moves import (
    DT,
    JOINT_ACCEL_MAX,
    MotionError,
    MoveSamples,
    joint_rates,
    joint_samples,
    linear_samples,
)

#: Control periods between the samples of the first look.
COARSE = 8
#: Fraction of a limit at which the first look samples the move at every control period.
SCREEN = 0.25
#: Fraction of a limit above which a sample makes the move slowed, and the fraction it is slowed to.
LOWER_ABOVE = 0.95
TARGET = 0.9
#: Rounds of slowing before a move is given up on.
ROUNDS = 12


@dataclass(frozen=True)
class MoveRates:
    """How close the joints of one sampled move come to their limits.

    Attributes
    ----------
    ratio : ndarray (K,)
        Largest of |joint speed| / speed limit and |joint acceleration| / JOINT_ACCEL_MAX over the joints, per sample.
    joint : int
        The joint of the highest ratio.
    speed : bool
        Whether that ratio is a speed's (else an acceleration's).
    peak : float
        Its value, rad/s or rad/s^2.
    """

    ratio: np.ndarray
    joint: int
    speed: bool
    peak: float

    @property
    def worst(self) -> float:
        return float(self.ratio.max(initial=0.0))

    def describe(self) -> str:
        what = f"speed {self.peak:.3g} rad/s" if self.speed else f"acceleration {self.peak:.3g} rad/s^2"
        return f"joint {self.joint + 1} ({JOINT_NAMES[self.joint]}) {what}"


def rates(model, q0: np.ndarray, samples: MoveSamples, period: float = DT) -> MoveRates:
    """The ratios of a move's samples (played from rest at ``q0``) to the joint limits."""
    V, A = joint_rates(q0, samples.q, period)
    rv = np.abs(V) / model.speed_limits
    ra = np.abs(A) / JOINT_ACCEL_MAX
    ratio = np.maximum(rv.max(axis=1), ra.max(axis=1))
    k = int(np.argmax(ratio))
    speed = bool(rv[k].max() >= ra[k].max())
    j = int(np.argmax(rv[k] if speed else ra[k]))
    return MoveRates(ratio, j, speed, float(abs(V[k, j]) if speed else abs(A[k, j])))


@dataclass(frozen=True)
class CheckedRun:
    """One run of moves (a single move, or a pass of blended ``movep`` moves) after the check.

    Attributes
    ----------
    segs : list of Segment
        The moves as they are to be written (v and a lowered on the slowed ones).
    duration : float
        The run's ``t`` (0: none), s, stretched with a slowed timed move.
    q_end : ndarray (6,)
        The joints the run ends at (the next run starts there), rad.
    slowed : tuple of int
        Indices of the slowed moves in ``segs``.
    factor : float
        The largest stretch c of a slowed move (1: none slowed); v over c, a over c^2.
    before, after : MoveRates
        The rates of the samples as given and as written (the same object when nothing was slowed).
    """

    segs: list
    duration: float
    q_end: np.ndarray
    slowed: tuple
    factor: float
    before: MoveRates
    after: MoveRates


def _written(x: float) -> float:
    """``x`` as a program writes it (:func:`planner.export.script_text.num`) and the controller reads it."""
    return float(as_written(x))


def _stretch(segs: list, which: np.ndarray, c: np.ndarray) -> list:
    """``segs`` with the moves ``which`` slowed by stretches ``c`` (v over c, a over c^2)."""
    out = list(segs)
    for i, ci in zip(which.tolist(), c.tolist(), strict=True):
        s = out[i]
        out[i] = replace(s, v=_written(s.v / ci), a=_written(s.a / ci**2))
    return out


def check_run(model, tcp, q0: np.ndarray, segs: list, duration: float = 0.0, *, joint: bool = False,
              what: str = "move") -> CheckedRun:
    """The run ``segs`` from joints ``q0`` (movej if ``joint``, else movel/movep; ``duration`` its t) checked on the
    controller's samples and slowed where a joint would exceed :data:`LOWER_ABOVE` of a limit (see the module doc).
    ExportError naming ``what`` if the run leaves the workspace or cannot be slowed enough in :data:`ROUNDS` rounds."""

    def sample(ss, dur, period=DT) -> MoveSamples:
        try:
            tr = (joint_samples(model, q0, ss, dur, period) if joint
                  else linear_samples(model, tcp, q0, ss, dur, period))
        except MotionError as exc:
            raise ExportError(f"{what}: {exc}") from None
        if tr.fault:
            raise ExportError(f"{what}: {tr.fault}")
        return tr

    coarse = sample(segs, duration, COARSE * DT)
    first = rates(model, q0, coarse, COARSE * DT)
    if first.worst < SCREEN:
        return CheckedRun(segs, duration, coarse.q[-1], (), 1.0, first, first)
    tr = sample(segs, duration)
    before = now = rates(model, q0, tr)
    slowed = np.zeros(len(segs), bool)
    stretch = np.ones(len(segs))
    for _ in range(ROUNDS):
        if now.worst <= LOWER_ABOVE:
            break
        bad = np.flatnonzero(now.ratio > TARGET)
        # the move each too-high sample belongs to (samples before a move's first belong to the one before)
        owner = np.clip(np.searchsorted(np.asarray(tr.starts), bad, side="right") - 1, 0, len(segs) - 1)
        which = np.unique(owner)
        # the stretch that brings the worst sample of each move to TARGET: speeds scale by 1 / c, accelerations by
        # 1 / c^2 (at least 2 %, so that every round gains)
        worst = np.zeros(len(segs))
        np.maximum.at(worst, owner, now.ratio[bad])
        c = np.maximum(np.sqrt(worst[which] / TARGET), 1.02)
        if len(segs) == 1 and duration > 0.0:
            duration = _written(duration * float(c[0]))
        segs = _stretch(segs, which, c)
        slowed[which] = True
        stretch[which] *= c
        tr = sample(segs, duration)
        now = rates(model, q0, tr)
    else:
        if now.worst > LOWER_ABOVE:
            raise ExportError(f"{what}: a joint stays too fast after slowing the moves {ROUNDS} times (by up to "
                              f"{stretch.max():.3g}x): {now.describe()}; the path passes too near a singularity")
    return CheckedRun(segs, duration, tr.q[-1], tuple(np.flatnonzero(slowed).tolist()), float(stretch.max()),
                      before, now)


def stretch_text(c: float) -> str:
    """How a stretch c lowers a move's v and a, for a person."""
    return f"v to {100.0 / c:.3g} %, a to {100.0 / c**2:.3g} %"


__all__ = ["COARSE", "LOWER_ABOVE", "ROUNDS", "SCREEN", "TARGET", "CheckedRun", "MoveRates", "check_run", "rates",
           "stretch_text"]
