"""Tool frames that rotate as little as possible about the tool axis, with their quality figures.

Per PH segment: :func:`er_frames` (Euler-Rodrigues), :func:`rmf_frames` (exact RMF), :func:`grm`
(rational GRM frame, Peng et al. 2023). Jüttler's rational rotation-minimizing motions:
:func:`rmm_arc`, :func:`ph_cubic_rmm`, :func:`ph_cubic_spline_rmm`, spherical biarcs and the exact
RMM of a spherical curve. Sampled curves: :func:`double_reflection_frames`. Whole paths:
:func:`frame_field` / :func:`path_frames` (continuous, closed, prescribed rolls); :func:`tool_frames` (tool axis
given by the CAD data) is deprecated: :func:`planner.cam.axis_field` replaces it.
"""

from planner.frames.double_reflection import double_reflection_frames
from planner.frames.er import er_frames
from planner.frames.grm import GRMFrame, grm, grm_from_coefficients
from planner.frames.juttler import ExactArcMotion, RationalArcMotion, arc_motion, exact_arc_motion, rmm_arc
from planner.frames.metrics import angular_velocity, frenet_frames, max_twist_deg, slerp_frames, twist_angles
from planner.frames.path import PathFrames, frame_field, path_frames
from planner.frames.ph_cubic_rmm import ph_cubic_rmm, ph_cubic_spline_rmm
from planner.frames.piecewise_motion import PiecewiseArcMotion, chain_arc_motion
from planner.frames.rmf import RMFAngle, rmf_frames
from planner.frames.spherical_biarc import SphericalBiarcSpline, fit_spherical_biarcs
from planner.frames.spherical_rmm import ExactSphericalRMM, exact_spherical_rmm, rational_spherical_rmm
from planner.frames.tool import ToolAxisWarning, ToolFrames, tool_frames
from planner.frames.validation import FrameDataError

__all__ = [
    "ExactArcMotion",
    "ExactSphericalRMM",
    "FrameDataError",
    "GRMFrame",
    "PathFrames",
    "PiecewiseArcMotion",
    "RMFAngle",
    "RationalArcMotion",
    "SphericalBiarcSpline",
    "ToolAxisWarning",
    "ToolFrames",
    "angular_velocity",
    "arc_motion",
    "chain_arc_motion",
    "double_reflection_frames",
    "er_frames",
    "exact_arc_motion",
    "exact_spherical_rmm",
    "fit_spherical_biarcs",
    "frame_field",
    "frenet_frames",
    "grm",
    "grm_from_coefficients",
    "max_twist_deg",
    "path_frames",
    "ph_cubic_rmm",
    "ph_cubic_spline_rmm",
    "rational_spherical_rmm",
    "rmf_frames",
    "rmm_arc",
    "slerp_frames",
    "tool_frames",
    "twist_angles",
]
