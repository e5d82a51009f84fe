"""Lower the feed locally, only where a sampled trajectory is too fast, and check again.

:func:`lower_feed_locally` takes a profile planned without caps and a ``measure`` callback that samples a
profile (e.g. poses at the controller rate and inverse kinematics) and rates every sample interval
(largest joint speed / limit). Each round caps the too-fast intervals (:func:`planner.motion.caps.caps_from_ratios`),
tightens the caps so far with them and re-plans (:func:`planner.motion.feed.cap_feed`), until nothing is
too fast, the caps stop changing (everything too fast is at the floor) or the rounds run out. The
outcome says whether the last trajectory is within the limits: never an infeasible one silently.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from planner.motion.caps import DEFAULT_FLOOR, DEFAULT_MARGIN, DEFAULT_ROUNDS, FeedCaps, cap_windows, caps_from_ratios
from planner.motion.feed import cap_feed
from planner.motion.limits import MotionInputError
from planner.motion.profile import FeedProfile


@dataclass(frozen=True)
class Measurement:
    """A sampled trajectory's speed figures, for :func:`lower_feed_locally`.

    Attributes
    ----------
    s, t : ndarray (n,)
        Arc length (m) and time (s) of every sample.
    ratio : ndarray (n - 1,)
        Largest |speed| / limit of every sample interval (NaN: unusable, e.g. next to an unreachable
        sample; then nothing is capped).
    tag : ndarray (n - 1,) of int
        What is fastest on every interval (the joint index).
    data : object
        Anything the caller wants back with the final profile (e.g. its pose stream and joints).
    """

    s: np.ndarray
    t: np.ndarray
    ratio: np.ndarray
    tag: np.ndarray
    data: object = None


@dataclass(frozen=True, eq=False)
class LoweredFeed:
    """Outcome of :func:`lower_feed_locally`.

    Attributes
    ----------
    profile : FeedProfile
        The last profile planned (the reference itself if nothing was too fast).
    measurement : Measurement
        Its measurement.
    caps : FeedCaps
        The caps it was planned with.
    windows : tuple of CapWindow
        Where the caps lower the feed, with the factors.
    rounds : int
        Re-planning rounds made.
    ok : bool
        Whether the last measurement is within the limits (every ratio <= 1).
    floored : bool
        Whether some cap is held up by the floor.
    """

    profile: FeedProfile
    measurement: Measurement
    caps: FeedCaps
    windows: tuple
    rounds: int
    ok: bool
    floored: bool


def lower_feed_locally(
    reference: FeedProfile,
    measure: Callable[[FeedProfile], Measurement],
    *,
    span_bounds=None,
    margin: float = DEFAULT_MARGIN,
    floor: float = DEFAULT_FLOOR,
    rounds: int = DEFAULT_ROUNDS,
) -> LoweredFeed:
    """Lower the feed of ``reference`` only where ``measure`` finds intervals too fast, then re-check.

    See the module doc. Speeds only drop from round to round.

    Parameters
    ----------
    reference : FeedProfile
        The profile planned without caps.
    measure : callable FeedProfile -> Measurement
        Samples a profile (e.g. poses at the controller rate, inverse kinematics) and rates it.
    span_bounds : ndarray (N,), optional
        Arc lengths of the waypoints, to name the spans of the windows.
    margin, floor : float
        See :func:`planner.motion.caps.caps_from_ratios`.
    rounds : int
        Re-planning rounds at most.

    Returns
    -------
    LoweredFeed
    """
    if not isinstance(rounds, int | np.integer) or rounds < 0:
        raise MotionInputError("rounds", f"must be an integer >= 0, got {rounds!r}")
    caps, profile, floored = FeedCaps.none(reference.length), reference, False
    m = measure(profile)
    done = 0
    while done < rounds and np.isfinite(m.ratio).all() and (m.ratio > 1.0).any():
        new, fl = caps_from_ratios(m.s, m.t, m.ratio, m.tag, reference, margin=margin, floor=floor)
        tighter = caps.tighten(new)
        if tighter.same_as(caps):  # everything too fast is already at the floor
            floored = True
            break
        caps, floored = tighter, floored or fl
        profile = cap_feed(reference, caps)
        m = measure(profile)
        done += 1
    ok = bool(np.nan_to_num(m.ratio, nan=0.0).max(initial=0.0) <= 1.0)
    return LoweredFeed(profile, m, caps, cap_windows(caps, reference, span_bounds, floor), done, ok, floored)
