"""The examples in the docstrings of the entry points a user starts from run, and print what they say."""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = [
    "planner.plan",            # plan
    "planner.settings",        # PlanSettings and its declaration
    "planner.trajectory",      # Trajectory.chunks
    "planner.curves.spline",   # fit_ph_spline
    "planner.frames.path",     # frame_field
    "planner.export.verb",     # export
    "planner.job",             # PlannedJob.not_executable
    "drivers.execute",         # execute_job on a simulated controller
]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, verbose=False)
    assert result.attempted > 0, f"{name} has no example"
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples of {name} failed (printed above)"
