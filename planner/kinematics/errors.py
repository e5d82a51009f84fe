"""Errors of the kinematics package (subclasses of the planner's shared errors)."""

from __future__ import annotations

from planner.errors import NoSolutionError


class UnreachableError(NoSolutionError):
    """A pose along a path has no inverse kinematics solution.

    Attributes
    ----------
    index : int
        Index of the first unreachable sample (0-based).
    """

    def __init__(self, message: str, index: int):
        self.index = index
        super().__init__(f"sample {index}: {message}")
