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


def trajectory_parameters(trajectory, parameters: Mapping | None = None, max_problems: int = 20) -> dict:
    """The header of every export: generator, the job's settings (as planned) and figures, the rate and sample count.

    SI units (m, s, rad) except the thresholds in degrees, as the keys say; ``parameters`` adds anything
    else (input file name, ...); ``max_problems`` caps the robot problems listed (their count is always given).
    """
    if not hasattr(trajectory, "job") or not hasattr(trajectory, "rate"):
        raise ExportError(f"trajectory must be a planned job's Trajectory (job.trajectory()), got "
                          f"{type(trajectory).__name__}")
    if parameters is not None and not isinstance(parameters, Mapping):
        raise ExportError(f"parameters must be a mapping (dict) of header entries, got {type(parameters).__name__}")
    job = trajectory.job
    out: dict = {
        "generator": generator(),
        "source": job.source,
        "settings": job.settings.record(),
        "passes": len(job.passes),
        "rapids": job.count("rapid"),
        "reorientations": job.count("reorientation"),
        "skipped": job.count("skipped"),
        "dwells": job.count("dwell"),
        "cut_length_m": float(sum(p.length for p in job.passes)),
        "duration_s": trajectory.duration,
        "motion_time_s": job.duration,
        "max_deviation_m": job.max_deviation,
        "rate_hz": float(trajectory.rate),
        "samples": trajectory.n_samples,
    }
    if job.settings.robot is not None:
        out["reachable"] = not job.problems
        out["problems"] = len(job.problems)
        out["problem_list"] = list(job.problems[:max_problems])
        if job.reconfigurations:
            out["reconfigurations"] = job.reconfiguration_lines()
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


def header_lines(params: Mapping) -> list[str]:
    """``key: value`` lines (values JSON-encoded) for a comment header."""
    lines = []
    for k, v in params.items():
        text = json.dumps(v, allow_nan=True) if not (isinstance(v, float) and math.isnan(v)) else "NaN"
        lines.append(f"{k}: {text}")
    return lines
