"""Removed after version 0.1.0 (commit 5839d4a): a job's CSV and JSON are ``planner.export.write_csv`` and
``write_json`` of ``job.trajectory(rate)``.

Its names stay importable for the next release, each with a ``DeprecationWarning`` naming its replacement
(:mod:`planner._deprecated`).
"""

from planner._deprecated import module_getattr

__getattr__ = module_getattr(__name__)
