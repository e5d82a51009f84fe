"""The command line ``planner``: :mod:`~planner.frontends.cli.main` (the parser, ``fit``, ``plan``, ``demo``; its
``main(argv)`` is the command), :mod:`~planner.frontends.cli.run` (``run``: plan and execute on a robot),
:mod:`~planner.frontends.cli.options` (the planning options the commands share); ``serve`` and ``keys`` come from
:mod:`planner.frontends.service.cli`. ``python -m planner.frontends.cli`` runs the command.
"""
