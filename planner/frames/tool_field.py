"""Tool frames normal to a path: the tool z is a normal-plane vector carried along by a frame method.

For CAD curves without tool axes (a glue bead, a weld seam): the tool approaches perpendicular to the
direction of travel, starting as close to -Z (straight down in the part frame) as the tangent allows, and
its spin about the tangent is that of the chosen method (:func:`planner.frames.frame_field`: exact RMF,
GRM, Jüttler's rational RMM, ER, double reflection). Column 0 of a tool frame is the unit tangent, column
2 the tool z; the frames are those of the path frame field with the columns as they are.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from planner.frames.metrics import max_twist_deg
from planner.frames.path import frame_field
from planner.protocols import FrameProvider, Path

#: Samples along the path at which the twist against the exact RMF is measured.
TWIST_SAMPLES = 2001


#: Below this length of -Z projected onto the normal plane (the tangent within 14.5 deg of vertical) the
#: start direction -Z is ill-conditioned: -X is used where its projection is longer.
VERTICAL_TOLERANCE = 0.25


def down_start(tangent: np.ndarray) -> np.ndarray:
    """Frame (3, 3) with column 0 the unit ``tangent`` and column 2 as close to -Z as possible.

    When the tangent is within 14.5 degrees of vertical (:data:`VERTICAL_TOLERANCE`), -Z projected onto the
    normal plane is short and its direction ill-conditioned; then -X is projected instead where that is
    longer, so nearly vertical starts give a well-defined tool direction.
    """
    t = np.asarray(tangent, dtype=float)
    z = np.array([0.0, 0.0, -1.0]) + t[2] * t
    if np.linalg.norm(z) < VERTICAL_TOLERANCE:
        zx = np.array([-1.0, 0.0, 0.0]) + t[0] * t
        if np.linalg.norm(zx) > np.linalg.norm(z):
            z = zx
    z /= np.linalg.norm(z)
    return np.column_stack((t, np.cross(z, t), z))


@dataclass(frozen=True, eq=False)
class PathToolField:
    """Tool frames along a path from a path frame field (column 2 the tool z, normal to the path).

    A frame field in the sense of :class:`planner.protocols.FrameField`: ``path``, ``start``, ``end``,
    ``frames(u)``, ``at_length(s)`` (and ``quaternions(u)`` / ``quaternions_at(k, t)`` where the method
    gives them, for the fast sampler).

    Attributes
    ----------
    path : PHSpline
    method : str
        The frame method (see :func:`planner.frames.frame_field`).
    field : PathFrames or MotionFrames
        The frame field of the method.
    reference : PathFrames
        The exact RMF from the same start frame (the field itself for "rmf").
    """

    path: Path
    method: str
    field: FrameProvider
    reference: FrameProvider

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"path": self.path, "method": self.method, "field": self.field, "reference": self.reference}

    @classmethod
    def from_state(cls, state: dict) -> PathToolField:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)

    def frames(self, u) -> np.ndarray:
        """Tool frames (n, 3, 3) at path parameters u (n,)."""
        return self.field.frames(np.atleast_1d(np.asarray(u, dtype=float)))

    def at_length(self, s) -> np.ndarray:
        """Tool frames (n, 3, 3) at arc lengths s (n,) from the start, m."""
        return self.field.at_length(s)

    def __getattr__(self, name: str):
        # quaternions(u) and quaternions_at(k, t) where the field has them (the sampler looks them up)
        if name in ("quaternions", "quaternions_at") and hasattr(self.field, name):
            return getattr(self.field, name)
        raise AttributeError(name)

    @cached_property
    def start(self) -> np.ndarray:
        """Tool frame (3, 3) at the start."""
        return self.frames(self.path.knots[:1])[0]

    @cached_property
    def end(self) -> np.ndarray:
        """Tool frame (3, 3) at the end."""
        return self.frames(self.path.knots[-1:])[0]

    def twist_curve(self, samples: int = TWIST_SAMPLES) -> tuple[np.ndarray, np.ndarray]:
        """(arc length (n,), m; signed angle (n,) of the frames against the exact RMF about the tangent, degrees)."""
        sv = np.linspace(0.0, self.path.length, samples)
        if self.method == "rmf":
            return sv, np.zeros(samples)
        F, R = self.field.at_length(sv), self.reference.at_length(sv)
        ang = np.arctan2(np.einsum("ni,ni->n", F[:, :, 1], R[:, :, 2]), np.einsum("ni,ni->n", F[:, :, 1], R[:, :, 1]))
        return sv, np.degrees(ang)

    def max_twist_deg(self, samples: int = TWIST_SAMPLES) -> float:
        """Largest angle between these frames and the exact RMF (same start), degrees; 0 for "rmf"."""
        if self.method == "rmf":
            return 0.0
        sv = np.linspace(0.0, self.path.length, samples)
        return float(max_twist_deg(self.field.at_length(sv), self.reference.at_length(sv)))


@dataclass(frozen=True, eq=False)
class SampledFrames:
    """A discrete frame method (double reflection) run once on a dense grid of the path parameter and
    slerped between: continuous and the same whatever samples are asked for (a sampler asks chunk by chunk).

    Attributes
    ----------
    path : PHSpline
    u : ndarray (m,)
        The grid of path parameters (``per_segment`` samples per PH segment).
    grid_quaternions : ndarray (m, 4)
        Unit quaternions (x, y, z, w, scipy's order) of the method's frames on the grid, as
        ``Rotation.from_matrix`` gives them.
    """

    path: Path
    u: np.ndarray
    grid_quaternions: np.ndarray

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"path": self.path, "u": self.u, "grid_quaternions": self.grid_quaternions}

    @classmethod
    def from_state(cls, state: dict) -> SampledFrames:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)

    @cached_property
    def interpolant(self):
        """The slerp (scipy.spatial.transform.Slerp) between the frames on the grid (the quaternions taken as
        they are, not normalized again)."""
        from scipy.spatial.transform import Rotation, Slerp

        return Slerp(self.u, Rotation(self.grid_quaternions, normalize=False))

    def frames(self, u) -> np.ndarray:
        u = np.clip(np.atleast_1d(np.asarray(u, dtype=float)), self.u[0], self.u[-1])
        return self.interpolant(u).as_matrix()

    def at_length(self, s) -> np.ndarray:
        return self.frames(self.path.parameter_at_length(s))


def sampled_frames(path, field, per_segment: int = 256) -> SampledFrames:
    """:class:`SampledFrames` of a frame field whose ``frames(u)`` depend on the samples it is given."""
    from scipy.spatial.transform import Rotation

    k = np.asarray(path.knots, dtype=float)
    u = np.append((k[:-1, None] + np.diff(k)[:, None] * np.arange(per_segment) / per_segment).ravel(), k[-1])
    return SampledFrames(path, u, Rotation.from_matrix(field.frames(u)).as_quat(canonical=False))


def path_tool_field(path, method: str = "rmf") -> PathToolField:
    """Tool frames normal to ``path`` by ``method``, starting with the tool z nearest -Z."""
    start = down_start(path.tangent(path.knots[:1])[0])
    field: FrameProvider = frame_field(path, method, start=start)
    if method == "double-reflection":  # a discrete method: run once on a dense grid
        field = sampled_frames(path, field)
    reference = field if method == "rmf" else frame_field(path, "rmf", start=start)
    return PathToolField(path, method, field, reference)
