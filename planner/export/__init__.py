"""Offline exports of a planned job: CSV and JSON pose streams, URScript programs (servoj or movep).

Every export carries the generator, the job's parameters and the tool I/O events. A whole CAM job
(:class:`planner.cam.CamJob`) is written move by move (:mod:`~planner.export.job_tables`) or as one
compact movep/movel program (:mod:`~planner.export.job_script`).
"""

from planner.export.header import ExportError, cam_job_parameters, generator, job_parameters
from planner.export.job_script import ProgramMove, job_program, plan_job_program
from planner.export.job_tables import write_job_csv, write_job_json
from planner.export.movep import MovePPlan, plan_movep
from planner.export.tables import PoseRecord, read_csv, read_json, write_csv, write_json
from planner.export.urscript import movep_program, servoj_program, write_script

__all__ = [
    "ExportError",
    "MovePPlan",
    "PoseRecord",
    "ProgramMove",
    "cam_job_parameters",
    "generator",
    "job_parameters",
    "job_program",
    "movep_program",
    "plan_job_program",
    "plan_movep",
    "read_csv",
    "read_json",
    "servoj_program",
    "write_csv",
    "write_job_csv",
    "write_job_json",
    "write_json",
    "write_script",
]
