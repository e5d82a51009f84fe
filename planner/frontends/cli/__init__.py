"""The command line ``planner``: :mod:`~planner.frontends.cli.main` (the parser, ``fit``, ``plan``, ``demo``),
:mod:`~planner.frontends.cli.run` (``run``: plan and execute on a robot), :mod:`~planner.frontends.cli.options` (the
planning options the commands share); ``serve`` and ``keys`` come from :mod:`planner.frontends.service.cli`.
"""

from __future__ import annotations


def main(argv: list[str] | None = None) -> int:
    """``planner ...`` with ``argv`` (default ``sys.argv[1:]``): its exit status. (Imported when called, so that
    ``python -m planner.frontends.cli.main`` does not find its module already imported.)"""
    from planner.frontends.cli.main import main as run

    return run(argv)


__all__ = ["main"]
