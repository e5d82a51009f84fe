"""Sampling a planned motion at the controller rate into UR poses.

Per sample (in chunks that fit the CPU caches): time -> arc length (closed-form feed profile) -> path
parameter (exact arc-length inversion) -> TCP position and tool frame in the part frame -> robot base
frame (base transform) -> pose p[x, y, z, rx, ry, rz] with a continuous rotation vector.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from planner import quaternion as qt
from planner.kinematics.poses import as_transform, matrix_to_pose
from planner.motion.evaluator import evaluator_for, span_bounds
from planner.motion.events import ScheduledEvent, io_states, schedule_events
from planner.motion.limits import MotionInputError, finite_array, positive
from planner.motion.profile import FeedProfile
from planner.motion.rotvec import continuous_rotvec, rotvec_from_quaternions
from planner.rotations import matrix_to_quaternion, quaternion_to_matrix
from planner.validation import ArgumentError

#: Controller rates of UR robots: e-Series 500 Hz, CB-Series 125 Hz.
RATES = (500.0, 125.0)


def _transform(value, name: str) -> np.ndarray:
    """:func:`planner.kinematics.poses.as_transform`, its refusal a MotionInputError naming ``name``."""
    try:
        return as_transform(value, name)
    except ArgumentError as exc:
        raise MotionInputError(exc.argument, exc.detail) from None


#: Highest sampling rate of a pose stream, Hz (controllers run at 125-500 Hz; beyond this it is a mistake).
MAX_RATE = 1e6


def _check_path(path) -> None:
    """MotionInputError unless ``path`` is a path (a PH spline: ``length``, ``parameter_at_length``, ``points``)."""
    if not all(hasattr(path, a) for a in ("length", "parameter_at_length", "points")):
        raise MotionInputError("path", f"must be a path (a PH spline from fit_ph_spline), got {type(path).__name__}")


def transform_to_pose(T: np.ndarray) -> np.ndarray:
    """Deprecated: :func:`planner.kinematics.matrix_to_pose` (the same pose, for one transform or n)."""
    warnings.warn("planner.motion.transform_to_pose is deprecated and will be removed in the release after the next "
                  "one: use planner.kinematics.matrix_to_pose", DeprecationWarning, stacklevel=2)
    return matrix_to_pose(T)


@dataclass(frozen=True, eq=False)
class PoseStream:
    """Poses of the tool centre point sampled at the controller rate.

    Attributes
    ----------
    rate : float
        Samples per second (Hz); sample i is at time i / rate.
    times : ndarray (n,)
        Sample times, s. The last sample is the first at or after the end of the motion.
    s : ndarray (n,)
        Arc length along the path, m.
    u : ndarray (n,)
        Path parameter (exact inverse of the arc length).
    span : ndarray (n,) of int
        Waypoint span of each sample (span i runs from waypoint i to i + 1).
    positions : ndarray (n, 3)
        TCP position in the robot base frame, m (a view of ``poses[:, :3]``).
    rotations : ndarray (n, 3, 3)
        TCP frame in the robot base frame (columns x, y, z; z the approach axis).
    poses : ndarray (n, 6)
        ``p[x, y, z, rx, ry, rz]`` of the TCP in the base frame, rotation vector continuous.
    tcp : ndarray (4, 4)
        The TCP in the flange frame (what ``set_tcp`` gives the controller).
    base : ndarray (4, 4)
        The part frame (in which the path is given) in the robot base frame.
    events : tuple of ScheduledEvent
        Tool I/O events placed on the samples, in time order.
    profile : FeedProfile
        The time law the stream samples.
    state : (quaternion (4,), rotation vector (3,)) or None
        The last sample's unit quaternion and rotation vector: ``previous`` of the next window.
    """

    rate: float
    times: np.ndarray
    s: np.ndarray
    u: np.ndarray
    span: np.ndarray
    positions: np.ndarray
    rotations: np.ndarray
    poses: np.ndarray
    tcp: np.ndarray
    base: np.ndarray
    events: tuple[ScheduledEvent, ...] = ()
    profile: FeedProfile | None = field(default=None, repr=False)
    state: tuple | None = field(default=None, repr=False)

    def __len__(self) -> int:
        return self.times.size

    @property
    def tcp_pose(self) -> np.ndarray:
        """The TCP offset as a UR pose (6,) in the flange frame."""
        return matrix_to_pose(self.tcp)

    @cached_property
    def flange_poses(self) -> np.ndarray:
        """Poses (n, 6) of the tool flange in the base frame: T_flange = T_tcp_in_base inv(TCP).

        What the robot reports with a zero TCP; the rotation vector is continuous.
        """
        Rt, pt = self.tcp[:3, :3], self.tcp[:3, 3]
        Rf = self.rotations @ Rt.T
        pf = self.positions - Rf @ pt
        r, _ = continuous_rotvec(Rf)
        return np.hstack((pf, r))

    def io_states(self) -> dict[tuple[str, int], np.ndarray]:
        """{(output, pin): state (n,) of bool} of every output the events drive (off before the first)."""
        return io_states(self.events, len(self))


def sample_poses(
    path,
    profile: FeedProfile,
    orientation,
    *,
    rate: float = 500.0,
    tcp=None,
    base=None,
    events=(),
    chunk: int = 8192,
    inversion: str = "fast",
    window: tuple[int, int] | None = None,
    previous: tuple | None = None,
) -> PoseStream:
    """Sample a planned motion at the controller rate.

    Parameters
    ----------
    path : PHSpline
        The path (``points(u)``, ``parameter_at_length(s)``), in the part frame.
    profile : FeedProfile
        Its time law (:func:`planner.motion.plan_feed`).
    orientation : callable s (n,) -> (n, 3, 3)
        Tool frames in the part frame (e.g. :func:`planner.motion.tool_orientation`); if it has
        ``at_parameter(u)`` that is used instead (saves a second arc-length inversion).
    rate : float
        Controller rate, Hz: 500 (UR e-Series, default) or 125 (CB-Series); any positive rate works.
    tcp : pose (6,) or matrix (4, 4), optional
        The TCP in the flange frame (kept for the exports and :attr:`PoseStream.flange_poses`).
    base : pose (6,) or matrix (4, 4), optional
        The part frame in the robot base frame.
    events : sequence of IOEvent
        Tool I/O events, scheduled onto the samples.
    chunk : int
        Samples per vectorized batch (cache-sized batches are several times faster than one batch).
    inversion : "fast" or "path"
        Arc-length inversion and point evaluation: :class:`SplineEvaluator` (default; the same
        results as the path's ``parameter_at_length`` and ``points`` to round-off, several times
        faster) or the path's own methods.
    window : (first, count), optional
        Only samples first .. first + count - 1 of the stream (bounded memory for long moves; the same
        values as the whole stream's rows). No events with a window.
    previous : (quaternion (4,), rotation vector (3,)), optional
        The sample before the window, so that the rotation vectors continue it (e.g. the last row of the
        previous window: ``(matrix_to_quaternion(R[-1]), poses[-1, 3:])``).

    Returns
    -------
    PoseStream
    """
    rate = positive(rate, "rate")
    if rate > MAX_RATE:
        raise MotionInputError("rate", f"must be at most {MAX_RATE:g} Hz, got {rate:g}")
    _check_path(path)
    if not isinstance(profile, FeedProfile):
        raise MotionInputError("profile", f"must be a FeedProfile, got {type(profile).__name__}")
    if abs(float(getattr(path, "length", np.nan)) - profile.length) > 1e-9 * max(profile.length, 1.0):
        raise MotionInputError("profile", f"was planned for length {profile.length} m, path is {path.length} m")
    if not isinstance(chunk, int | np.integer) or chunk < 16:
        raise MotionInputError("chunk", f"must be an integer >= 16, got {chunk!r}")
    if inversion not in ("fast", "path"):
        raise MotionInputError("inversion", f"must be 'fast' or 'path', got {inversion!r}")
    Tt, Tb = _transform(tcp, "tcp"), _transform(base, "base")
    Rb, pb = Tb[:3, :3], Tb[:3, 3]
    turn = not np.array_equal(Rb, np.eye(3))
    qb = matrix_to_quaternion(Rb[None])
    ev = evaluator_for(path) if inversion == "fast" and hasattr(path, "sigma_coeffs") else None
    frames_u = getattr(orientation, "at_parameter", None)
    quats_u = getattr(orientation, "quaternions_at_parameter", None)
    quats_kt = getattr(orientation, "quaternions_at_segment", None) if ev is not None else None
    if not (callable(orientation) or frames_u is not None):
        raise MotionInputError("orientation",
                               f"must be a callable s -> (n, 3, 3) frames, got {type(orientation).__name__}")
    total = int(np.ceil(profile.duration * rate - 1e-9)) + 1
    if window is None:
        first, n = 0, total
        scheduled = schedule_events(events, profile, rate, n)  # validate the events before the work
    else:
        first, n = int(window[0]), int(window[1])
        if events:
            raise MotionInputError("events", "are scheduled on the whole stream: not with a window")
        if not (0 <= first and 0 <= n and first + n <= total):
            raise MotionInputError("window", f"samples {first}..{first + n - 1} are outside 0..{total - 1}")
        scheduled = ()
    times = (first + np.arange(n)) / rate
    s, u = np.empty(n), np.empty(n)
    poses = np.empty((n, 6))
    rot = np.empty((n, 3, 3))
    q_prev, r_prev = (None, None) if previous is None else previous
    for a in range(0, n, chunk):
        b = min(a + chunk, n)
        sc = profile.s(times[a:b])
        qc = None
        if ev is not None:
            k, t = ev.locate(sc)
            uc, pc = ev.parameter(k, t), ev.points(k, t)
            if quats_kt is not None:  # frames at the located samples: no second search for the segment
                qc = quats_kt(k, t)
        else:
            uc = path.parameter_at_length(sc)
            pc = path.points(uc)
        if qc is None and quats_u is not None:
            qc = quats_u(uc)
        if qc is not None:  # quaternion path: tool frame in base = qb * q
            qc = qt.mul(qb, qc) if turn else qc
            r, qc = rotvec_from_quaternions(qc, q_prev, r_prev)
            quaternion_to_matrix(qc, out=rot[a:b])
        else:
            R = frames_u(uc) if frames_u is not None else orientation(sc)
            R = np.matmul(Rb, R) if turn else np.asarray(R, dtype=float)
            r, qc = continuous_rotvec(R, q_prev, r_prev)
            rot[a:b] = R
        q_prev, r_prev = qc[-1], r[-1]
        s[a:b], u[a:b], poses[a:b, 3:] = sc, uc, r
        poses[a:b, :3] = pc @ Rb.T + pb if turn else pc + pb
    span_b = span_bounds(path)
    span = np.clip(np.searchsorted(span_b, s, side="right") - 1, 0, span_b.size - 2)
    state = None if q_prev is None else (q_prev, r_prev)
    return PoseStream(rate, times, s, u, span, poses[:, :3], rot, poses, Tt, Tb, scheduled, profile, state)


def poses_at_length(path, orientation, s, *, base=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """TCP positions (n, 3), frames (n, 3, 3) and poses (n, 6) in the base frame at arc lengths s (n,).

    The rotation vectors are continuous along s (for sparse points such as move targets).
    """
    s = finite_array(s, "s")
    if s.ndim > 1:
        raise MotionInputError("s", f"must be arc lengths of shape (n,), got {s.shape}")
    s = np.atleast_1d(s)
    _check_path(path)
    if not (callable(orientation) or hasattr(orientation, "at_parameter")):
        raise MotionInputError("orientation",
                               f"must be a callable s -> (n, 3, 3) frames, got {type(orientation).__name__}")
    Tb = _transform(base, "base")
    if hasattr(path, "sigma_coeffs"):
        ev = evaluator_for(path)
        k, t = ev.locate(s)
        u, p = ev.parameter(k, t), ev.points(k, t)
    else:
        u = path.parameter_at_length(s)
        p = path.points(u)
    at_u = getattr(orientation, "at_parameter", None)
    R = np.asarray(at_u(u) if at_u is not None else orientation(s), dtype=float)
    R = np.matmul(Tb[:3, :3], R)
    p = p @ Tb[:3, :3].T + Tb[:3, 3]
    r, _ = continuous_rotvec(R)
    return p, R, np.hstack((p, r))
