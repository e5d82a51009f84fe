"""The REST service for path jobs (``planner serve``): FastAPI app, SQLite/SQLAlchemy store, worker processes.

A front end like the CLI: every job is planned by :func:`planner.plan` in a worker process, saved with
:meth:`planner.PlannedJob.save`, and its exports are streamed from the saved job by the same writers the CLI
uses (byte for byte the files ``planner plan -o`` writes).

Modules: :mod:`~planner.service.config` (settings from the environment), :mod:`~planner.service.store` (tables,
engine, migrations), :mod:`~planner.service.auth` (API keys and roles), :mod:`~planner.service.schemas` (the
request and response models; ``SettingsModel`` mirrors :class:`planner.PlanSettings`), :mod:`~planner.service.workers`
(the pool of planning processes), :mod:`~planner.service.app` (routes), :mod:`~planner.service.cli` (``planner serve``
and ``planner keys``).
"""
