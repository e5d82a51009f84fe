"""Paths and tool frames of the moves between cutting passes: straight rapids and turns in place.

Both turn the tool about an axis perpendicular to the tool axis (n = z0 x z1), so they never spin it
about itself: a rapid turns the axis along the great circle in proportion to the distance travelled,
a reorientation turns it in place with a jerk-limited angle profile.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner import quaternion as qt
from planner.cam.axes import rotation_matrices, turn_axis
from planner.curves.spline import PHSpline
from planner.motion import MotionLimits, plan_feed
from planner.motion.rotvec import matrix_to_quaternion


def straight_path(p0: np.ndarray, p1: np.ndarray) -> PHSpline:
    """The straight PH quintic from p0 to p1 at uniform speed (its parameter is the arc length).

    A constant quaternion polynomial A = sqrt(L) n(c) (n(c) rotating i onto the chord c) has the
    constant hodograph A i A* = c (grm seed sec. 2.1), so r(t) = p0 + t c.
    """
    p0 = np.asarray(p0, dtype=float)
    c = np.asarray(p1, dtype=float) - p0
    L = float(np.linalg.norm(c))
    a = np.sqrt(L) * qt.rotate_i_to(c[None])[0]
    return PHSpline(np.broadcast_to(a, (1, 3, 4)).copy(), p0[None].copy(), np.array([0.0, L]), "C1", 0)


@dataclass(frozen=True, eq=False)
class TurningFrames:
    """Frames F(x) = Rot(n, angle * x / span) F0 for x in [0, span]: a turn at constant rate in x.

    A frame provider (``frames(u)``, ``at_length(s)``, ``quaternions(u)``, ``path``) for a straight
    rapid (x = arc length = path parameter) and the frames of a reorientation (x = angle turned).
    """

    path: object
    start: np.ndarray
    n: np.ndarray
    angle: float
    span: float

    def frames(self, x) -> np.ndarray:
        x = np.atleast_1d(np.asarray(x, dtype=float))
        if self.angle == 0.0:
            return np.broadcast_to(self.start, (x.size, 3, 3)).copy()
        return rotation_matrices(self.n, self.angle * np.clip(x / self.span, 0.0, 1.0)) @ self.start

    def quaternions(self, x) -> np.ndarray:
        x = np.atleast_1d(np.asarray(x, dtype=float))
        q0 = matrix_to_quaternion(self.start[None])[0]
        half = 0.5 * self.angle * np.clip(x / self.span, 0.0, 1.0)
        r = np.concatenate((np.cos(half)[:, None], np.sin(half)[:, None] * self.n), axis=1)
        return qt.mul(r, np.broadcast_to(q0, r.shape))  # the turn about n applied after the start frame

    def at_length(self, s) -> np.ndarray:
        return self.frames(s)

    @property
    def end(self) -> np.ndarray:
        return self.frames(np.array([self.span]))[0]


def rapid_frames(path, start: np.ndarray, z_end: np.ndarray) -> TurningFrames:
    """Frames along a straight rapid: the axis turns from the start frame's to ``z_end`` without spin."""
    n, ang = turn_axis(start, z_end)
    return TurningFrames(path, start, n, ang, float(path.length))


def turn_frames(start: np.ndarray, z_end: np.ndarray) -> TurningFrames:
    """Frames of a turn in place, parametrized by the angle turned (radians)."""
    n, ang = turn_axis(start, z_end)
    return TurningFrames(None, start, n, ang, max(ang, 1e-300))


def turn_profile(angle: float, limits: MotionLimits):
    """Jerk-limited angle profile (a FeedProfile whose "length" is the angle, radians) of a turn."""
    return plan_feed(float(angle), limits.speed, limits)
