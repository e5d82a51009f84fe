"""Our numerical failures are not the user's fault: ConvergenceError is a NumericalError, never a ValueError."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from planner.curves import fit_ph_spline
from planner.curves.ph_spline_c2 import solve_c2
from planner.errors import ConvergenceError, NumericalError, PlannerError, WaypointError
from planner.frames.spherical_biarc import fit_spherical_biarcs


def test_numerical_errors_are_not_user_errors():
    assert issubclass(ConvergenceError, NumericalError)
    assert issubclass(NumericalError, RuntimeError)
    for cls in (NumericalError, ConvergenceError):
        assert not issubclass(cls, ValueError)
        assert not issubclass(cls, PlannerError)
    assert issubclass(WaypointError, PlannerError) and issubclass(PlannerError, ValueError)


def test_forced_non_convergence_of_the_c2_solve_is_a_numerical_error():
    """No Newton step allowed: the C1 start (C2 jumps far above the tolerance) cannot be accepted."""
    t = np.linspace(0.0, 3.0, 9)
    p = np.column_stack((np.cos(t), np.sin(t), 0.3 * t * t))
    c1 = fit_ph_spline(p, continuity="C1")
    h = np.diff(c1.knots)
    tangents = c1.tangent(c1.knots[[0, -1]])
    with pytest.raises(NumericalError) as info:
        solve_c2(c1.A / np.sqrt(h)[:, None, None], p, h, tangents[0], tangents[1], max_iter=0)
    err = info.value
    assert isinstance(err, ConvergenceError) and not isinstance(err, ValueError)
    assert str(err).startswith("C2 PH spline did not converge (residual ")
    assert "numerical failure of the planner, not a problem with the input" in str(err)
    again = pickle.loads(pickle.dumps(err))  # a worker pool hands it over unchanged
    assert type(again) is ConvergenceError and str(again) == str(err) and again.detail == err.detail
    with pytest.raises(ValueError):  # while bad data stays the user's
        fit_ph_spline(np.zeros((3, 3)))


def test_corner_in_the_axis_curve_is_reported_as_ours():
    def corner(t):
        a = np.where(t < 0.5, t, 0.5) + 0.3
        b = np.where(t < 0.5, 0.0, t - 0.5)
        return np.stack((np.sin(a) * np.cos(b), np.sin(a) * np.sin(b), np.cos(a)), axis=1)

    with pytest.raises(NumericalError) as info:  # a ValueError would escape this and fail the test
        fit_spherical_biarcs(corner, 1e-9, interval=(0.0, 1.0))
    assert isinstance(info.value, ConvergenceError) and not isinstance(info.value, ValueError)
    assert "near t = 0.5" in str(info.value) and str(info.value).endswith(f"({NumericalError.NOTE})")


def test_singular_slope_system_is_ours():
    """Coincident knots (which the waypoint checks exclude upstream) make the LAPACK system singular: ours."""
    from planner.curves.tangents import slopes_rows

    with np.errstate(divide="ignore", invalid="ignore"), pytest.raises(NumericalError, match="singular cubic spline"):
        slopes_rows(np.array([0.0, 1.0, 1.0, 2.0]), np.ones((3, 3)))


def test_argument_errors_survive_pickling_between_processes():
    """Worker processes send errors back pickled: an ArgumentError keeps its argument and message."""
    import pickle

    from planner.validation import ArgumentError, as_floats

    try:
        as_floats(object(), "waypoints")
    except ArgumentError as exc:
        back = pickle.loads(pickle.dumps(exc))
        assert type(back) is ArgumentError and back.argument == "waypoints" and str(back) == str(exc)
        assert "an object" in str(back)
    else:
        raise AssertionError("as_floats accepted an object")
