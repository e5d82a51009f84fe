"""The REST service for path jobs (``planner serve``): FastAPI app, SQLite/SQLAlchemy store, worker processes.

A front end like the CLI: every job is planned by :func:`planner.plan` in a worker process, saved with
:meth:`planner.PlannedJob.save`, and its exports are streamed from the saved job by the same writers the CLI
uses (byte for byte the files ``planner plan -o`` writes).

Modules: :mod:`.config` (settings from the environment), :mod:`.store` (tables, engine, migrations), :mod:`.auth`
(API keys and roles), :mod:`.schemas` (the request and response models), :mod:`.deps` (what the routes share: the
service, the caller, the caller's job), :mod:`.workers` (the pool of planning processes), :mod:`.app` (the job
routes), :mod:`.executions` (the execution routes), :mod:`.cli` (``planner serve`` and ``planner keys``).
"""
