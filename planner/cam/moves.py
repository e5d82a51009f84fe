"""Paths and tool frames of the moves between cutting passes: straight rapids and turns in place, and
the joint moves that change the arm configuration in a rapid.

Rapids and turns turn the tool about an axis perpendicular to the tool axis (n = z0 x z1), so they never
spin it about itself: a rapid turns the axis along the great circle in proportion to the distance
travelled, a reorientation turns it in place with a jerk-limited angle profile. A reconfiguration
(:class:`Reconfiguration`) moves the joints on a straight line in joint space, movej-like, with a
jerk-limited time law from joint speed and acceleration limits (:func:`joint_move_profile`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner import quaternion as qt
from planner.cam.axes import turn_axis
from planner.curves.spline import PHSpline
from planner.errors import PlannerError
from planner.motion import MotionLimits, plan_feed
from planner.protocols import Path
from planner.rotations import matrix_to_quaternion, rotvec_to_matrix, rotvec_to_quaternion


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

    path: Path | None
    start: np.ndarray
    n: np.ndarray
    angle: float
    span: float

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"path": self.path, "start": self.start, "n": self.n, "angle": self.angle, "span": self.span}

    @classmethod
    def from_state(cls, state: dict) -> TurningFrames:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)

    def frames(self, x) -> np.ndarray:
        x = np.atleast_1d(np.asarray(x, dtype=float))
        if self.angle == 0.0:
            return np.broadcast_to(self.start, (x.size, 3, 3)).copy()
        turned = (self.angle * np.clip(x / self.span, 0.0, 1.0))[:, None] * self.n
        return rotvec_to_matrix(turned) @ self.start

    def quaternions(self, x) -> np.ndarray:
        x = np.atleast_1d(np.asarray(x, dtype=float))
        q0 = matrix_to_quaternion(self.start[None])[0]
        r = rotvec_to_quaternion((self.angle * np.clip(x / self.span, 0.0, 1.0))[:, None] * self.n)
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


@dataclass(frozen=True, eq=False)
class Reconfiguration:
    """A change of the arm configuration in joint space (movej-like) at a rapid's safe point.

    The tool leaves the point and comes back to it: both joint vectors put the tool on the same pose,
    on different inverse-kinematics branches (shoulder, elbow, wrist solution) or with a joint turned by
    a whole turn. Every joint moves on the straight line between them, all starting and stopping
    together (like UR's ``movej``).

    Attributes
    ----------
    q_from, q_to : ndarray (6,)
        Joint positions before and after, rad.
    point : ndarray (3,)
        The safe point, part frame, m.
    line : int
        Source line of the rapid record the safe point belongs to.
    pass_index : int
        The first pass made on the new configuration.
    passes : tuple of int
        The passes of the run (joined at corners, without a rapid between them) it is made for.
    reason : str
        What the former configuration could not do (names the pass or rapid and the source line).
    change : str
        What changes, for a person (e.g. "wrist flipped, wrist 3 +1 turn").
    where : str
        Where in the rapids it happens (e.g. "at the end of the rapid at line 20357").
    tcp_excursion : float
        Largest distance of the TCP from the safe point during the joint move, m (from forward
        kinematics of the straight joint-space line; the part may be in the way: the planner has no
        geometry of it).
    """

    q_from: np.ndarray
    q_to: np.ndarray
    point: np.ndarray
    line: int
    pass_index: int
    passes: tuple
    reason: str
    change: str
    where: str
    tcp_excursion: float = 0.0

    kind = "reconfiguration"

    def to_state(self) -> dict:
        """The fields as data, for the saved-job file (:mod:`planner.jobfile`)."""
        return {"q_from": self.q_from, "q_to": self.q_to, "point": self.point, "line": self.line,
                "pass_index": self.pass_index, "passes": self.passes, "reason": self.reason, "change": self.change,
                "where": self.where, "tcp_excursion": self.tcp_excursion}

    @classmethod
    def from_state(cls, state: dict) -> Reconfiguration:
        """The object from :meth:`to_state` fields read back (checked by the reader)."""
        return cls(**state)

    def joints(self, fraction) -> np.ndarray:
        """Joint positions (n, 6) at fractions (n,) of the move (0: q_from, 1: q_to)."""
        f = np.atleast_1d(np.asarray(fraction, dtype=float))
        return self.q_from + f[:, None] * (self.q_to - self.q_from)


def joint_move_profile(q_from, q_to, joint_limits: MotionLimits, speed_limits=None):
    """Jerk-limited time law of a synchronized joint move: a FeedProfile over the fraction [0, 1] of it.

    Joint j moves by |dq_j| times the fraction, so its speed, acceleration and jerk are |dq_j| times
    those of the fraction: the fraction's limits are the smallest of ``joint_limits`` (rad/s, rad/s^2,
    rad/s^3, the same for every joint, e.g. UR's movej defaults v = 1.05, a = 1.4) and ``speed_limits``
    (6,) (the model's joint speed limits, rad/s) divided by |dq_j|. The joint with the largest ratio of
    travel to limit leads; the others are slower and finish together with it.
    """
    dq = np.abs(np.asarray(q_to, dtype=float) - np.asarray(q_from, dtype=float))
    if not (dq > 0.0).any():
        raise PlannerError("a joint move needs two different joint vectors")
    v = np.full(6, joint_limits.speed) if speed_limits is None else np.minimum(joint_limits.speed, speed_limits)
    moving = dq > 0.0
    speed = float(np.min(v[moving] / dq[moving]))
    acc = joint_limits.acceleration / float(dq.max())
    jerk = joint_limits.jerk / float(dq.max())
    return plan_feed(1.0, speed, MotionLimits(speed, acc, jerk))
