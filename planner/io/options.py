"""Checks of the readers' arguments (not of the file's contents): each bad argument is refused before the file is
opened, with a :class:`ReaderArgumentError` (a :class:`~planner.errors.PlannerError`) that names the argument and,
for a named choice, lists the known values."""

from __future__ import annotations

import io
import math
import numbers
import os
from collections.abc import Iterable

import numpy as np

from planner.errors import PlannerError
from planner.validation import ArgumentError, _described


class ReaderArgumentError(ArgumentError):
    """A bad argument of a reader (``read_toolpath``, ``read_apt``, ...). The message names the argument:
    ``"units must be one of 'mm', 'm', 'inch', got 'bogus'"``.

    Attributes
    ----------
    argument : str
        The argument at fault (``"units"``, ``"arc_tolerance"``, ``"src"``).
    """

    def __init__(self, argument: str, message: str):
        self.argument = argument
        PlannerError.__init__(self, message)

    def __reduce__(self):
        return (type(self), (self.argument, str(self)))


class ReaderArgumentTypeError(ReaderArgumentError, TypeError):
    """A reader's argument of the wrong type (a stream where a path or a text stream is needed, a number where a
    name is); also a ``TypeError`` for callers that catch that."""


def check_src(src, name: str = "src") -> None:
    """``src`` is a file path (str or os.PathLike) or a text stream; else :class:`ReaderArgumentTypeError`."""
    if isinstance(src, str | os.PathLike):
        return
    binary = isinstance(src, io.RawIOBase | io.BufferedIOBase) or (
        isinstance(getattr(src, "mode", None), str) and "b" in src.mode and not isinstance(src, io.TextIOBase)
    )
    if binary:
        raise ReaderArgumentTypeError(name, f"{name} is a binary stream: open the file in text mode (or pass its path)")
    if isinstance(src, io.TextIOBase) or hasattr(src, "readline") or hasattr(src, "read"):
        return
    raise ReaderArgumentTypeError(name, f"{name} must be a file path or a text stream, got {_described(src)}")


def binary_stream(name: str = "src") -> ReaderArgumentTypeError:
    """The error for a stream that yields bytes (found when reading it)."""
    return ReaderArgumentTypeError(name, f"{name} is a binary stream: open the file in text mode (or pass its path)")


def _listed(known: Iterable[str]) -> str:
    names = [repr(k) for k in known]
    return ", ".join(names[:-1]) + f" or {names[-1]}" if len(names) > 1 else "".join(names)


def choice(value, name: str, known: Iterable[str]) -> str:
    """``value`` if it is one of the names ``known`` (compared as given); else :class:`ReaderArgumentError` listing
    them (:class:`ReaderArgumentTypeError` for a value that is not a string)."""
    known = tuple(known)
    if not isinstance(value, str):
        raise ReaderArgumentTypeError(name, f"{name} must be one of {_listed(known)}, got {_described(value)}")
    if value not in known:
        raise ReaderArgumentError(name, f"{name} must be one of {_listed(known)}, got {value!r}")
    return value


def number_in(value, name: str, lo: float, hi: float, *, lo_open: bool = False, what: str | None = None) -> float:
    """``value`` as a finite float in [lo, hi] (``(lo, hi]`` with ``lo_open``); else :class:`ReaderArgumentError`
    naming ``name`` (booleans, strings, complex numbers, NaN and inf are refused). ``what`` describes the range in
    the message (default "a number in [lo, hi]")."""
    what = what or f"a number in {'(' if lo_open else '['}{lo:g}, {hi:g}]"
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
        raise ReaderArgumentTypeError(name, f"{name} must be {what}, got {_described(value)}")
    try:
        x = float(value)
    except (OverflowError, TypeError, ValueError):
        raise ReaderArgumentError(name, f"{name} must be {what}, got {_described(value)}") from None
    if not (math.isfinite(x) and (lo < x if lo_open else lo <= x) and x <= hi):
        raise ReaderArgumentError(name, f"{name} must be {what}, got {x!r}")
    return x


#: The widest accepted ``axis_tolerance`` (exclusive): at 1 a zero vector would pass for a unit one.
AXIS_TOLERANCE_MAX = 0.5
#: The range of an ``arc_tolerance`` (metres), as in PlanSettings: below a nanometre no machine resolves the
#: chords, and the number of them grows without end.
ARC_TOLERANCE_RANGE = (1e-9, 1.0)


def axis_tolerance(value) -> float:
    """A valid ``axis_tolerance`` (the largest accepted deviation of an axis' length from 1): a number in [0, 0.5]."""
    return number_in(value, "axis_tolerance", 0.0, AXIS_TOLERANCE_MAX)


def chord_tolerance(value, name: str = "tolerance") -> float:
    """A valid tolerance of chords on a curve (metres): a number in [1e-9, 1]."""
    lo, hi = ARC_TOLERANCE_RANGE
    return number_in(value, name, lo, hi, what=f"positive, a length in metres in [{lo:g}, {hi:g}]")


def arc_tolerance(value) -> float | None:
    """A valid ``arc_tolerance`` of a reader (metres): None (arcs kept), or a number in [1e-9, 1]."""
    return None if value is None else chord_tolerance(value, "arc_tolerance")


def peck_clearance(value) -> float:
    """A valid ``peck_clearance`` (metres): a number in (0, 1)."""
    x = number_in(value, "peck_clearance", 0.0, 1.0, lo_open=True, what="a length in metres in (0, 1)")
    if x >= 1.0:
        raise ReaderArgumentError("peck_clearance", f"peck_clearance must be a length in metres in (0, 1), got {x!r}")
    return x


def source_label(value) -> str | None:
    """A valid ``source`` (the name messages use): None or a string."""
    if value is not None and not isinstance(value, str):
        raise ReaderArgumentTypeError("source", f"source must be a string (the name messages use) or None, got "
                                                f"{_described(value)}")
    return value


def flag(value, name: str) -> bool:
    """A valid boolean option (``True`` or ``False``, numpy booleans too)."""
    if not isinstance(value, bool | np.bool_):
        raise ReaderArgumentTypeError(name, f"{name} must be True or False, got {_described(value)}")
    return bool(value)


def delimiter(value) -> str | None:
    """A valid column separator: None (detected) or one character."""
    if value is None:
        return None
    if not isinstance(value, str):
        raise ReaderArgumentTypeError("delimiter", f"delimiter must be one character such as ',', ';', '\\t' or ' ' "
                                                   f"(or None to detect it), got {_described(value)}")
    if len(value) != 1 or value in "\"\r\n":
        raise ReaderArgumentError("delimiter", f"delimiter must be one character such as ',', ';', '\\t' or ' ' "
                                               f"(or None to detect it), got {_described(value)}")
    return value
