"""PH curves and splines: exact arc length, the carriers of every path the planner plans.

- :class:`PHQuintic`, :class:`PHCubic`: single spatial PH segments (quaternion form, grm seed).
- :func:`fit_ph_spline`: C1 or C2 PH quintic spline through waypoints -> :class:`PHSpline`.
- :func:`fit_ph_cubic_spline`: G1 PH cubic spline (Jüttler, section 7.1) -> :class:`PHSpline`.
- :class:`DPCubic`, :func:`dp_ph_hermite`, :func:`fit_planar_ph_spline`: planar DP-PH cubics (DP seed).
- :class:`RationalPH` and the closed-form classes 3-6: spatial rational PH curves in dual form.
"""

from planner.curves.dp_cubic import DPCubic
from planner.curves.dp_ph_hermite import dp_ph_error, dp_ph_hermite
from planner.curves.ph_cubic import PHCubic
from planner.curves.ph_cubic_spline import fit_ph_cubic_spline
from planner.curves.ph_quintic import PHQuintic
from planner.curves.planar_ph_spline import PlanarPHSpline, fit_planar_ph_spline
from planner.curves.rational_ph import RationalPH
from planner.curves.rational_ph_families import class3, class4, class5, class6
from planner.curves.spline import PHSpline, fit_ph_spline

__all__ = [
    "DPCubic",
    "PHCubic",
    "PHQuintic",
    "PHSpline",
    "PlanarPHSpline",
    "RationalPH",
    "class3",
    "class4",
    "class5",
    "class6",
    "dp_ph_error",
    "dp_ph_hermite",
    "fit_planar_ph_spline",
    "fit_ph_cubic_spline",
    "fit_ph_spline",
]
