"""Offline exports of a planned job: CSV and JSON pose streams, URScript programs (servoj or movep).

Every export carries the generator, the job's parameters and the tool I/O events.
"""

from planner.export.header import ExportError, generator, job_parameters
from planner.export.movep import MovePPlan, plan_movep
from planner.export.tables import PoseRecord, read_csv, read_json, write_csv, write_json
from planner.export.urscript import movep_program, servoj_program, write_script

__all__ = [
    "ExportError",
    "MovePPlan",
    "PoseRecord",
    "generator",
    "job_parameters",
    "movep_program",
    "plan_movep",
    "read_csv",
    "read_json",
    "servoj_program",
    "write_csv",
    "write_json",
    "write_script",
]
