"""Reading toolpaths: CAM/CAD files (APT/CL data, 5-axis G-code, CSV, JSON) into a :class:`Toolpath`.

``read_toolpath(path, **options)`` picks the reader; every reader streams its file, returns points
in metres in the part frame with modal tool axes, per-span feeds (m/s), rapid flags, source lines
and events, and raises :class:`InputFileError` naming the file, line and field of any bad value.
"""

from planner.io.apt import read_apt
from planner.io.csv_reader import read_csv
from planner.io.cycles import DrillCycle, hole_moves
from planner.io.dispatch import detect_format, read_toolpath
from planner.io.errors import InputFileError, InputFileWarning, ReaderWarning
from planner.io.gcode import read_gcode
from planner.io.json_reader import read_json
from planner.io.machines import HAAS_UMC_750, MACHINES, TableTableKinematics, machine_kinematics
from planner.io.toolpath import EVENT_KINDS, Arc, Event, Nurbs, Toolpath, arc_samples, linearize_arcs

__all__ = [
    "EVENT_KINDS",
    "HAAS_UMC_750",
    "MACHINES",
    "Nurbs",
    "ReaderWarning",
    "Arc",
    "DrillCycle",
    "Event",
    "InputFileError",
    "InputFileWarning",
    "TableTableKinematics",
    "Toolpath",
    "arc_samples",
    "detect_format",
    "hole_moves",
    "linearize_arcs",
    "machine_kinematics",
    "read_apt",
    "read_csv",
    "read_gcode",
    "read_json",
    "read_toolpath",
]
