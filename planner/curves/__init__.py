"""PH curves and splines: exact arc length, the carriers of every path the planner plans.

- :class:`PHQuintic`, :class:`PHCubic`: single spatial PH segments (quaternion form, grm seed).
- :func:`fit_ph_spline`: C1 or C2 PH quintic spline through waypoints -> :class:`PHSpline`.
- :func:`fit_ph_cubic_spline`: G1 PH cubic spline (Jüttler, section 7.1) -> :class:`PHSpline`.
"""

from planner.curves.ph_cubic import PHCubic
from planner.curves.ph_cubic_spline import fit_ph_cubic_spline
from planner.curves.ph_quintic import PHQuintic
from planner.curves.spline import PHSpline, fit_ph_spline

__all__ = ["PHCubic", "PHQuintic", "PHSpline", "fit_ph_cubic_spline", "fit_ph_spline"]
