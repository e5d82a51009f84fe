"""One planning job, end to end: waypoints (and tool axes) in, a timed UR pose stream out.

PH path -> tool frames (rotation-minimizing about the tool axis) -> jerk-limited feed along the exact arc
length -> poses at the controller rate -> UR inverse kinematics and reachability (lowering the feed where
joint speed limits would be exceeded). Pure orchestration of the planner packages; no file I/O.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from planner.curves import fit_ph_cubic_spline, fit_ph_spline
from planner.errors import PlannerError
from planner.frames import frame_field, max_twist_deg, tool_frames
from planner.motion import MotionLimits, PoseStream, plan_feed, sample_poses, tool_orientation

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


@dataclass(frozen=True, eq=False)
class Job:
    """A planned job: the path, its tool frames and time law, the pose stream and its figures."""

    settings: JobSettings
    waypoints: np.ndarray
    path: object
    frames: object
    stream: PoseStream
    profile: object
    joints: np.ndarray | None
    reachability: object | None
    feed_scale: float
    twist_deg: float
    twist_s: np.ndarray
    twist_curve_deg: np.ndarray
    timings: dict = field(default_factory=dict)
    max_deviation: float | None = None

    def summary(self) -> dict:
        """The job's figures in human units (mm, s, deg)."""
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
    """
    s = settings
    if s.frame not in FRAME_METHODS:
        raise PlannerError(f"frame must be one of {FRAME_METHODS}, got {s.frame!r}")
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
    feed_scale = 1.0
    joints = report = None
    for _ in range(4):  # lower the feed until the joint speeds fit (reported, never silent)
        tic = time.perf_counter()
        feeds = None if span_feeds is None else np.asarray(span_feeds, float) * feed_scale
        profile = plan_feed(path, s.feed * feed_scale, limits, span_feeds=feeds,
                            orientation=orientation if s.angular_speed else None)
        stream = sample_poses(path, profile, orientation, rate=s.rate, tcp=s.tcp, base=s.base)
        timings["stream_s"] = time.perf_counter() - tic
        if s.robot is None:
            break
        from planner.kinematics import check_reachability, inverse_path

        tic = time.perf_counter()
        joints = inverse_path(s.robot, stream.flange_poses if s.tcp is not None else stream.poses,
                              allow_unreachable=True)
        span = np.searchsorted(path.waypoint_knots, stream.u, side="right") - 1
        report = check_reachability(s.robot, joints, stream.times, arc_length=stream.s, span=span)
        timings["kinematics_s"] = time.perf_counter() - tic
        if report.ok or not np.isfinite(joints).all() or report.feed_scale >= 1.0:
            break
        feed_scale *= report.feed_scale
    return Job(s, wp, path, field_used, stream, profile, joints, report, feed_scale, twist, sv,
               twist_curve, timings, deviation)
