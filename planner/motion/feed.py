"""Planning the feed along a path: per-span feeds, speed/acceleration/jerk limits, angular speed limit.

The commanded feed is piecewise constant in arc length ("levels"): the span feeds (NaN: the job's
feed), capped by the speed limit and, where the tool frame turns fast, by the angular speed limit
(|omega| = v |dR/ds|, so v <= omega_max / |dR/ds|). The tool cruises on each level at a plateau speed
and changes speed by jerk-limited S-curves (:mod:`planner.motion.scurve`) that never exceed the
commanded feed: a slow-down ends where the slower level starts, a speed-up starts where the faster
level starts. Plateau speeds come from a forward and a backward pass (the speed reachable within each
level) and, at local peaks, from the largest speed whose speed-up and slow-down both fit in the level.
Feed caps on arc-length windows (:mod:`planner.motion.caps`) lower the commanded feed further where
given (``plan_feed(..., caps=...)``, or :func:`cap_feed` on a planned profile).
"""

from __future__ import annotations

import numpy as np

from planner.motion import scurve
from planner.motion.caps import FeedCaps, apply_caps
from planner.motion.evaluator import span_bounds
from planner.motion.limits import MotionInputError, MotionLimits, positive
from planner.motion.orientation import Orientation, orientation_rate
from planner.motion.profile import FeedProfile
from planner.validation import ArgumentError, as_floats


def _feeds(values, name: str) -> np.ndarray:
    """Feeds as floats, m/s: NaN (unknown: the job's feed) passes, inf and non-numbers are refused by name."""
    try:
        f = as_floats(values, name)
    except ArgumentError as exc:
        raise MotionInputError(name, f"{str(exc).partition(': ')[2]} (NaN for the job's feed)") from None
    bad = np.isinf(f)
    if bad.any():
        i = np.unravel_index(int(np.argmax(bad)), f.shape)
        raise MotionInputError(name + "".join(f"[{j}]" for j in i), f"must be finite or NaN, got {f[i]}")
    return f


def span_feeds_from_point_feeds(feeds) -> np.ndarray:
    """Per-span feeds (n - 1,) from per-point feeds (n,) of the motion *into* each point.

    ``planner.io.Toolpath.feeds[i]`` is the feed of the move into point i, so span i (from point i
    to point i + 1) runs at ``feeds[i + 1]``; NaN (unknown) stays NaN (the job's feed applies).
    """
    f = _feeds(feeds, "feeds")
    if f.ndim != 1 or f.size < 2:
        raise MotionInputError("feeds", f"expected one feed per point (n >= 2,), got shape {f.shape}")
    return f[1:].copy()


#: Angular speed caps are rounded down to powers of this ratio.
_CAP_STEP = 1.01


def _span_bounds(path) -> tuple[float, np.ndarray]:
    """(length, arc lengths of the waypoints) of a path, or of a bare length."""
    if isinstance(path, int | float | np.floating | np.integer):
        L = positive(path, "path")
        return L, np.array([0.0, L])
    L = positive(getattr(path, "length", np.nan), "path.length")
    return L, span_bounds(path)


def _span_commands(feed: float, limits: MotionLimits, span_feeds, n_spans: int) -> np.ndarray:
    if span_feeds is None:
        f = np.full(n_spans, feed)
    else:
        f = _feeds(span_feeds, "span_feeds")
        if f.shape != (n_spans,):
            raise MotionInputError("span_feeds", f"expected one feed per span, shape ({n_spans},), got {f.shape}")
        bad = np.isinf(f) | (f <= 0.0)
        if bad.any():
            i = int(np.argmax(bad))
            raise MotionInputError(f"span_feeds[{i}]", f"feed must be finite and > 0 (NaN: job feed), got {f[i]}")
        f = np.where(np.isnan(f), feed, f)
    return np.minimum(f, limits.speed)


def _angular_caps(orientation, omega: float, b: np.ndarray, pieces: int, rounds: int = 10,
                  rtol: float = 0.02) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Piece bounds (M + 1,) splitting every span, the feed cap (M,) and the span (M,) of each piece.

    The rate |dR/ds| is sampled at ``pieces`` + 1 nodes per span (stencils inside the span), then
    pieces whose end rates differ by more than ``rtol`` are halved, ``rounds`` times at most, so
    that nodes are dense where the rate changes. A piece's cap uses the largest rate at its own ends
    and at its neighbours' ends in the same span, raised by ``rtol``: a margin for a peak between
    nodes (the cap may be up to ``rtol`` lower than needed, never higher).
    """
    n_spans = b.size - 1
    frac = np.linspace(0.0, 1.0, pieces + 1)
    pos = (b[:-1, None] + (b[1:] - b[:-1])[:, None] * frac).ravel()
    spn = np.repeat(np.arange(n_spans), pieces + 1)
    rate = orientation_rate(orientation, pos, b[spn], b[spn + 1])
    for _ in range(rounds):
        same = spn[1:] == spn[:-1]
        hi_r = np.maximum(rate[1:], rate[:-1])
        split = same & (np.abs(rate[1:] - rate[:-1]) > rtol * hi_r)
        if not split.any():
            break
        mid = 0.5 * (pos[1:] + pos[:-1])[split]
        ms = spn[:-1][split]
        mr = orientation_rate(orientation, mid, b[ms], b[ms + 1])
        pos, spn, rate = (np.concatenate(x) for x in ((pos, mid), (spn, ms), (rate, mr)))
        order = np.lexsort((pos, spn))
        pos, spn, rate = pos[order], spn[order], rate[order]
    same = spn[1:] == spn[:-1]  # piece j runs from node j to node j + 1 (same span)
    j = np.flatnonzero(same)
    left = np.where((j > 0) & (spn[np.maximum(j - 1, 0)] == spn[j]), rate[np.maximum(j - 1, 0)], 0.0)
    jr = np.minimum(j + 2, pos.size - 1)
    right = np.where(spn[jr] == spn[j], rate[jr], 0.0)
    # a smooth peak between nodes whose rates differ by < rtol exceeds them by about rtol / 4 at most
    kmax = np.maximum.reduce((left, rate[j], rate[j + 1], right)) * (1.0 + rtol)
    with np.errstate(divide="ignore"):
        cap = np.where(kmax > 0.0, omega / kmax, np.inf)
        # round down to steps of 1 %: neighbouring pieces with nearly the same cap merge into one level
        # (fewer, longer levels: fewer speed changes, at most 1 % slower than the exact cap)
        cap = np.where(np.isfinite(cap), _CAP_STEP ** np.floor(np.log(cap) / np.log(_CAP_STEP)), np.inf)
    bounds = np.concatenate((pos[j], b[-1:]))
    return bounds, cap, spn[j]


def _plateaus(ell: np.ndarray, V: np.ndarray, A: float, J: float) -> np.ndarray:
    """Cruise speed on every level: forward pass, backward pass, then the peaks."""
    c = V.astype(float).copy()
    prev = 0.0
    for k in range(c.size):  # forward: speed reachable from the previous level within this one
        if c[k] > prev:
            c[k] = min(c[k], scurve.reach(prev, float(ell[k]), A, J))
        prev = c[k]
    nxt = 0.0
    for k in range(c.size - 1, -1, -1):  # backward: speed from which the next level is reachable
        if c[k] > nxt:
            c[k] = min(c[k], scurve.reach(nxt, float(ell[k]), A, J))
        nxt = c[k]
    left = np.concatenate(([0.0], c[:-1]))
    right = np.concatenate((c[1:], [0.0]))
    peak = (c > left) & (c > right)
    over = peak & (scurve.distance(left, c, A, J) + scurve.distance(c, right, A, J) > ell)
    if over.any():  # speed-up and slow-down both in the level: bisection for the largest that fits
        lo = np.maximum(left[over], right[over])
        hi = c[over].copy()
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            fits = scurve.distance(left[over], mid, A, J) + scurve.distance(mid, right[over], A, J) <= ell[over]
            lo = np.where(fits, mid, lo)
            hi = np.where(fits, hi, mid)
            if np.all(hi - lo <= 2.0 * np.finfo(float).eps * hi):
                break
        c[over] = lo
    return c


def _phases(bounds: np.ndarray, c: np.ndarray, A: float, J: float) -> tuple[np.ndarray, ...]:
    """Phase table (durations, s0, v0, a0, jerk), shape (m, 7) each, of the levels in order."""
    ell = np.diff(bounds)
    left = np.concatenate(([0.0], c[:-1]))
    right = np.concatenate((c[1:], [0.0]))
    has_in, has_out = left < c, right < c
    d_in = np.where(has_in, scurve.distance(left, c, A, J), 0.0)
    d_out = np.where(has_out, scurve.distance(c, right, A, J), 0.0)
    pin = scurve.transition_phases(left, c, bounds[:-1], A, J)
    pout = scurve.transition_phases(c, right, bounds[1:] - d_out, A, J)
    cruise_len = np.maximum(ell - d_in - d_out, 0.0)
    cruise = (cruise_len / c, bounds[:-1] + d_in, c, np.zeros_like(c), np.zeros_like(c))
    out = []
    for q, (a, mid, b) in enumerate(zip(pin, cruise, pout, strict=True)):
        if q == 0:  # durations: drop the transitions a level does not have
            a, b = a * has_in[:, None], b * has_out[:, None]
        out.append(np.concatenate((a, mid[:, None], b), axis=1))
    return tuple(out)


def plan_feed(
    path,
    feed: float,
    limits: MotionLimits,
    *,
    span_feeds=None,
    orientation: Orientation | None = None,
    angular_pieces: int = 8,
    caps: FeedCaps | None = None,
) -> FeedProfile:
    """Jerk-limited feed profile along a path: start and end at rest, cruise at the commanded feeds.

    Parameters
    ----------
    path : PHSpline or float
        The path (its ``length``, and ``waypoint_knots`` / ``arc_length`` for the spans), or just a
        length in metres (one span).
    feed : float
        The job's feed (TCP speed), m/s; capped by ``limits.speed``.
    limits : MotionLimits
        Speed, acceleration, jerk and (optional) angular speed limits.
    span_feeds : array_like (N - 1,), optional
        Feed of every span between consecutive waypoints, m/s; NaN where the job's feed applies (see
        :func:`span_feeds_from_point_feeds` for per-point feeds as the readers give them).
    orientation : callable s (n,) -> (n, 3, 3), optional
        Tool frames along the path; needed when ``limits.angular_speed`` is set.
    angular_pieces : int
        Initial pieces per span on which the angular speed cap is constant (|dR/ds| is sampled at
        their ends, and pieces are halved where it changes by more than 2 %).
    caps : FeedCaps, optional
        Upper bounds of the feed on arc-length windows (:mod:`planner.motion.caps`, e.g. where robot
        joints would be too fast): the commanded feed is lowered to them where they are lower.

    Returns
    -------
    FeedProfile

    Raises
    ------
    MotionInputError
        A non-positive or non-finite feed, limit or span feed (naming it and its index), span feeds
        not one per span, an angular limit without an orientation.
    """
    L, b = _span_bounds(path)
    if not isinstance(limits, MotionLimits):
        raise MotionInputError("limits", f"must be a MotionLimits, got {type(limits).__name__}")
    feed = positive(feed, "feed")
    cmd = _span_commands(feed, limits, span_feeds, b.size - 1)
    if limits.angular_speed is not None:
        if orientation is None:
            raise MotionInputError("orientation", "is needed when limits.angular_speed is set")
        if not isinstance(angular_pieces, int | np.integer) or angular_pieces < 1:
            raise MotionInputError("angular_pieces", f"must be an integer >= 1, got {angular_pieces!r}")
        bounds, cap, piece_span = _angular_caps(orientation, limits.angular_speed, b, int(angular_pieces))
        V = np.minimum(cmd[piece_span], cap)
    else:
        bounds, V = b, cmd
    if caps is not None:
        bounds, V = apply_caps(bounds, V, caps)
    return profile_from_levels(bounds, V, L, limits)


def cap_feed(profile: FeedProfile, caps: FeedCaps) -> FeedProfile:
    """``profile`` re-planned with its commanded feed lowered to ``caps`` where they are lower.

    Same limits and length; the levels (span feeds, angular speed caps) are the profile's own, so this
    is cheap. Outside the caps and the speed changes into and out of them nothing changes.
    """
    if not isinstance(profile, FeedProfile):
        raise MotionInputError("profile", f"must be a FeedProfile, got {type(profile).__name__}")
    bounds, V = apply_caps(profile.level_bounds, profile.commanded, caps)
    return profile_from_levels(bounds, V, profile.length, profile.limits)


def profile_from_levels(bounds: np.ndarray, V: np.ndarray, length: float, limits: MotionLimits) -> FeedProfile:
    """The jerk-limited profile of commanded levels: feed V[k] (m/s) on [bounds[k], bounds[k + 1]] (m).

    Neighbouring levels with the same feed are merged; the tool starts and ends at rest.
    """
    A, J = limits.acceleration, limits.jerk
    keep = np.concatenate(([True], V[1:] != V[:-1]))  # merge neighbours with the same command
    V = V[keep]
    bounds = np.concatenate((bounds[:-1][keep], bounds[-1:]))
    c = _plateaus(np.diff(bounds), V, A, J)
    dur, s0, v0, a0, jerk = (x.ravel() for x in _phases(bounds, c, A, J))
    live = dur > 0.0
    t = np.concatenate(([0.0], np.cumsum(dur[live])))
    return FeedProfile(t, s0[live], v0[live], a0[live], jerk[live], length, limits, bounds, V, c)
