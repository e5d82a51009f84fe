"""Per-job reachability: joint position limits, joint speed limits and unreachable samples.

A joint trajectory is the output of :func:`planner.kinematics.inverse_path` (rows of NaN mark poses
without an inverse kinematics solution). Joint speeds are forward differences over the sample times;
the speed between samples i and i + 1 is charged to sample i + 1, the first one that cannot be
reached in time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.errors import PlannerError
from planner.kinematics._checks import rows_of_six, times
from planner.kinematics.inverse import inverse_path
from planner.kinematics.ur_models import JOINT_NAMES, URModel, get_model

__all__ = [
    "JOINT_SPEED_REASONS",
    "Violation",
    "ReachabilityReport",
    "joint_speeds",
    "speed_ratios",
    "check_reachability",
    "check_poses",
    "feed_scale",
    "feed_scale_profile",
]

_KINDS = ("unreachable", "position", "speed")

#: What limits the feed where a joint is the fastest, by joint index (e.g. "joint 4 (wrist 2) speed").
JOINT_SPEED_REASONS = tuple(f"joint {j} ({name}) speed" for j, name in enumerate(JOINT_NAMES))


@dataclass(frozen=True)
class Violation:
    """One place where the robot cannot follow the job.

    Attributes
    ----------
    kind : str
        ``"unreachable"`` (no IK solution), ``"position"`` (joint limit) or ``"speed"``.
    index : int
        Sample index (0-based).
    time : float
        Sample time in s.
    joint : int or None
        Joint index 0..5 (None for an unreachable sample).
    value : float
        Joint position (rad) or |joint speed| (rad/s); NaN for an unreachable sample.
    limit : float
        The limit exceeded (rad or rad/s); NaN for an unreachable sample.
    arc_length : float or None
        Arc length of the sample along the path (m), if given to the check.
    span : int or None
        Waypoint span of the sample, if given to the check.
    """

    kind: str
    index: int
    time: float
    joint: int | None
    value: float
    limit: float
    arc_length: float | None = None
    span: int | None = None

    def describe(self) -> str:
        """One line saying what is violated where, for a person."""
        where = f"sample {self.index} (t = {self.time:.6g} s"
        if self.arc_length is not None:
            where += f", s = {self.arc_length:.6g} m"
        if self.span is not None:
            where += f", span {self.span}"
        where += ")"
        if self.kind == "unreachable":
            return f"{where}: pose has no inverse kinematics solution"
        assert self.joint is not None, "every kind of violation but 'unreachable' names its joint"
        name = f"joint {self.joint} ({JOINT_NAMES[self.joint]})"
        if self.kind == "position":
            side = "above" if self.value > self.limit else "below"
            return f"{where}: {name} at {self.value:.6g} rad is {side} its limit {self.limit:.6g} rad"
        return f"{where}: {name} speed {self.value:.6g} rad/s exceeds its limit {self.limit:.6g} rad/s"


@dataclass(frozen=True)
class ReachabilityReport:
    """Outcome of a reachability check over a whole job.

    Attributes
    ----------
    ok : bool
        True if every sample is reachable within joint position and speed limits.
    first : Violation or None
        The earliest violation (ties: unreachable, then position, then speed).
    n_unreachable : int
        Number of samples without an IK solution.
    n_position : int
        Number of samples with a joint outside its position limits.
    n_speed : int
        Number of samples reached with a joint faster than its speed limit.
    max_speed_ratio : float
        Largest |joint speed| / speed limit over the job (0 for a single sample).
    feed_scale : float
        Factor (<= 1) by which to scale the feed so that every joint speed is within its limit.
    message : str
        Human-readable summary naming the first violation.
    """

    ok: bool
    first: Violation | None
    n_unreachable: int
    n_position: int
    n_speed: int
    max_speed_ratio: float
    feed_scale: float
    message: str


def _times(t, n: int) -> np.ndarray:
    t = times(t, n)
    if t.shape != (n,):
        raise PlannerError(f"t: expected shape ({n},) (one time per sample), got {t.shape}")
    bad = ~np.isfinite(t)
    if bad.any():
        raise PlannerError(f"t[{int(np.argmax(bad))}] is {t[np.argmax(bad)]}; times must be finite")
    dt = np.diff(t)
    if (dt <= 0).any():
        i = int(np.argmax(dt <= 0)) + 1
        raise PlannerError(f"t[{i}] = {t[i]} s is not after t[{i - 1}] = {t[i - 1]} s; times must increase")
    return t


def _trajectory(q, t) -> tuple[np.ndarray, np.ndarray]:
    q, _ = rows_of_six(q, "q", allow_nan_rows=True)
    return q, _times(t, len(q))


def joint_speeds(q, t) -> np.ndarray:
    """Forward-difference joint speeds (rad/s).

    Parameters
    ----------
    q : array_like, shape (n, 6)
        Joint positions in rad (continuous, i.e. unwrapped); rows of NaN are unreachable samples.
    t : array_like, shape (n,)
        Strictly increasing sample times in s.

    Returns
    -------
    ndarray, shape (n - 1, 6)
        Row i is (q[i + 1] - q[i]) / (t[i + 1] - t[i]); NaN next to unreachable samples.
    """
    q, t = _trajectory(q, t)
    return np.diff(q, axis=0) / np.diff(t)[:, None]


def _speed_ratios(m: URModel, q: np.ndarray, t: np.ndarray) -> np.ndarray:
    """|qdot| / limit per interval (n - 1, 6), 0 where undefined (next to unreachable samples)."""
    ratio = np.abs(np.diff(q, axis=0) / np.diff(t)[:, None]) / m.speed_limits
    return np.nan_to_num(ratio, nan=0.0)


def speed_ratios(model: str | URModel, q, t) -> tuple[np.ndarray, np.ndarray]:
    """How many times too fast every sample interval is, and which joint is the fastest.

    Parameters
    ----------
    model : str or URModel
    q : array_like, shape (n, 6)
        Joint trajectory in rad (rows of NaN: unreachable samples).
    t : array_like, shape (n,)
        Strictly increasing sample times in s.

    Returns
    -------
    ratio : ndarray, shape (n - 1,)
        max_j |q[i + 1, j] - q[i, j]| / (t[i + 1] - t[i]) / limit_j: > 1 where a joint is too fast;
        NaN next to an unreachable sample.
    joint : ndarray of int, shape (n - 1,)
        The joint j of that largest ratio (0 next to an unreachable sample).
    """
    m = get_model(model)
    q, t = _trajectory(q, t)
    r = np.abs(np.diff(q, axis=0) / np.diff(t)[:, None]) / m.speed_limits
    if not r.size:
        return np.zeros(0), np.zeros(0, dtype=int)
    undefined = np.isnan(r).any(axis=1)
    r = np.nan_to_num(r, nan=0.0)
    j = np.argmax(r, axis=1)
    return np.where(undefined, np.nan, r[np.arange(len(r)), j]), j


def _margin(margin: float) -> float:
    if not (np.isfinite(margin) and 0.0 < margin <= 1.0):
        raise PlannerError(f"margin: must be in (0, 1], got {margin}")
    return float(margin)


def feed_scale(model: str | URModel, q, t, margin: float = 1.0) -> float:
    """Factor by which to scale the feed (and so every speed) to keep joint speeds within limits.

    Scaling the feed by f stretches the sample times by 1 / f along the same path, so joint speeds
    scale by f.

    Parameters
    ----------
    model : str or URModel
    q : array_like, shape (n, 6)
        Joint trajectory in rad (rows of NaN: unreachable samples, ignored).
    t : array_like, shape (n,)
        Sample times in s.
    margin : float in (0, 1]
        Fraction of the speed limits to use (e.g. 0.9 keeps 10 % reserve).

    Returns
    -------
    float
        ``min(1, margin / max_ij |qdot_ij| / limit_j)``; 1 if the trajectory is already slow enough.
    """
    m = get_model(model)
    q, t = _trajectory(q, t)
    peak = float(_speed_ratios(m, q, t).max(initial=0.0))
    margin = _margin(margin)
    return 1.0 if peak <= margin else margin / peak


def feed_scale_profile(model: str | URModel, q, t, margin: float = 1.0) -> np.ndarray:
    """Per-sample feed factor (n,): the local version of :func:`feed_scale`.

    Sample i gets ``min(1, margin / r)`` with r the largest speed ratio of the intervals on either
    side of it, so the planner can lower the feed only where a joint would be too fast.
    """
    m = get_model(model)
    q, t = _trajectory(q, t)
    margin = _margin(margin)
    r = _speed_ratios(m, q, t).max(axis=1, initial=0.0)
    local = np.zeros(len(q))
    local[:-1] = r
    local[1:] = np.maximum(local[1:], r)
    with np.errstate(divide="ignore"):
        return np.where(local <= margin, 1.0, margin / local)


def check_reachability(
    model: str | URModel,
    q,
    t,
    *,
    arc_length=None,
    span=None,
    margin: float = 1.0,
) -> ReachabilityReport:
    """Check a joint trajectory against the model's joint position and speed limits.

    Parameters
    ----------
    model : str or URModel
    q : array_like, shape (n, 6)
        Joint positions in rad (continuous); rows of NaN are unreachable samples.
    t : array_like, shape (n,)
        Strictly increasing sample times in s.
    arc_length : array_like, shape (n,), optional
        Arc length of each sample along the path (m), quoted in the report.
    span : array_like of int, shape (n,), optional
        Waypoint span index of each sample, quoted in the report.
    margin : float in (0, 1]
        Passed to the feed factor in the report (speed violations are against the full limits).

    Returns
    -------
    ReachabilityReport
    """
    m = get_model(model)
    q, t = _trajectory(q, t)
    n = len(q)
    s = None if arc_length is None else np.asarray(arc_length, dtype=float)
    if s is not None and s.shape != (n,):
        raise PlannerError(f"arc_length: expected shape ({n},), got {s.shape}")
    sp = None if span is None else np.asarray(span)
    if sp is not None and sp.shape != (n,):
        raise PlannerError(f"span: expected shape ({n},), got {sp.shape}")

    unreachable = np.isnan(q).all(axis=1)
    lo, hi = m.lower, m.upper
    pos_bad = (q < lo) | (q > hi)  # False on NaN rows
    ratio = _speed_ratios(m, q, t)
    speed_bad = np.zeros((n, 6), dtype=bool)
    speed_bad[1:] = ratio > 1.0
    per_kind = (unreachable, pos_bad.any(axis=1), speed_bad.any(axis=1))

    first: Violation | None = None
    candidates = [(int(np.argmax(mask)), k) for k, mask in enumerate(per_kind) if mask.any()]
    if candidates:
        i, k = min(candidates)
        kind = _KINDS[k]
        at = None if s is None else float(s[i])
        span = None if sp is None else int(sp[i])
        if kind == "unreachable":
            first = Violation(kind, i, float(t[i]), None, float("nan"), float("nan"), arc_length=at, span=span)
        elif kind == "position":
            excess = np.where(q[i] > hi, q[i] - hi, lo - q[i])
            j = int(np.argmax(np.where(pos_bad[i], excess, -np.inf)))
            limit = hi[j] if q[i, j] > hi[j] else lo[j]
            first = Violation(kind, i, float(t[i]), j, float(q[i, j]), float(limit), arc_length=at, span=span)
        else:
            j = int(np.argmax(ratio[i - 1]))
            speed = ratio[i - 1, j] * m.speed_limits[j]
            first = Violation(kind, i, float(t[i]), j, float(speed), float(m.speed_limits[j]), arc_length=at, span=span)

    peak = float(ratio.max(initial=0.0))
    margin = _margin(margin)
    scale = 1.0 if peak <= margin else margin / peak
    counts = tuple(int(mask.sum()) for mask in per_kind)
    if first is None:
        message = (
            f"{m.name}: all {n} samples reachable within joint position and speed limits "
            f"(peak joint speed {100 * peak:.3g} % of its limit)"
        )
    else:
        message = f"{m.name}: {first.describe()}"
        message += (
            f"; in total {counts[0]} unreachable, {counts[1]} outside position limits, "
            f"{counts[2]} too fast of {n} samples"
        )
        if counts[2]:
            message += f"; scale the feed by {scale:.4g} to respect joint speed limits"
    return ReachabilityReport(
        ok=first is None,
        first=first,
        n_unreachable=counts[0],
        n_position=counts[1],
        n_speed=counts[2],
        max_speed_ratio=peak,
        feed_scale=scale,
        message=message,
    )


def check_poses(
    model: str | URModel,
    poses,
    t,
    q_start=None,
    *,
    tcp=None,
    arc_length=None,
    span=None,
    margin: float = 1.0,
) -> tuple[np.ndarray, ReachabilityReport]:
    """Inverse kinematics along a pose stream, then :func:`check_reachability`.

    Parameters
    ----------
    model, q_start, tcp
        As for :func:`planner.kinematics.inverse_path`.
    poses : array_like, shape (n, 6)
        Tool poses ``[x, y, z, rx, ry, rz]`` (m, rotation vector) in the base frame.
    t, arc_length, span, margin
        As for :func:`check_reachability`.

    Returns
    -------
    q : ndarray, shape (n, 6)
        Joint trajectory (rows of NaN where unreachable).
    report : ReachabilityReport
    """
    q = inverse_path(model, poses, q_start, tcp=tcp, allow_unreachable=True)
    return q, check_reachability(model, q, t, arc_length=arc_length, span=span, margin=margin)
