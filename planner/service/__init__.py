"""Deprecated (kept for one release): the REST service moved to :mod:`planner.frontends.service`.

``python -m planner.service serve|keys ...`` still runs it (``planner serve`` / ``planner keys`` are the commands);
importing this package warns. Its modules are under ``planner.frontends.service`` (``app``, ``config``, ...).
"""

from __future__ import annotations

import importlib
import warnings

warnings.warn("planner.service is deprecated and will be removed in the next release: the REST service is "
              "planner.frontends.service (run it with `planner serve`)", DeprecationWarning, stacklevel=2)


def __getattr__(name: str):
    try:
        return importlib.import_module(f"planner.frontends.service.{name}")
    except ModuleNotFoundError:
        raise AttributeError(f"planner.service (deprecated) has no {name!r}: see planner.frontends.service") from None
