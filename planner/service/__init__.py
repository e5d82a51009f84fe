"""Deprecated (kept for one release): the REST service moved to :mod:`planner.frontends.service`.

``python -m planner.service serve|keys ...`` still runs it (``planner serve`` / ``planner keys`` are the commands);
importing this package warns. Its modules are under ``planner.frontends.service`` (``app``, ``config``, ...).
"""

import importlib

from planner._deprecated import moved_module

_served = moved_module(__name__, (), "the REST service is planner.frontends.service (run it with `planner serve`)")


def __getattr__(name: str):
    try:
        return importlib.import_module(f"planner.frontends.service.{name}")
    except ModuleNotFoundError:
        return _served(name)  # AttributeError naming the new home
