"""Planning real CAM toolpaths: passes, tolerance-bounded PH fitting, modal tool axes, whole jobs.

The parts of :func:`planner.plan` that real CAM toolpaths need: the split into cutting passes, rapid
moves and reorientations (:mod:`~planner.cam.passes`), PH quintic splines within a tolerance of the CAM
polyline (:mod:`~planner.cam.fidelity`), the modal tool axes interpolated without overshoot with
rotation-minimizing spin (:mod:`~planner.cam.axes`), rapids and turns (:mod:`~planner.cam.moves`), and the
robot check with the arm configuration of every run of passes (:mod:`~planner.cam.reach`,
:mod:`~planner.cam.configure`).
"""

from planner.cam.axes import AxisField, axis_field
from planner.cam.fidelity import PassFit, fit_pass, fit_passes
from planner.cam.moves import Reconfiguration
from planner.cam.passes import (
    CamInputError,
    CutPass,
    Dwell,
    RapidMove,
    Reorientation,
    Segmentation,
    Skipped,
    split_passes,
)

__all__ = [
    "AxisField",
    "CamInputError",
    "CutPass",
    "Dwell",
    "PassFit",
    "RapidMove",
    "Reconfiguration",
    "Reorientation",
    "Segmentation",
    "Skipped",
    "axis_field",
    "fit_pass",
    "fit_passes",
    "split_passes",
]

# Names of version 0.1.0 removed since, importable for the next release with a DeprecationWarning naming the
# replacement (planner._deprecated).
from planner._deprecated import module_getattr as _module_getattr  # noqa: E402

__getattr__ = _module_getattr(__name__)
