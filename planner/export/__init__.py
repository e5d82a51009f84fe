"""Offline exports of a planned job: CSV and JSON tables, a URScript program, the plot and the saved plan.

The export verb (:mod:`planner.export.verb`: :func:`export`, :func:`stream`, :func:`write`) gives any of them as
bytes or writes it by a file's suffix; the command line and the REST service both take their exports from it.
Formatters only: they read a :class:`planner.trajectory.Trajectory` (or, for the program, the job's moves
and their planned movep targets) and never plan. Every export carries the generator, the job's settings
and figures, and is written atomically.
"""

from planner.export.files import (
    OutputTarget,
    atomic_binary,
    atomic_text,
    check_output,
    output_target,
    write_bytes_atomic,
)
from planner.export.header import ExportError, generator, trajectory_parameters
from planner.export.job_script import (
    MAX_PROGRAM_BYTES,
    ProgramMove,
    ProgramPiece,
    job_program,
    job_program_pieces,
    plan_job_program,
)
from planner.export.movep import MovePPlan, plan_movep
from planner.export.tables import JSON_FORMAT, csv_text, json_text, write_csv, write_json
from planner.export.urscript import write_script
from planner.export.verb import FORMATS, export, file_name, format_of, plot_title, stream, write

__all__ = [
    "FORMATS",
    "JSON_FORMAT",
    "MAX_PROGRAM_BYTES",
    "ExportError",
    "MovePPlan",
    "OutputTarget",
    "ProgramMove",
    "ProgramPiece",
    "atomic_binary",
    "atomic_text",
    "check_output",
    "csv_text",
    "export",
    "file_name",
    "format_of",
    "generator",
    "job_program",
    "job_program_pieces",
    "json_text",
    "output_target",
    "plan_job_program",
    "plan_movep",
    "plot_title",
    "stream",
    "trajectory_parameters",
    "write_bytes_atomic",
    "write_csv",
    "write_json",
    "write",
    "write_script",
]

# Names of version 0.1.0 removed since, importable for the next release with a DeprecationWarning naming the
# replacement (planner._deprecated).
from planner._deprecated import module_getattr as _module_getattr  # noqa: E402

__getattr__ = _module_getattr(__name__)
