"""Errors raised on bad user data: every one is a ``ValueError`` that says what and where."""

from __future__ import annotations


class PlannerError(ValueError):
    """Base class of every error the planner raises on bad input."""


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


class ConvergenceError(PlannerError):
    """An iterative solve (e.g. the C2 PH spline Newton solve) did not converge."""
