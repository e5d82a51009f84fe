"""Errors of the kinematics package (subclasses of the planner's shared errors)."""

from __future__ import annotations

from planner.errors import NoSolutionError


class UnreachableError(NoSolutionError):
    """A pose along a path has no inverse kinematics solution.

    Attributes
    ----------
    index : int or None
        Index of the first unreachable sample (0-based); None for a single pose.
    """

    def __init__(self, message: str, index: int | None = None):
        self.index = index
        super().__init__(message if index is None else f"sample {index}: {message}")
