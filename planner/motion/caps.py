"""Feed caps on arc-length windows: lower the feed only where something (a robot joint) would be too fast.

A :class:`FeedCaps` is a piecewise-constant upper bound c(s) of the feed over [0, L] (m/s; +inf where
uncapped), each piece carrying an integer tag the caller chooses (the planner: the joint that set it).
:func:`cap_feed` (:mod:`planner.motion.feed`) re-plans a feed profile under caps (the commanded feed becomes
min(commanded, cap); slow-downs end where a capped piece starts, speed-ups start where it ends, so the
tool never exceeds a cap). :func:`caps_from_ratios` turns a sampled trajectory's speed ratios (how many
times too fast each sample interval is) into caps; :mod:`planner.motion.local_feed` iterates.

The ratio of an interval scales with the tool's speed along the same path (joint speed = dq/ds * ds/dt),
so an interval covered at mean speed v with ratio r > 1 needs a feed of at most v * margin / r there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.motion.limits import MotionInputError, finite_array
from planner.motion.profile import FeedProfile

#: Caps are rounded down to powers of this ratio: neighbouring intervals share levels (fewer speed
#: changes), at most 2 % slower than the exact cap.
CAP_STEP = 1.02
#: Fraction of the limit a capped interval is planned for (the rest covers sampling differences).
DEFAULT_MARGIN = 0.97
#: Lowest cap, as a fraction of the feed commanded without caps.
DEFAULT_FLOOR = 0.01
#: Re-planning rounds at most.
DEFAULT_ROUNDS = 8


def _dedupe(points: np.ndarray, length: float) -> np.ndarray:
    """Sorted unique break points in [0, length], neighbours closer than 1e-12 length merged, ends exact."""
    p = np.unique(np.clip(points, 0.0, length))
    p = p[np.concatenate(([True], np.diff(p) > 1e-12 * max(length, 1.0)))]
    p[0] = 0.0
    if p[-1] < length - 1e-12 * max(length, 1.0):
        p = np.append(p, length)
    p[-1] = length
    return p


@dataclass(frozen=True, eq=False)
class FeedCaps:
    """Piecewise-constant upper bound of the feed along a path.

    Attributes
    ----------
    bounds : ndarray (m + 1,)
        Increasing arc lengths (m) from 0 to the path length: piece k is [bounds[k], bounds[k + 1]].
    speed : ndarray (m,)
        Cap of every piece, m/s (+inf: no cap).
    tag : ndarray (m,) of int
        What set each cap (the caller's code; the planner uses the joint index), -1 where uncapped.
    """

    bounds: np.ndarray
    speed: np.ndarray
    tag: np.ndarray

    @property
    def length(self) -> float:
        """Length of the path, m."""
        return float(self.bounds[-1])

    @property
    def active(self) -> bool:
        """Whether any piece is capped."""
        return bool(np.isfinite(self.speed).any())

    @classmethod
    def none(cls, length: float) -> FeedCaps:
        """No cap anywhere on a path of ``length`` m."""
        return cls(np.array([0.0, float(length)]), np.array([np.inf]), np.array([-1]))

    @classmethod
    def on_intervals(cls, start, end, speed, tag, length: float) -> FeedCaps:
        """Caps on disjoint intervals [start[k], end[k]] (m, sorted, each shape (k,)), none elsewhere."""
        start, end = (np.asarray(x, dtype=float).ravel() for x in (start, end))
        speed = np.asarray(speed, dtype=float).ravel()
        tag = np.asarray(tag, dtype=int).ravel()
        if not (start.shape == end.shape == speed.shape == tag.shape):
            raise MotionInputError("caps", f"start, end, speed and tag differ in shape: {start.shape}, "
                                   f"{end.shape}, {speed.shape}, {tag.shape}")
        if start.size and ((end < start).any() or (start[1:] < end[:-1]).any()):
            raise MotionInputError("caps", "intervals must be sorted and disjoint")
        bad = np.isnan(speed) | (speed <= 0.0)
        if bad.any():
            i = int(np.argmax(bad))
            raise MotionInputError(f"caps[{i}]", f"speed must be > 0 (inf: no cap), got {speed[i]}")
        if not start.size:
            return cls.none(length)
        pts = _dedupe(np.concatenate(([0.0, float(length)], start, end)), float(length))
        mid = 0.5 * (pts[1:] + pts[:-1])
        k = np.maximum(np.searchsorted(start, mid, side="right") - 1, 0)
        inside = (mid >= start[k]) & (mid < end[k])
        return cls(pts, np.where(inside, speed[k], np.inf), np.where(inside, tag[k], -1))._merged()

    def at(self, s) -> tuple[np.ndarray, np.ndarray]:
        """(cap (n,) m/s, tag (n,)) at arc lengths s (n,)."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        k = np.clip(np.searchsorted(self.bounds, s, side="right") - 1, 0, self.speed.size - 1)
        return self.speed[k], self.tag[k]

    def tighten(self, other: FeedCaps) -> FeedCaps:
        """The pointwise lower of two caps on the same path (tag of the lower one)."""
        pts = _dedupe(np.concatenate((self.bounds, other.bounds)), self.length)
        mid = 0.5 * (pts[1:] + pts[:-1])
        (a, ta), (b, tb) = self.at(mid), other.at(mid)
        lower = b < a
        return FeedCaps(pts, np.where(lower, b, a), np.where(lower, tb, ta))._merged()

    def same_as(self, other: FeedCaps) -> bool:
        """Whether two caps are the same function (same pieces, speeds and tags)."""
        return (self.bounds.shape == other.bounds.shape and np.array_equal(self.bounds, other.bounds)
                and np.array_equal(self.speed, other.speed) and np.array_equal(self.tag, other.tag))

    def _merged(self) -> FeedCaps:
        """Neighbouring pieces with the same cap and tag merged."""
        keep = np.concatenate(([True], (self.speed[1:] != self.speed[:-1]) | (self.tag[1:] != self.tag[:-1])))
        return FeedCaps(np.concatenate((self.bounds[:-1][keep], self.bounds[-1:])), self.speed[keep], self.tag[keep])


@dataclass(frozen=True)
class CapWindow:
    """One stretch of the path where caps lower the feed below what is commanded there.

    Attributes
    ----------
    start, end : float
        Arc lengths (m) where the stretch starts and ends (the tool slows down before ``start`` and
        speeds up after ``end``).
    factor : float
        Lowest cap over the stretch as a fraction of the feed commanded there without caps (0..1).
    speed : float
        That lowest cap, m/s.
    tag : int
        What set the lowest cap (the planner: the joint index).
    first_span, last_span : int or None
        Waypoint spans the stretch touches (None without span bounds).
    floored : bool
        Whether the floor held a cap up (the measured need was lower still).
    """

    start: float
    end: float
    factor: float
    speed: float
    tag: int
    first_span: int | None = None
    last_span: int | None = None
    floored: bool = False

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"start": self.start, "end": self.end, "factor": self.factor, "speed": self.speed, "tag": self.tag,
                "first_span": self.first_span, "last_span": self.last_span, "floored": self.floored}

    @classmethod
    def from_state(cls, state: dict) -> CapWindow:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)

    @property
    def length(self) -> float:
        """Length of the stretch, m."""
        return self.end - self.start

    def describe(self, reasons=None, *, angular: bool = False) -> str:
        """E.g. ``"feed lowered to 38 % over 41 mm at spans 120-131 (joint 4 (wrist 2) speed)"``.

        ``reasons[tag]`` names what set the cap (omitted if None); ``angular``: the profile's "arc
        length" is an angle in rad (a turn in place), shown in degrees.
        """
        extent = f"{np.degrees(self.length):.3g} deg" if angular else f"{1e3 * self.length:.3g} mm"
        text = f"feed lowered to {100 * self.factor:.3g} %{' (the floor)' if self.floored else ''} over {extent}"
        if self.first_span is not None:
            text += (f" at span {self.first_span}" if self.first_span == self.last_span
                     else f" at spans {self.first_span}-{self.last_span}")
        if reasons is not None and 0 <= self.tag < len(reasons):
            text += f" ({reasons[self.tag]})"
        return text


def cap_windows(caps: FeedCaps, reference: FeedProfile, span_bounds=None, floor: float | None = None) -> tuple:
    """The stretches where ``caps`` lower the feed below ``reference``'s commanded feed, in order.

    Parameters
    ----------
    caps : FeedCaps
    reference : FeedProfile
        The profile planned without the caps (its commanded feed is the 100 % of the factors).
    span_bounds : ndarray (N,), optional
        Arc lengths of the waypoints (:func:`planner.motion.span_bounds`), to name the spans.
    floor : float, optional
        The floor the caps were planned with (a window whose lowest factor is at it is ``floored``).

    Returns
    -------
    tuple of CapWindow
    """
    pts = _dedupe(np.concatenate((caps.bounds, reference.level_bounds)), caps.length)
    mid = 0.5 * (pts[1:] + pts[:-1])
    speed, tag = caps.at(mid)
    factor = np.where(np.isfinite(speed), speed / reference.commanded_at(mid), np.inf)
    low = factor < 1.0
    if not low.any():
        return ()
    edges = np.flatnonzero(np.diff(np.concatenate(([0], low.astype(np.int8), [0]))))
    out = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):  # one per window (few)
        k = a + int(np.argmin(factor[a:b]))
        s0, s1 = float(pts[a]), float(pts[b])
        spans: tuple[int | None, int | None] = (None, None)
        if span_bounds is not None:
            sb = np.asarray(span_bounds, dtype=float)
            first = int(np.clip(np.searchsorted(sb, s0, side="right") - 1, 0, sb.size - 2))
            last = int(np.clip(np.searchsorted(sb, s1, side="left") - 1, first, sb.size - 2))
            spans = (first, last)
        floored = floor is not None and factor[k] <= floor * (1.0 + 1e-6)
        out.append(CapWindow(s0, s1, float(factor[k]), float(speed[k]), int(tag[k]), *spans,
                             floored=bool(floored)))
    return tuple(out)


def caps_from_ratios(s, t, ratio, tag, reference: FeedProfile, *, margin: float = DEFAULT_MARGIN,
                     floor: float = DEFAULT_FLOOR) -> tuple[FeedCaps, bool]:
    """Caps that bring the too-fast sample intervals of a trajectory to ``margin`` of their limit.

    Parameters
    ----------
    s, t : array_like (n,)
        Arc length (m) and time (s) of every sample (t strictly increasing, s non-decreasing).
    ratio : array_like (n - 1,)
        How many times too fast interval i (samples i to i + 1) is: largest |speed| / limit over
        whatever is limited (joints); <= 1 is within the limits.
    tag : array_like (n - 1,) of int
        What is fastest on each interval (the joint index), kept with its cap.
    reference : FeedProfile
        The profile planned without caps: the floor is ``floor`` times its commanded feed.
    margin : float in (0, 1]
        Fraction of the limit a capped interval is planned for.
    floor : float in (0, 1]
        Lowest cap, as a fraction of the commanded feed.

    Returns
    -------
    caps : FeedCaps
        On every interval over 1 and its two neighbours (a peak between samples): v margin / r with v
        the interval's mean speed, the lowest of the three, rounded down to a power of
        :data:`CAP_STEP`, not below the floor. No cap anywhere if nothing is too fast.
    floored : bool
        Whether some cap was held up by the floor.
    """
    s = finite_array(s, "s")
    t = finite_array(t, "t", s.shape)
    ratio = finite_array(ratio, "ratio", (max(s.size - 1, 0),))
    tag = np.asarray(tag, dtype=int)
    if tag.shape != ratio.shape:
        raise MotionInputError("tag", f"expected shape {ratio.shape}, got {tag.shape}")
    if not (0.0 < margin <= 1.0) or not (0.0 < floor <= 1.0):
        raise MotionInputError("margin", f"margin and floor must be in (0, 1], got {margin}, {floor}")
    L = reference.length
    bad = ratio > 1.0
    if not bad.any():
        return FeedCaps.none(L), False
    dt = np.diff(t)
    if (dt <= 0.0).any():
        raise MotionInputError("t", "times must increase")
    v = np.diff(s) / dt
    with np.errstate(divide="ignore", over="ignore"):
        need = np.where(ratio > 0.0, v * margin / ratio, np.inf)
    # an interval's cap is the lowest need of itself and its neighbours, on the too-fast ones and theirs
    pad = np.concatenate(([np.inf], need, [np.inf]))
    three = np.stack((pad[:-2], pad[1:-1], pad[2:]))
    pick = np.argmin(three, axis=0)
    cap = three[pick, np.arange(need.size)]
    tpad = np.concatenate(([-1], tag, [-1]))
    ctag = np.stack((tpad[:-2], tpad[1:-1], tpad[2:]))[pick, np.arange(need.size)]
    near = bad.copy()
    near[1:] |= bad[:-1]
    near[:-1] |= bad[1:]
    near &= np.diff(s) > 0.0
    idx = np.flatnonzero(near)
    s0, s1 = s[idx], s[idx + 1]
    lowest = floor * reference.commanded_at(0.5 * (s0 + s1))
    c = CAP_STEP ** np.floor(np.log(cap[idx]) / np.log(CAP_STEP))
    floored = c < lowest
    return FeedCaps.on_intervals(s0, s1, np.maximum(c, lowest), ctag[idx], L), bool(floored.any())


def apply_caps(bounds: np.ndarray, V: np.ndarray, caps: FeedCaps) -> tuple[np.ndarray, np.ndarray]:
    """Levels (bounds (m + 1,), commanded (m,)) split at the caps' pieces and lowered to them."""
    if not isinstance(caps, FeedCaps):
        raise MotionInputError("caps", f"must be a FeedCaps, got {type(caps).__name__}")
    L = float(bounds[-1])
    if abs(caps.length - L) > 1e-9 * max(L, 1.0):
        raise MotionInputError("caps", f"were made for length {caps.length} m, the path is {L} m")
    pts = _dedupe(np.concatenate((bounds, caps.bounds)), L)
    mid = 0.5 * (pts[1:] + pts[:-1])
    k = np.clip(np.searchsorted(bounds, mid, side="right") - 1, 0, V.size - 1)
    return pts, np.minimum(V[k], caps.at(mid)[0])
