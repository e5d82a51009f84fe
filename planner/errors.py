"""The planner's two kinds of error: the user's mistakes and our own numerical failures.

- :class:`PlannerError` (a ``ValueError``) and its subclasses: the input is unusable (bad data, an
  option out of range, a toolpath the robot cannot follow). The message says what and where. The CLI
  exits with code 2, the REST service answers 4xx.
- :class:`NumericalError` (a ``RuntimeError``, deliberately *not* a ``ValueError``, so that no
  ``except ValueError`` / ``except PlannerError`` turns it into the user's fault) and its subclasses: an
  algorithm of ours failed on input that is valid (a solver did not converge). The CLI reports
  "internal error, please report" with exit code 3, the REST service answers 5xx.
"""

from __future__ import annotations


class PlannerError(ValueError):
    """Base class of every error the planner raises on bad input.

    Attributes
    ----------
    field : str or None
        The setting (a :class:`planner.PlanSettings` field name) or argument the error is about, when one is to
        blame: front ends name it (the REST service's 422 ``loc``) from here, never from the message's text.
    value : object
        The refused value (None when ``field`` is None or the value was None).
    """

    field: str | None = None
    value: object = None

    def __init__(self, *args, field: str | None = None, value: object = None):
        super().__init__(*args)
        if field is not None:
            self.field = field
            self.value = value


class WaypointError(PlannerError):
    """A waypoint (or the tangent given for it) is unusable.

    Attributes
    ----------
    index : int or None
        Index of the offending waypoint in the user's list (0-based), or None when the problem is
        with the list as a whole (too short, wrong shape).
    """

    def __init__(self, message: str, index: int | None = None):
        self.index = index
        where = f"waypoint {index}: " if index is not None else ""
        super().__init__(where + message)


class NoSolutionError(PlannerError):
    """The data admits no curve of the requested kind (e.g. no PH cubic through given G1 data)."""


class NumericalError(RuntimeError):
    """Base class of the planner's own numerical failures: not a ``ValueError``, not the user's fault.

    Raised when an algorithm fails on input that passed validation. The message starts with what failed
    and where, and ends by saying that this is a numerical failure of the planner, not a problem with the
    input. Front ends map it to an internal error: the service to HTTP 5xx, the CLI to
    "internal error, please report" with exit code 3.

    Attributes
    ----------
    detail : str
        The message without the closing sentence.
    """

    #: Appended to every message.
    NOTE = "this is a numerical failure of the planner, not a problem with the input; please report it"

    def __init__(self, detail: str):
        self.detail = detail
        super().__init__(f"{detail} ({self.NOTE})")

    def __reduce__(self):  # pickled (e.g. by a worker pool) and rebuilt with the same message
        return type(self), (self.detail,)


class ConvergenceError(NumericalError):
    """An iterative solve (e.g. the C2 PH spline Newton solve) or an adaptive refinement did not converge."""
