"""The interfaces where the planner's objects meet, declared as ``typing.Protocol`` s.

A path (:class:`Path`: the PH splines of :mod:`planner.curves`, a straight rapid), a field of tool frames
along it (:class:`FrameProvider`, and :class:`FrameField` with its end frame: :class:`planner.cam.AxisField`,
:class:`planner.frames.tool_field.PathToolField`,
the turning frames of rapids and turns in place), and the trajectory every consumer reads
(:class:`TrajectoryLike`: :class:`planner.trajectory.Trajectory`). Consumers (exports, plot, drivers, the
service) are typed against these, not against the concrete classes; mypy checks the match.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any, Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class Path(Protocol):
    """A parametric path in the part frame (m): ``points(u)`` for parameters u (n,) -> (n, 3)."""

    @property
    def length(self) -> float:
        """Exact arc length, m."""
        ...

    @property
    def knots(self) -> np.ndarray:
        """Parameters of the segment ends (m + 1,)."""
        ...

    @property
    def waypoint_knots(self) -> np.ndarray:
        """Parameters of the points the path was fitted to (n,)."""
        ...

    @property
    def waypoints(self) -> np.ndarray:
        """The points the path was fitted to (n, 3)."""
        ...

    def locate(self, u: Any) -> tuple[np.ndarray, np.ndarray]:
        """(segment (n,), local parameter in [0, 1] (n,)) of parameters u (n,)."""
        ...

    def arc_length(self, u: Any) -> np.ndarray:
        """Arc lengths (n,) from the start at parameters u (n,)."""
        ...

    def points(self, u: Any) -> np.ndarray:
        """Points (n, 3) at parameters u (n,)."""
        ...

    def tangent(self, u: Any) -> np.ndarray:
        """Unit tangents (n, 3) at parameters u (n,)."""
        ...

    def parameter_at_length(self, s: Any) -> np.ndarray:
        """Parameters (n,) at arc lengths s (n,) from the start."""
        ...


@runtime_checkable
class FrameProvider(Protocol):
    """Frames along a path or a move: orthonormal, right-handed (3, 3) per sample."""

    def frames(self, u: Any) -> np.ndarray:
        """Frames (n, 3, 3) at the move's parameters u (n,) (path parameter, or angle turned in place)."""
        ...

    def at_length(self, s: Any) -> np.ndarray:
        """Frames (n, 3, 3) at arc lengths s (n,) (angle turned, for a turn in place)."""
        ...


@runtime_checkable
class FrameField(FrameProvider, Protocol):
    """Tool frames along a move: column 2 the tool z (approach axis); a :class:`FrameProvider` with its end."""

    @property
    def end(self) -> np.ndarray:
        """Frame (3, 3) at the end of the move."""
        ...


@runtime_checkable
class TrajectoryLike(Protocol):
    """A job sampled at a controller rate, read chunk by chunk (:class:`planner.trajectory.Trajectory`)."""

    job: Any
    rate: float

    @property
    def robot(self) -> str | None: ...

    @property
    def n_samples(self) -> int: ...

    @property
    def duration(self) -> float: ...

    def chunks(self, *, joints: bool | None = None,
               progress: Callable[[str, int, int], None] | None = None) -> Iterator[Any]: ...

    def moves(self) -> list[dict]: ...
