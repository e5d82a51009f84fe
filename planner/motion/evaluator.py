"""The motion layer's access to fast arc-length inversion: one cached
:class:`~planner.curves.arc_evaluator.SplineEvaluator` per path, and the arc length of its spans."""

from __future__ import annotations

import weakref

import numpy as np

from planner.curves.arc_evaluator import SplineEvaluator

_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def evaluator_for(path) -> SplineEvaluator:
    """The :class:`SplineEvaluator` of a PH spline, built once per path object (weakly cached)."""
    try:
        ev = _CACHE.get(path)
    except TypeError:  # not weak-referenceable or not hashable: build every time
        return SplineEvaluator.of(path)
    if ev is None:
        ev = _CACHE[path] = SplineEvaluator.of(path)
    return ev


def span_bounds(path) -> np.ndarray:
    """Arc length (m) at every user waypoint of a path (the span ends): 0 first, the length last."""
    if not hasattr(path, "length"):
        from planner.motion.limits import MotionInputError

        raise MotionInputError("path", f"must be a path (a PH spline from fit_ph_spline), got {type(path).__name__}")
    L = float(path.length)
    wk = getattr(path, "waypoint_knots", None)
    if wk is None:
        return np.array([0.0, L])
    wk = np.asarray(wk, float)
    if hasattr(path, "sigma_coeffs"):  # waypoints are knots, whose arc lengths are tabulated
        ev = evaluator_for(path)
        b = ev.cumulative[np.clip(np.searchsorted(ev.knots, wk), 0, ev.knots.size - 1)].copy()
    else:
        b = np.asarray(path.arc_length(wk), float)
    b[0], b[-1] = 0.0, L
    return b
