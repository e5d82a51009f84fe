"""Planning real CAM toolpaths: passes, tolerance-bounded PH fitting, modal tool axes, whole jobs.

``plan_cam_job(toolpath)`` splits a toolpath (:func:`planner.io.read_toolpath`) into cutting passes,
rapid moves and reorientations (:mod:`~planner.cam.passes`), fits every pass with a PH quintic spline
within a tolerance of the CAM polyline (:mod:`~planner.cam.fidelity`), interpolates the modal tool
axes without overshoot with rotation-minimizing spin (:mod:`~planner.cam.axes`), times every move and
checks the robot and chooses the arm configuration of every run of passes (:mod:`~planner.cam.job`,
:mod:`~planner.cam.reach`, :mod:`~planner.cam.configure`); ``CamJob.iter_stream()`` gives
the pose stream at the controller rate (:mod:`~planner.cam.stream`).
"""

from planner.cam.axes import AxisField, axis_field
from planner.cam.fidelity import PassFit, fit_pass, fit_passes
from planner.cam.job import CamJob, CamSettings, PassReport, PlannedMove, plan_cam_job
from planner.cam.moves import Reconfiguration
from planner.cam.passes import (
    CamInputError,
    CutPass,
    RapidMove,
    Reorientation,
    Segmentation,
    Skipped,
    split_passes,
)
from planner.cam.stream import JobStream, StreamChunk

__all__ = [
    "AxisField",
    "CamInputError",
    "CamJob",
    "CamSettings",
    "CutPass",
    "JobStream",
    "PassFit",
    "PassReport",
    "PlannedMove",
    "RapidMove",
    "Reconfiguration",
    "Reorientation",
    "Segmentation",
    "Skipped",
    "StreamChunk",
    "axis_field",
    "fit_pass",
    "fit_passes",
    "plan_cam_job",
    "split_passes",
]
