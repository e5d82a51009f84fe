"""Removed after version 0.1.0 (commit 5839d4a): the pose stream of a job is ``job.trajectory(rate)``
(:class:`planner.Trajectory`).

Its names stay importable for the next release, each with a ``DeprecationWarning`` naming its replacement
(:mod:`planner._deprecated`).
"""

from planner._deprecated import module_getattr

__getattr__ = module_getattr(__name__)
