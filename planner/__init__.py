"""Robot tool-orientation planning: PH paths, rotation-minimizing tool frames, timing and export.

One entry point: ``plan(source, PlanSettings(...))`` turns a toolpath file, a read toolpath or waypoints
into a :class:`PlannedJob`; ``job.trajectory()`` is the one stream every consumer reads (exports, plot,
drivers, service). The planning core is pure computation: it never does network I/O and never imports
``drivers``, ``sim`` or the service layer.
"""

from planner.errors import NumericalError, PlannerError
from planner.job import PlannedJob, load_job
from planner.plan import plan
from planner.settings import PlanSettings
from planner.trajectory import Chunk, Trajectory

__version__ = "0.2.0.dev0"

__all__ = ["Chunk", "NumericalError", "PlanSettings", "PlannedJob", "PlannerError", "Trajectory", "load_job", "plan"]
