"""Removed after version 0.1.0 (commit 5839d4a): the picture of a planned job is :func:`planner.plot.plot_job`.

Its name stays importable for the next release, with a ``DeprecationWarning`` naming the replacement
(:mod:`planner._deprecated`).
"""

from planner._deprecated import module_getattr

__getattr__ = module_getattr(__name__)
