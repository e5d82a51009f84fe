"""What generated an export and with which job parameters: the header every export carries."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from importlib import metadata

import numpy as np

from planner.errors import PlannerError


class ExportError(PlannerError):
    """Data given to an exporter is unusable (the message names the parameter and sample)."""


def generator() -> str:
    """``"ph-toolpath-planner <version> (planner.export)"``."""
    try:
        version = metadata.version("ph-toolpath-planner")
    except metadata.PackageNotFoundError:
        version = "unknown"
    return f"ph-toolpath-planner {version} (planner.export)"


def _plain(value):
    """JSON-friendly version of a parameter value (arrays to lists, numpy scalars to Python)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def job_parameters(stream=None, parameters: Mapping | None = None, *, profile=None, tcp_pose=None, base=None,
                   n_events: int | None = None) -> dict:
    """The job's parameters as a JSON-friendly dict: stream facts, limits, TCP, base, plus ``parameters``.

    Parameters
    ----------
    stream : PoseStream, optional
        Supplies the rate, sample count, profile, TCP, base and event count.
    parameters : mapping, optional
        Anything else worth recording (input file, frame method, robot model ...); keys become strings.
    profile, tcp_pose, base, n_events : optional
        The same facts without a stream (for the ``movep`` program).
    """
    out: dict = {"generator": generator()}
    if stream is not None:
        out.update({"rate_hz": float(stream.rate), "samples": len(stream)})
        profile, tcp_pose, base, n_events = stream.profile, stream.tcp_pose, stream.base, len(stream.events)
    if profile is not None:
        lim = profile.limits
        out.update({
            "length_m": float(profile.length),
            "duration_s": float(profile.duration),
            "feed_min_m_s": float(np.min(profile.commanded)),
            "feed_max_m_s": float(np.max(profile.commanded)),
            "speed_limit_m_s": lim.speed,
            "acceleration_limit_m_s2": lim.acceleration,
            "jerk_limit_m_s3": lim.jerk,
            "angular_speed_limit_rad_s": lim.angular_speed,
        })
    if tcp_pose is not None:
        out["tcp_pose"] = [float(x) for x in tcp_pose]
    if base is not None:
        out["base_transform"] = np.asarray(base, float).tolist()
    if n_events is not None:
        out["io_events"] = int(n_events)
    for k, v in (parameters or {}).items():
        key = str(k)
        if key in out:
            raise ExportError(f"parameters: key {key!r} is reserved (set by the exporter)")
        out[key] = _plain(v)
    try:
        json.dumps(out, allow_nan=True)
    except TypeError as exc:
        raise ExportError(f"parameters: values must be JSON-serializable ({exc})") from None
    return out


def cam_job_parameters(job, rate: float | None = None, parameters: Mapping | None = None,
                       max_problems: int = 20) -> dict:
    """The parameters and figures of a whole CAM job (:class:`planner.cam.CamJob`) for an export header.

    SI units (m, s, rad) except the thresholds in degrees, as the keys say. ``rate`` (Hz) adds the
    rate and the number of poses of the stream at it; ``parameters`` adds anything else (input file
    name, ...); ``max_problems`` caps the robot problems listed (their count is always given).
    """
    s = job.settings
    lim, turn = s.limits, s.turn_limits
    out: dict = {
        "source": job.source,
        "passes": len(job.passes),
        "rapids": job.count("rapid"),
        "reorientations": job.count("reorientation"),
        "skipped": job.count("skipped"),
        "cut_length_m": float(sum(p.length for p in job.passes)),
        "duration_s": job.duration,
        "tolerance_m": s.tolerance,
        "max_deviation_m": job.max_deviation,
        "corner_deg": s.corner_deg,
        "axis_jump_deg": s.axis_jump_deg,
        "feed_m_s": s.feed,
        "feed_override": s.feed_override,
        "rapid_speed_m_s": s.rapid_speed,
        "limits": {"speed_m_s": lim.speed, "acceleration_m_s2": lim.acceleration, "jerk_m_s3": lim.jerk,
                   "angular_speed_rad_s": lim.angular_speed},
        "turn_limits": {"angular_speed_rad_s": turn.speed, "angular_acceleration_rad_s2": turn.acceleration,
                        "angular_jerk_rad_s3": turn.jerk},
        "part_frame": None if s.part_frame is None else [float(x) for x in s.part_frame],
        "tcp_pose": None if s.tcp is None else [float(x) for x in s.tcp],
        "robot": s.robot,
    }
    if rate is not None:
        out.update({"rate_hz": float(rate), "samples": job.n_samples(rate)})
    if s.robot is not None:
        out["reachable"] = not job.problems
        out["problems"] = len(job.problems)
        out["problem_list"] = list(job.problems[:max_problems])
    return job_parameters(None, {**out, **dict(parameters or {})})


def header_lines(params: Mapping) -> list[str]:
    """``key: value`` lines (values JSON-encoded) for a comment header."""
    lines = []
    for k, v in params.items():
        text = json.dumps(v, allow_nan=True) if not (isinstance(v, float) and math.isnan(v)) else "NaN"
        lines.append(f"{k}: {text}")
    return lines


def parse_header_line(line: str) -> tuple[str, object]:
    """Inverse of one :func:`header_lines` line."""
    key, _, text = line.partition(": ")
    return key, json.loads(text)


def event_dicts(stream) -> list[dict]:
    """The stream's scheduled I/O events as dicts (time order)."""
    return [
        {"time": e.time, "index": e.index, "s": e.event.s, "output": e.event.output, "pin": e.event.pin,
         "value": e.event.value, "lead_time": e.event.lead_time, "name": e.event.name}
        for e in stream.events
    ]


def io_column(channel: tuple[str, int]) -> str:
    """Column name of an output's state: ``standard_do0``, ``configurable_do3``, ``tool_do1``."""
    return f"{channel[0]}_do{channel[1]}"


def check_joints(joints, times: np.ndarray) -> np.ndarray | None:
    """Joint solutions (n, 6) in rad, one finite row per sample time (n,); None passes through."""
    if joints is None:
        return None
    n = len(times)
    try:
        q = np.asarray(joints, dtype=float)
    except (TypeError, ValueError):
        raise ExportError("joints: must be a numeric array of shape (n, 6)") from None
    if q.shape != (n, 6):
        raise ExportError(f"joints: expected shape ({n}, 6) (one joint vector per sample), got {q.shape}")
    bad = ~np.isfinite(q).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise ExportError(f"joints[{i}]: sample {i} (t = {times[i]:.6g} s) has no finite joint solution: "
                          f"{q[i].tolist()}")
    return q
