"""Tool I/O events along the path (spray valve on/off, glue, ...) and their timing at the controller rate.

An event says: output ``pin`` of kind ``output`` must *take effect* when the tool reaches arc length
``s``. A valve that needs ``lead_time`` seconds to open is switched that long before the tool gets
there, at t(s) - lead_time on the feed profile. In a sampled stream the switch goes with the first
sample at or after that time.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from planner.kinematics.ur_outputs import OUTPUT_PINS
from planner.motion.limits import MotionInputError, nonnegative, real


class IOEventWarning(UserWarning):
    """An event's switching time falls before the start of the motion (it is moved to the start)."""


@dataclass(frozen=True)
class IOEvent:
    """Set a digital output when the tool reaches an arc length.

    Attributes
    ----------
    s : float
        Arc length along the path where the output must have taken effect, m.
    pin : int
        Output number (0..7 standard or configurable, 0..1 tool).
    value : bool
        Level to set.
    output : str
        ``"standard"``, ``"configurable"`` or ``"tool"`` digital output.
    lead_time : float
        Seconds before reaching ``s`` at which to switch (valve response time), >= 0.
    name : str
        Free label carried into the exports (e.g. ``"spray on"``).
    """

    s: float
    pin: int
    value: bool
    output: str = "standard"
    lead_time: float = 0.0
    name: str = ""

    def __post_init__(self):
        if self.output not in OUTPUT_PINS:
            raise MotionInputError("output", f"must be one of {sorted(OUTPUT_PINS)}, got {self.output!r}")
        n = OUTPUT_PINS[self.output]
        if isinstance(self.pin, bool) or not isinstance(self.pin, int | np.integer) or not 0 <= self.pin < n:
            raise MotionInputError("pin", f"{self.output} digital output must be 0..{n - 1}, got {self.pin!r}")
        s = float(self.s) if isinstance(self.s, int | float | np.floating | np.integer) else math.nan
        if not math.isfinite(s):
            raise MotionInputError("s", f"must be a finite arc length in metres, got {self.s!r}")
        object.__setattr__(self, "s", s)
        object.__setattr__(self, "pin", int(self.pin))
        object.__setattr__(self, "value", bool(self.value))
        object.__setattr__(self, "lead_time", nonnegative(self.lead_time, "lead_time"))

    @property
    def channel(self) -> tuple[str, int]:
        """(output kind, pin): the output this event drives."""
        return (self.output, self.pin)


def io_window(s_on: float, s_off: float, pin: int, *, output: str = "standard", lead_time: float = 0.0,
              off_lead_time: float | None = None, name: str = "") -> tuple[IOEvent, IOEvent]:
    """Two events: output on from arc length ``s_on`` to ``s_off`` (e.g. spray between s1 and s2).

    ``lead_time`` applies to switching on and, unless ``off_lead_time`` is given, to switching off
    (a valve that takes that long to respond both ways).
    """
    s_on, s_off = real(s_on, "s_on"), real(s_off, "s_off")
    if not s_on < s_off:
        raise MotionInputError("s_off", f"must be after s_on ({s_on}), got {s_off}")
    off = lead_time if off_lead_time is None else off_lead_time
    label = f"{name} " if name else ""
    return (IOEvent(s_on, pin, True, output, lead_time, f"{label}on".strip()),
            IOEvent(s_off, pin, False, output, off, f"{label}off".strip()))


@dataclass(frozen=True)
class ScheduledEvent:
    """An :class:`IOEvent` placed on a sampled stream.

    Attributes
    ----------
    event : IOEvent
    time : float
        When the output is switched, s: t(event.s) - event.lead_time (0 if that is before the start).
    index : int
        First sample at or after ``time``: the switch is issued with that sample.
    """

    event: IOEvent
    time: float
    index: int


def schedule_events(events, profile, rate: float, n_samples: int) -> tuple[ScheduledEvent, ...]:
    """Switching time and sample index of every event, in time order (stable for ties).

    Raises
    ------
    MotionInputError
        An element that is not an IOEvent, or an event outside the path (naming ``events[i]``).

    Warns
    -----
    IOEventWarning
        An event whose lead time puts its switch before the start (it is issued at the first sample).
    """
    events = tuple(events)
    for i, e in enumerate(events):
        if not isinstance(e, IOEvent):
            raise MotionInputError(f"events[{i}]", f"must be an IOEvent, got {type(e).__name__}")
        if not 0.0 <= e.s <= profile.length:
            raise MotionInputError(f"events[{i}].s", f"{e.s} m is outside the path [0, {profile.length}] m")
    if not events:
        return ()
    t = profile.time_at(np.array([e.s for e in events])) - np.array([e.lead_time for e in events])
    for i in np.flatnonzero(t < 0.0).tolist():
        e = events[i]
        warnings.warn(f"events[{i}] ({e.name or e.channel}): switching {e.lead_time} s before s = {e.s} m "
                      f"falls {-t[i]:.6g} s before the motion starts; it is issued at t = 0",
                      IOEventWarning, stacklevel=3)
    t = np.maximum(t, 0.0)
    idx = np.minimum(np.ceil(t * rate - 1e-9).astype(np.int64), n_samples - 1)
    order = np.argsort(t, kind="stable")
    return tuple(ScheduledEvent(events[i], float(t[i]), int(idx[i])) for i in order)


def io_states(scheduled, n_samples: int) -> dict[tuple[str, int], np.ndarray]:
    """State (n,) of every output the events drive at every sample; outputs start off (False)."""
    out: dict[tuple[str, int], np.ndarray] = {}
    for ch in dict.fromkeys(e.event.channel for e in scheduled):
        evs = [e for e in scheduled if e.event.channel == ch]
        idx = np.array([e.index for e in evs])
        val = np.array([e.event.value for e in evs])
        # state at sample i: value of the last event issued at or before i
        last = np.searchsorted(idx, np.arange(n_samples), side="right") - 1
        out[ch] = np.where(last >= 0, val[np.maximum(last, 0)], False)
    return out
