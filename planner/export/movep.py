"""Targets and blend radii for a ``movep`` program that follows the path within a tolerance.

``movep`` moves the tool at constant speed along straight lines between targets and blends around each
target with a circular arc inside a sphere of radius r (UR Script Manual, movep; not covered by
shared/UR-PROTOCOLS.md). Its deviation from the planned path is at most the deviation of the
polyline of targets from the path plus the corner each blend cuts:

- targets: the path is split at the feed levels and at I/O trigger points, then every piece whose
  chord strays more than tolerance / 2 from the path (checked at 8 interior points, or more: at most 10
  tolerances apart), or whose
  orientation strays more than ``angle_tolerance`` from the rotation interpolated along the chord, is
  halved, until none does (only the new halves are checked again);
- blend radius r at a target where the polyline turns by alpha: a blend of radius r cuts the corner
  by about r sin(alpha / 2) / 2 (the midpoint of the quadratic blend between the points r before and
  after the corner), so r <= tolerance / sin(alpha / 2); also r <= half of either neighbouring chord
  (blends must not overlap), and at a target that carries an I/O switch r <= v * event_time_tolerance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.export.header import ExportError
from planner.motion.events import ScheduledEvent, schedule_events
from planner.motion.limits import positive
from planner.motion.stream import poses_at_length
from planner.rotations import rotation_angle, slerp_matrices

_CHECKS = 8
#: Largest distance between two check points of a piece, in tolerances: 8 evenly spaced points missed a bend of the
#: path 0.3 mm from the start of a 7.9 mm chord of the NX job (pass 368, line 10697): the chord was 0.0142 mm from
#: the path there (0.0048 mm at the checks), and so was the program's motion (tolerance 0.01 mm).
_SPACING = 10.0
#: Check points near each end of a piece, spacing / 2 ... spacing / 32 from it.
_END_CHECKS = 5
#: Most check points of one piece: a longer piece is halved unchecked (a straight line of over 1,000 tolerances).
_MOST_CHECKS = 1024


@dataclass(frozen=True, eq=False)
class MovePPlan:
    """Targets of a ``movep`` program.

    Attributes
    ----------
    s : ndarray (m,)
        Arc length of each target along the path (0 first, the path length last), m.
    poses : ndarray (m, 6)
        TCP poses p[x, y, z, rx, ry, rz] of the targets in the base frame.
    radii : ndarray (m,)
        Blend radius at each target, m (0 at the first and last).
    speeds : ndarray (m,)
        Tool speed of the move into each target, m/s (0 for the first, which is the start).
    deviation : float
        Largest distance of the checked path points from the polyline of targets, m.
    angle_deviation : float
        Largest angle between the path's tool frame and the rotation interpolated along the chord, rad.
    events : tuple of ScheduledEvent
        I/O events in time order; ``index`` is the target after whose move the switch is issued.
    tolerance : float
        The path tolerance the plan meets, m.
    accelerations : ndarray (m,) or None
        Tool acceleration ``a`` of the move into each target, m/s^2, where moves were slowed for the joints' limits
        (:mod:`planner.export.move_check`); None: the program's one acceleration for every move.
    """

    s: np.ndarray
    poses: np.ndarray
    radii: np.ndarray
    speeds: np.ndarray
    deviation: float
    angle_deviation: float
    events: tuple
    tolerance: float
    accelerations: np.ndarray | None = None


def _checks(a: np.ndarray, b: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Check points of the pieces [a, b] (k,) of arc length: at least :data:`_CHECKS` interior points of each, evenly
    spaced, and no further apart than ``spacing`` (m). Returns (arc length of each check (N,), its piece (N,), the
    index of each piece's first check (k,), the pieces too long to be checked so with :data:`_MOST_CHECKS` (k,
    bool): halved unchecked)."""
    ell = b - a
    need = np.ceil(np.minimum(ell / spacing, 2.0 * _MOST_CHECKS))
    long = need > _MOST_CHECKS + 1
    n = np.where(long, _CHECKS, np.maximum(_CHECKS, need - 1)).astype(np.int64)
    piece = np.repeat(np.arange(a.size), n)
    first = np.cumsum(n) - n
    frac = (np.arange(piece.size) - first[piece] + 1) / (n[piece] + 1)
    # and near both ends, at distances spacing / 2^k (k = 1..5; at most 5/12 of the piece): a bend of the path just
    # after a target, where the chord's distance from the path rises from 0, narrower than the even spacing
    e = np.minimum(spacing * 0.5 ** np.arange(1, _END_CHECKS + 1)[None, :] / np.maximum(ell, 1e-300)[:, None],
                   np.arange(1, _END_CHECKS + 1)[None, :] / (2 * _END_CHECKS + 2))  # (k, 5) fractions
    frac = np.concatenate((frac, e.ravel(), 1.0 - e.ravel()))
    ends = np.repeat(np.arange(a.size), _END_CHECKS)
    piece = np.concatenate((piece, ends, ends))
    order = np.argsort(piece, kind="stable")
    piece, frac = piece[order], frac[order]
    first = np.cumsum(n + 2 * _END_CHECKS) - (n + 2 * _END_CHECKS)
    return a[piece] + ell[piece] * frac, piece, first, long


def _deviations(pa, Ra, pb, Rb, pc, Rc) -> tuple[np.ndarray, np.ndarray]:
    """Distance (N,) of the check points pc (N, 3) from their chords pa -> pb (N, 3), and the angle of their frames
    Rc (N, 3, 3) from the rotation interpolated from Ra to Rb (N, 3, 3) (each check with its piece's ends)."""
    d = pb - pa
    dd = np.maximum(np.einsum("ni,ni->n", d, d), 1e-300)
    lam = np.clip(np.einsum("ni,ni->n", pc - pa, d) / dd, 0.0, 1.0)
    dist = np.linalg.norm(pc - pa - lam[:, None] * d, axis=1)
    interp = slerp_matrices(Ra, Rb, lam[:, None])[:, 0]  # (N, 3, 3): slerp Ra -> Rb at the chord fractions
    return dist, rotation_angle(interp, Rc)


def plan_movep(path, orientation, profile, *, tolerance: float, angle_tolerance: float = np.radians(1.0),
               base=None, events=(), event_time_tolerance: float = 0.002, max_rounds: int = 40) -> MovePPlan:
    """Choose ``movep`` targets and blend radii so that the program follows the path within ``tolerance``.

    Parameters
    ----------
    path : PHSpline
    orientation : callable s -> (n, 3, 3)
        Tool frames in the part frame.
    profile : FeedProfile
        The time law: its commanded feeds set the move speeds, its timing places the I/O triggers.
    tolerance : float
        Largest distance of the programmed motion from the path, m.
    angle_tolerance : float
        Largest orientation error of the interpolated tool frame between targets, rad.
    base : pose (6,) or matrix (4, 4), optional
        Part frame in the robot base frame.
    events : sequence of IOEvent
    event_time_tolerance : float
        Largest timing error of an I/O switch from blending, s (limits the blend radius there).
    max_rounds : int
        Halving rounds before giving up.
    """
    tol = positive(tolerance, "tolerance")
    ang_tol = positive(angle_tolerance, "angle_tolerance")
    ev_tol = positive(event_time_tolerance, "event_time_tolerance")
    L = profile.length
    sched = schedule_events(events, profile, 1.0 / ev_tol, 1)
    trig = profile.s(np.array([e.time for e in sched])) if sched else np.zeros(0)
    S = np.unique(np.concatenate(([0.0, L], np.clip(profile.level_bounds, 0.0, L), trig)))
    a, b = S[:-1], S[1:]  # the pieces still to check: a piece once within tolerance is never checked again
    starts, dev, ang_dev = [], 0.0, 0.0
    for _ in range(max_rounds):
        k = a.size
        checks, piece, first, long = _checks(a, b, _SPACING * tol)
        p, R, _ = poses_at_length(path, orientation, np.concatenate((a, b, checks)), base=base)
        ends = k + piece
        dist, ang = _deviations(p[piece], R[piece], p[ends], R[ends], p[2 * k:], R[2 * k:])
        dist, ang = np.maximum.reduceat(dist, first), np.maximum.reduceat(ang, first)  # the largest of each piece
        bad = (dist > 0.5 * tol) | (ang > ang_tol) | long
        starts.append(a[~bad])
        dev, ang_dev = max(dev, float(dist[~bad].max(initial=0.0))), max(ang_dev, float(ang[~bad].max(initial=0.0)))
        if not bad.any():
            break
        c = 0.5 * (a[bad] + b[bad])
        a, b = np.concatenate((a[bad], c)), np.concatenate((c, b[bad]))
    else:
        n = sum(x.size for x in starts) + a.size
        raise ExportError(f"tolerance: the path could not be followed within {tol} m / {ang_tol} rad by "
                          f"{n + 1} movep targets after {max_rounds} halving rounds; raise the tolerance")
    S = np.unique(np.concatenate(starts + [np.array([L])]))
    _, _, poses = poses_at_length(path, orientation, S, base=base)
    pv = poses[:, :3]
    chord = np.diff(pv, axis=0)
    ell = np.linalg.norm(chord, axis=1)
    cosang = np.einsum("ni,ni->n", chord[:-1], chord[1:]) / np.maximum(ell[:-1] * ell[1:], 1e-300)
    half = np.sin(0.5 * np.arccos(np.clip(cosang, -1.0, 1.0)))
    speeds = np.concatenate(([0.0], profile.commanded_at(0.5 * (S[:-1] + S[1:]))))
    radii = np.zeros(S.size)
    with np.errstate(divide="ignore"):
        radii[1:-1] = np.minimum(0.5 * np.minimum(ell[:-1], ell[1:]), np.where(half > 0, tol / half, np.inf))
    where = np.clip(np.searchsorted(S, trig), 0, S.size - 1) if trig.size else np.zeros(0, int)
    for i in where:  # a switch after a blended move fires when the blend starts: keep it short
        radii[i] = min(radii[i], speeds[i] * ev_tol)
    radii[-1] = 0.0
    placed = tuple(ScheduledEvent(e.event, e.time, int(i)) for i, e in zip(where, sched, strict=True))
    return MovePPlan(S, poses, radii, speeds, dev, ang_dev, placed, tol)
