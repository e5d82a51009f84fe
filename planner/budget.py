"""The work budget of a job, computed from the toolpath before any fitting or sampling.

A mistyped feed (``FEDRAT/1e-300``), a unit mistake (a file in mm read as m, coordinates scaled by 1e6) or
an absurd rate would otherwise go straight into sampling and die minutes later in an allocation of
terabytes. :func:`check_budget` estimates, from the polyline lengths, the feeds, the rate and the arcs still
to be linearised, the number of poses of the trajectory and the points the fit will see, and refuses the
job in well under a second with one line naming the cause and its place (file line) when it exceeds the
limits of the settings (``max_poses``, ``max_points``) or leaves the range of any real robot cell
(:data:`MAX_COORDINATE`, :data:`MIN_FEED`, :data:`MAX_FEED`).

The estimate is a lower bound of the work: every span at its feed (capped by the speed limit), without the
acceleration phases, and every dwell's seconds; the real count is at most a few samples per move longer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from planner.errors import PlannerError
from planner.settings import MAX_FEED, MIN_FEED  # the feed range of the settings, also for the file's feeds

#: Coordinates beyond this distance from the part origin (m) are no robot cell (a UR reaches 1.3 m, a robot on a
#: track or gantry tens of metres): a unit mistake, e.g. a CLSF in mm read with --units m.
MAX_COORDINATE = 100.0
#: Bytes per pose of the CSV trajectory with joints (for the figure shown to the user).
CSV_BYTES_PER_POSE = 180


class BudgetError(PlannerError):
    """The job would exceed its work budget or leaves the range of a robot cell (the message says where)."""


@dataclass(frozen=True)
class Budget:
    """What a job will cost, estimated before planning.

    Attributes
    ----------
    length : float
        Length of the polyline (cuts and rapids), m.
    seconds : float
        Motion time at the feeds (lower bound: no acceleration phases), s.
    poses : float
        Poses of the trajectory at the settings' rate.
    points : int
        Points the fit will see after the arcs are linearised (estimate).
    """

    length: float
    seconds: float
    poses: float
    points: int

    @property
    def csv_bytes(self) -> float:
        """Approximate size of the CSV trajectory with joints, bytes."""
        return self.poses * CSV_BYTES_PER_POSE


def _check_arguments(toolpath, settings) -> None:
    """PlannerError unless ``toolpath`` is a Toolpath and ``settings`` checked PlanSettings."""
    from planner.io.toolpath import Toolpath
    from planner.settings import PlanSettings

    if not isinstance(toolpath, Toolpath):
        raise PlannerError(f"toolpath must be a planner.io.Toolpath (read_toolpath), got {type(toolpath).__name__}")
    if not isinstance(settings, PlanSettings) or settings.arc_tolerance is None:
        raise PlannerError(f"settings must be checked PlanSettings (PlanSettings(...).checked()), got "
                           f"{type(settings).__name__}")


def _per_minute(v: float, units: str) -> str:
    """A feed (m/s) per minute in the file's length unit, as CAM files give feeds."""
    if units == "inch":
        return f"{v / 0.0254 * 60.0:.3g} in/min"
    if units == "m":
        return f"{v * 60.0:.3g} m/min"
    return f"{v * 6e4:.3g} mm/min"


def _where(toolpath, i: int) -> str:
    return f"{toolpath.source} line {int(toolpath.lines[i])}"


def _arc_points(toolpath, tolerance: float) -> int:
    """Points the arcs (estimate) and NURBS records (their sampling, counted) of the toolpath will add when
    linearised within ``tolerance``."""
    from planner.io.toolpath import NURBS_SAMPLING_FRACTION, Arc, Nurbs

    total = 0.0
    p = toolpath.points
    for arc in toolpath.events:
        if isinstance(arc, Nurbs):
            total += max(len(arc.sample_parameters(tolerance * NURBS_SAMPLING_FRACTION)) - 2, 0)
            continue
        if not isinstance(arc, Arc):
            continue
        c, n = np.asarray(arc.centre, float), np.asarray(arc.axis, float)
        v0, v1 = p[arc.start] - c, p[arc.index] - c
        v0, v1 = v0 - (v0 @ n) * n, v1 - (v1 @ n) * n
        r = max(float(np.linalg.norm(v0)), float(np.linalg.norm(v1)))
        if not (math.isfinite(r) and r > 0.0):
            continue
        ang = math.atan2(float(np.cross(v0, v1) @ n), float(v0 @ v1)) % (2.0 * math.pi) or 2.0 * math.pi
        step = 2.0 * math.acos(max(-1.0, 1.0 - min(tolerance / r, 2.0)))
        total += ang / max(step, 1e-300)
    return int(min(total, 1e18))


def _dwells(toolpath) -> list:
    """The dwell events of positive, finite length (the tool waits that many seconds)."""
    return [e for e in toolpath.events if e.kind == "dwell" and math.isfinite(e.value) and e.value > 0.0]


def estimate(toolpath, settings) -> Budget:
    """The :class:`Budget` of a toolpath under checked, resolved settings (see :func:`check_budget`)."""
    _check_arguments(toolpath, settings)
    p = toolpath.points
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1) if len(p) > 1 else np.zeros(0)
    rapid = toolpath.rapid[1:]
    f = toolpath.feeds[1:] * settings.feed_override
    f = np.where(np.isnan(f), settings.feed * settings.feed_override, f)
    v = np.where(rapid, settings.rapid_speed, np.minimum(f, settings.limits.speed))
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        t = seg / v
    seconds = (float(np.sum(t)) if t.size else 0.0) + sum(e.value for e in _dwells(toolpath))
    points = len(p) + _arc_points(toolpath, settings.arc_tolerance)
    return Budget(float(seg.sum()) if seg.size else 0.0, seconds, seconds * settings.rate, points)


def check_budget(toolpath, settings) -> Budget:
    """Refuse a job that leaves the range of a robot cell or exceeds the settings' work limits.

    Parameters
    ----------
    toolpath : planner.io.Toolpath
        As read (arcs not yet linearised).
    settings : PlanSettings
        Checked and resolved (``max_poses``, ``max_points``, feeds, rate, arc tolerance).

    Returns
    -------
    Budget

    Raises
    ------
    BudgetError
        Naming the cause and its place, e.g. ``part.apt line 24: feed 1.7e-305 m/s is below 1 um/s`` or
        ``the path is 1.2e+06 m long ...: are the units right? (the file says mm)``.
    """
    _check_arguments(toolpath, settings)
    p = toolpath.points
    if len(p):
        far = np.abs(p).max(axis=1)
        i = int(np.argmax(far))
        if far[i] > MAX_COORDINATE:
            raise BudgetError(f"{_where(toolpath, i)}: coordinate {far[i]:.3g} m is beyond any robot cell "
                              f"({MAX_COORDINATE:g} m from the part origin): are the units right? "
                              f"(the file says {toolpath.units})")
    f = toolpath.feeds[1:]
    cut = ~toolpath.rapid[1:] & np.isfinite(f)
    for bad, what in ((cut & (f * settings.feed_override < MIN_FEED), f"below {MIN_FEED * 1e6:g} um/s"),
                      (cut & (f * settings.feed_override > MAX_FEED), f"above {MAX_FEED:g} m/s")):
        if bad.any():
            i = int(np.argmax(bad)) + 1
            v = f[i - 1] * settings.feed_override
            raise BudgetError(f"{_where(toolpath, i)}: feed {v:.3g} m/s is {what} ({_per_minute(v, toolpath.units)}): "
                              f"no robot cell cuts at that feed (are the feed units right?)")
    b = estimate(toolpath, settings)
    if b.points > settings.max_points:
        raise BudgetError(f"{toolpath.source}: the arcs would be linearised into about {b.points:.3g} points "
                          f"(more than max_points = {settings.max_points:g}): is arc_tolerance "
                          f"({settings.arc_tolerance:.3g} m) right?")
    if b.poses > settings.max_poses:
        seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
        cut_v = np.where(np.isnan(f), settings.feed, f) * settings.feed_override
        v = np.where(toolpath.rapid[1:], settings.rapid_speed, np.minimum(cut_v, settings.limits.speed))
        i = int(np.argmax(seg / v)) + 1
        share = seg[i - 1] / v[i - 1] * settings.rate
        waits = _dwells(toolpath)
        longest = max(waits, key=lambda e: e.value, default=None)
        if longest is not None and longest.value * settings.rate >= 0.5 * b.poses:
            cause = (f"{toolpath.source} line {longest.line}: a dwell of {longest.value:.3g} s would need "
                     f"{longest.value * settings.rate:.3g} poses")
        elif share >= 0.5 * b.poses:
            cause = f"{_where(toolpath, i)}: {seg[i - 1]:.3g} m at {v[i - 1]:.3g} m/s would need {share:.3g} poses"
        elif b.length > 100.0:
            cause = f"the path is {b.length:.3g} m long: are the units right? (the file says {toolpath.units})"
        else:
            cause = f"{b.length:.3g} m of path at the feeds is {b.seconds:.3g} s of motion"
        raise BudgetError(f"{cause}; the job would be about {b.poses:.3g} poses at {settings.rate:g} Hz "
                          f"({b.seconds / 3600:.3g} h, about {b.csv_bytes / 1e9:.3g} GB of CSV), more than "
                          f"max_poses = {settings.max_poses:g}")
    return b
