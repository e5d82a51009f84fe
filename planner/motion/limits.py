"""Motion limits of a job and the checks of user-given numbers (errors name the parameter)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from planner.errors import PlannerError
from planner.validation import ArgumentError, as_float, as_floats


class MotionInputError(PlannerError):
    """A time-law or sampling parameter is unusable.

    Attributes
    ----------
    parameter : str
        Name of the offending parameter (e.g. ``"limits.jerk"``, ``"span_feeds[3]"``).
    """

    def __init__(self, parameter: str, message: str):
        self.parameter = parameter
        super().__init__(f"{parameter}: {message}")


def real(value, name: str) -> float:
    """One real number (NaN and inf pass), or MotionInputError naming ``name`` (strings, complex numbers,
    booleans, None, arrays of other sizes, integers beyond the float range)."""
    try:
        return as_float(value, name, finite=False)
    except ArgumentError as exc:
        raise MotionInputError(name, str(exc).partition(": ")[2]) from None


def positive(value, name: str) -> float:
    """``value`` as a float, or MotionInputError naming ``name`` unless finite and > 0."""
    x = real(value, name)
    if not math.isfinite(x) or x <= 0.0:
        raise MotionInputError(name, f"must be finite and > 0, got {x}")
    return x


def nonnegative(value, name: str) -> float:
    """``value`` as a float, or MotionInputError naming ``name`` unless finite and >= 0."""
    x = real(value, name)
    if not math.isfinite(x) or x < 0.0:
        raise MotionInputError(name, f"must be finite and >= 0, got {x}")
    return x


@dataclass(frozen=True)
class MotionLimits:
    """Limits of the tool motion along the path.

    Speed, acceleration and jerk are those of the feed: the first three time derivatives of the arc
    length s(t) along the path (tangential TCP motion). The angular speed limit bounds |omega| of
    the tool frame about any axis.

    Attributes
    ----------
    speed : float
        Largest TCP speed, m/s.
    acceleration : float
        Largest |d^2 s / dt^2|, m/s^2.
    jerk : float
        Largest |d^3 s / dt^3|, m/s^3.
    angular_speed : float or None
        Largest tool angular speed, rad/s (None: no limit).
    """

    speed: float
    acceleration: float
    jerk: float
    angular_speed: float | None = None

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"speed": self.speed, "acceleration": self.acceleration, "jerk": self.jerk,
                "angular_speed": self.angular_speed}

    @classmethod
    def from_state(cls, state: dict) -> MotionLimits:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)

    def __post_init__(self):
        object.__setattr__(self, "speed", positive(self.speed, "limits.speed"))
        object.__setattr__(self, "acceleration", positive(self.acceleration, "limits.acceleration"))
        object.__setattr__(self, "jerk", positive(self.jerk, "limits.jerk"))
        if self.angular_speed is not None:
            object.__setattr__(self, "angular_speed", positive(self.angular_speed, "limits.angular_speed"))


def finite_array(values, name: str, shape: tuple | None = None) -> np.ndarray:
    """A float array, MotionInputError naming ``name`` and the first bad index if not finite."""
    try:
        a = as_floats(values, name)
    except ArgumentError as exc:
        raise MotionInputError(name, str(exc).partition(": ")[2]) from None
    if shape is not None and a.shape != shape:
        raise MotionInputError(name, f"expected shape {shape}, got {a.shape}")
    bad = ~np.isfinite(a)
    if bad.any():
        i = np.unravel_index(int(np.argmax(bad)), a.shape)
        where = "".join(f"[{j}]" for j in i)
        raise MotionInputError(f"{name}{where}", f"must be finite, got {a[i]}")
    return a
