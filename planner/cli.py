"""Deprecated (kept for one release): the command line moved to :mod:`planner.frontends.cli`.

``planner.cli.main`` is :func:`planner.frontends.cli.main.main`; the shared options (``settings_from_args``,
``add_plan_options``, ...) are in :mod:`planner.frontends.cli.options`. Importing this module warns.
"""

from __future__ import annotations

import importlib
import warnings

warnings.warn("planner.cli is deprecated and will be removed in the next release: the command line is "
              "planner.frontends.cli (main: planner.frontends.cli.main, options: planner.frontends.cli.options)",
              DeprecationWarning, stacklevel=2)

_HOMES = ("planner.frontends.cli.main", "planner.frontends.cli.options")


def __getattr__(name: str):
    for home in _HOMES:
        module = importlib.import_module(home)
        if hasattr(module, name):
            return getattr(module, name)
    raise AttributeError(f"planner.cli (deprecated) has no {name!r}: see planner.frontends.cli")


if __name__ == "__main__":  # python -m planner.cli (deprecated): the planner command
    import sys

    sys.exit(importlib.import_module("planner.frontends.cli.main").main())
