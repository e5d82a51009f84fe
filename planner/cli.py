"""Deprecated (kept for one release): the command line moved to :mod:`planner.frontends.cli`.

``planner.cli.main`` is :func:`planner.frontends.cli.main.main`; the shared options (``settings_from_args``,
``add_plan_options``, ...) are in :mod:`planner.frontends.cli.options`. Importing this module warns.
"""

from planner._deprecated import moved_module

__getattr__ = moved_module(__name__, ("planner.frontends.cli.main", "planner.frontends.cli.options"),
                           "the command line is planner.frontends.cli (main: planner.frontends.cli.main, options: "
                           "planner.frontends.cli.options)")

if __name__ == "__main__":  # python -m planner.cli (deprecated): the planner command
    import sys

    sys.exit(__getattr__("main")())
