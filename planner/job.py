"""One planning job, end to end: waypoints (and tool axes) in, a timed UR pose stream out.

PH path -> tool frames (rotation-minimizing about the tool axis) -> jerk-limited feed along the exact arc
length -> poses at the controller rate -> UR inverse kinematics and reachability. Where a joint would be
faster than its speed limit the feed is lowered locally, only over the stretch that needs it
(:func:`planner.motion.local_feed.lower_feed_locally`), and the job names every stretch slowed; what
the floor of the feed cannot fix is reported, never streamed silently. Pure orchestration of the
planner packages; no file I/O.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from planner.curves import fit_ph_cubic_spline, fit_ph_spline
from planner.errors import PlannerError
from planner.frames import frame_field, max_twist_deg, tool_frames
from planner.kinematics import check_reachability, inverse_path, speed_ratios
from planner.kinematics.reachability import JOINT_SPEED_REASONS
from planner.motion import MotionLimits, PoseStream, plan_feed, sample_poses, span_bounds, tool_orientation
from planner.motion.caps import DEFAULT_FLOOR
from planner.motion.local_feed import Measurement, lower_feed_locally

FRAME_METHODS = ("rmf", "grm", "juttler", "er", "double-reflection")


@dataclass(frozen=True)
class JobSettings:
    """What the user sets for a job (SI units: m, s, rad).

    Attributes
    ----------
    frame : str
        Frame method: "rmf" (exact), "grm", "juttler", "er" or "double-reflection". With tool axes in
        the input, "juttler" selects Jüttler's rational RMM about them, anything else the exact one.
    feed : float
        TCP speed along the path, m/s (per-span feeds of the input take precedence where given).
    acceleration, jerk : float
        Limits of the feed, m/s^2 and m/s^3.
    angular_speed : float or None
        Limit of the tool's angular speed, rad/s.
    rate : float
        Controller rate, Hz (500 for e-Series, 125 for CB).
    robot : str or None
        UR model ("ur3e", "ur5e", "ur10e", "ur16e", "ur20") or None to plan without kinematics.
    base : pose (6,) or None
        The part frame in the robot base frame, p[x, y, z, rx, ry, rz].
    tcp : pose (6,) or None
        The tool centre point in the flange frame.
    tolerance : float or None
        Fit the path within this distance (m) of the waypoint polyline everywhere (straight runs kept
        straight, knots added where needed; :func:`planner.cam.fit_pass`) instead of interpolating the
        waypoints with a C2 spline (None).
    feed_floor : float
        With a robot: the lowest fraction (0..1] of the commanded feed to which the feed is lowered
        where a joint would exceed its speed limit; if that is not slow enough the job reports it.
    """

    frame: str = "rmf"
    feed: float = 0.05
    acceleration: float = 0.5
    jerk: float = 5.0
    angular_speed: float | None = 1.0
    rate: float = 500.0
    robot: str | None = "ur5e"
    base: tuple | None = None
    tcp: tuple | None = None
    tolerance: float | None = None
    feed_floor: float = DEFAULT_FLOOR


@dataclass(frozen=True, eq=False)
class Job:
    """A planned job: the path, its tool frames and time law, the pose stream and its figures.

    ``feed_caps`` holds one :class:`planner.motion.caps.CapWindow` per stretch where the feed was
    lowered for the joint speed limits (start and end arc length, lowest factor, spans, joint; tag =
    joint index), in path order; ``feed_scale`` is the lowest factor (1 if the feed was not lowered).
    """

    settings: JobSettings
    waypoints: np.ndarray
    path: object
    frames: object
    stream: PoseStream
    profile: object
    joints: np.ndarray | None
    reachability: object | None
    feed_caps: tuple
    twist_deg: float
    twist_s: np.ndarray
    twist_curve_deg: np.ndarray
    timings: dict = field(default_factory=dict)
    max_deviation: float | None = None
    feed_rounds: int = 0

    @property
    def feed_scale(self) -> float:
        """Lowest fraction of the commanded feed anywhere on the path (1 where it was never lowered)."""
        return min((w.factor for w in self.feed_caps), default=1.0)

    def feed_cap_lines(self) -> list[str]:
        """One line per stretch slowed for the joint speed limits, e.g. "feed lowered to 38 % over 41 mm
        at spans 120-131 (joint 4 (wrist 2) speed)"."""
        return [w.describe(JOINT_SPEED_REASONS) for w in self.feed_caps]

    def summary(self) -> dict:
        """The job's figures in human units (mm, s, deg); ``feed_caps`` lists the slowed stretches."""
        out = {
            "waypoints": int(len(self.waypoints)),
            "segments": int(self.path.n_segments),
            "length_mm": self.path.length * 1e3,
            "duration_s": float(self.profile.duration),
            "samples": int(self.stream.times.size),
            "max_waypoint_error_mm": float(self.path.interpolation_errors(self.waypoints).max()) * 1e3,
            "frame": self.settings.frame,
            "max_twist_vs_exact_rmf_deg": self.twist_deg,
            "feed_scale": self.feed_scale,
            "feed_caps": [
                {"start_mm": 1e3 * w.start, "end_mm": 1e3 * w.end, "percent": 100 * w.factor,
                 "spans": [w.first_span, w.last_span], "joint": w.tag, "at_floor": w.floored}
                for w in self.feed_caps
            ],
            "feed_lowered": self.feed_cap_lines(),
        }
        if self.max_deviation is not None:
            out["max_deviation_mm"] = self.max_deviation * 1e3
        if self.reachability is not None:
            out["reachable"] = bool(self.reachability.ok)
            out["reachability"] = self.reachability.message
        return out


def _down_start(path):
    """Start frame of a path frame field with column 2 (the tool z) as close to -Z as possible."""
    t = path.tangent(path.knots[:1])[0]
    z = np.array([0.0, 0.0, -1.0]) - (-t[2]) * t
    if np.linalg.norm(z) < 1e-6:  # travelling vertically: point the tool along -X
        z = np.array([-1.0, 0.0, 0.0]) - (-t[0]) * t
    z /= np.linalg.norm(z)
    return np.column_stack((t, np.cross(z, t), z))


def plan_job(waypoints, axes=None, settings: JobSettings = JobSettings(), *, span_feeds=None) -> Job:
    """Plan one pass: PH path through ``waypoints`` (N, 3) (m, part frame), tool frames, time law, poses.

    Parameters
    ----------
    waypoints : array_like (N, 3)
    axes : array_like (N, 3), optional
        Tool approach axis (tool z) at each waypoint. Without axes the tool z starts pointing down (-Z
        of the part frame) and rides the path's frame field (``settings.frame``) without spin about
        the tangent: it stays vertical on planar jobs.
    settings : JobSettings
    span_feeds : array_like (N - 1,), optional
        Per-span feeds from the input, m/s (NaN: the job's feed).

    Returns
    -------
    Job
        With a robot, the feed is lowered wherever a joint would exceed its speed limit at the
        controller rate, only there (``Job.feed_caps`` names every stretch), until every sample is
        within the limits or the feed is at ``settings.feed_floor`` there (``Job.reachability`` then
        names the samples still too fast).
    """
    s = settings
    if s.frame not in FRAME_METHODS:
        raise PlannerError(f"frame must be one of {FRAME_METHODS}, got {s.frame!r}")
    if not (isinstance(s.feed_floor, int | float) and 0.0 < s.feed_floor <= 1.0):
        raise PlannerError(f"feed_floor must be a fraction in (0, 1] of the commanded feed, got {s.feed_floor!r}")
    timings = {}
    tic = time.perf_counter()
    wp = np.asarray(waypoints, dtype=float)
    deviation = None
    if s.frame == "juttler" and axes is None:
        path = fit_ph_cubic_spline(wp)
    elif s.tolerance is not None:
        from planner.cam import fit_pass

        fit = fit_pass(wp, s.tolerance)
        path, deviation = fit.path, fit.max_deviation
    else:
        path = fit_ph_spline(wp)
    timings["fit_s"] = time.perf_counter() - tic

    tic = time.perf_counter()
    if axes is not None:
        method = "rational" if s.frame == "juttler" else "exact"
        tool = tool_frames(path, axes, method)
        exact = tool_frames(path, axes) if method != "exact" else tool
        orientation = tool_orientation(tool, z_column=2)
        field_used, reference = tool, exact
    else:
        start = _down_start(path)
        field_used = frame_field(path, s.frame, start=start)
        reference = field_used if s.frame == "rmf" else frame_field(path, "rmf", start=start)
        orientation = tool_orientation(field_used, z_column=2)
    sv = np.linspace(0.0, path.length, 2001)
    F, R = field_used.at_length(sv), reference.at_length(sv)
    # twist about the tool axis (axes given) or about the tangent (path frames), in degrees
    if axes is not None:
        ang = np.arctan2(np.einsum("ni,ni->n", np.cross(R[:, :, 0], F[:, :, 0]), R[:, :, 2]),
                         np.einsum("ni,ni->n", R[:, :, 0], F[:, :, 0]))
        twist_curve = np.degrees(ang)
    else:
        twist_curve = np.degrees(np.arctan2(np.einsum("ni,ni->n", F[:, :, 1], R[:, :, 2]),
                                            np.einsum("ni,ni->n", F[:, :, 1], R[:, :, 1])))
    twist = float(np.abs(twist_curve).max()) if axes is not None else max_twist_deg(F, R)
    timings["frames_s"] = time.perf_counter() - tic

    limits = MotionLimits(s.feed, s.acceleration, s.jerk, s.angular_speed)
    tic = time.perf_counter()
    reference = plan_feed(path, s.feed, limits, span_feeds=span_feeds,
                          orientation=orientation if s.angular_speed else None)
    timings["feed_s"] = time.perf_counter() - tic
    if s.robot is None:
        tic = time.perf_counter()
        stream = sample_poses(path, reference, orientation, rate=s.rate, tcp=s.tcp, base=s.base)
        timings["stream_s"] = time.perf_counter() - tic
        return Job(s, wp, path, field_used, stream, reference, None, None, (), twist, sv, twist_curve, timings,
                   deviation)

    lowered = lower_feed_locally(reference, _joint_measure(path, orientation, s, timings),
                                 span_bounds=span_bounds(path), floor=s.feed_floor)
    stream, joints = lowered.measurement.data
    tic = time.perf_counter()
    report = check_reachability(s.robot, joints, stream.times, arc_length=stream.s, span=stream.span)
    timings["kinematics_s"] += time.perf_counter() - tic
    return Job(s, wp, path, field_used, stream, lowered.profile, joints, report, lowered.windows, twist, sv,
               twist_curve, timings, deviation, lowered.rounds)


def _joint_measure(path, orientation, s: JobSettings, timings: dict):
    """The job's measurement for :func:`lower_feed_locally`: poses at the controller rate, inverse
    kinematics, the joint speed ratio of every sample interval (data: the stream and its joints).
    Adds the wall times of every round to ``timings`` ("stream_s", "kinematics_s")."""
    timings["stream_s"] = timings["kinematics_s"] = 0.0

    def measure(profile) -> Measurement:
        tic = time.perf_counter()
        stream = sample_poses(path, profile, orientation, rate=s.rate, tcp=s.tcp, base=s.base)
        toc = time.perf_counter()
        joints = inverse_path(s.robot, stream.flange_poses if s.tcp is not None else stream.poses,
                              allow_unreachable=True)
        ratio, joint = speed_ratios(s.robot, joints, stream.times)
        timings["stream_s"] += toc - tic
        timings["kinematics_s"] += time.perf_counter() - toc
        return Measurement(stream.s, stream.times, ratio, joint, (stream, joints))

    return measure
