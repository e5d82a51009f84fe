"""Deprecated (kept for one release): ``planner run`` is :mod:`planner.frontends.cli.run`, and running a job on a
robot as a library is :mod:`drivers.execute` (``execute_job``, ``start_sim``, ``run_demo_on_sim``, ``plot_run``,
``free_loopback_host``). Importing this module warns.
"""

from __future__ import annotations

import importlib
import warnings

warnings.warn("drivers.cli is deprecated and will be removed in the next release: use drivers.execute (execute_job, "
              "start_sim, run_demo_on_sim) and planner.frontends.cli.run (the planner run command)",
              DeprecationWarning, stacklevel=2)

_HOMES = ("drivers.execute", "planner.frontends.cli.run")


def __getattr__(name: str):
    for home in _HOMES:
        module = importlib.import_module(home)
        if hasattr(module, name):
            return getattr(module, name)
    raise AttributeError(f"drivers.cli (deprecated) has no {name!r}: see drivers.execute and planner.frontends.cli.run")
