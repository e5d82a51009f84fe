"""The picture of a planned job: moved to :mod:`planner.export.plot` (a plot is one of the export verb's formats,
:func:`planner.export.export`). ``from planner.plot import plot_job`` keeps working: every name of
:mod:`planner.export.plot` is reachable here.
"""

from __future__ import annotations

import importlib

from planner.export.plot import PLOT_SUFFIXES, StreamDigest, check_plot_target, digest, plot_job

__all__ = ["PLOT_SUFFIXES", "StreamDigest", "check_plot_target", "digest", "plot_job"]


def __getattr__(name: str):
    return getattr(importlib.import_module("planner.export.plot"), name)
