"""The REST service for path jobs (``planner serve``): FastAPI app, SQLite/SQLAlchemy store, worker processes.

A front end like the CLI: every job is planned by :func:`planner.plan` in a worker process, saved with
:meth:`planner.PlannedJob.save`, and its exports are streamed from the saved job by the export verb the CLI
uses (:mod:`planner.export.verb`: byte for byte the files ``planner plan -o`` writes).

Laid out as FastAPI's full-stack template: :mod:`.app` (``create_app``: the lifespan and the wiring),
:mod:`.routes` (one module per resource: ``jobs``, ``exports``, ``executions``, ``service``), :mod:`.deps` (what
the routes share, as ``Annotated`` dependencies: the service, the caller, the caller's own job), :mod:`.schemas`
(the request and the typed response models, with their unit convention). Beside them: :mod:`.submit` (a job's
input checked and stored), :mod:`.fast_submit` (the measured fast path of a JSON submit), :mod:`.body_limit`,
:mod:`.errors` (422 naming the field), :mod:`.config` (settings from the environment), :mod:`.store` (tables,
engine, migrations), :mod:`.auth` (API keys and roles), :mod:`.tasks` (the task layer: planning and executions
on robots, one life cycle, run by the local backend's worker processes or by Celery workers), :mod:`.inserter` (new
jobs in group commits), :mod:`.plots` (the drawing process), :mod:`.cli` (``planner serve``, ``planner worker`` and
``planner keys``).
"""
