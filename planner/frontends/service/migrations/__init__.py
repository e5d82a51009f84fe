"""Alembic migrations of the job store (run by :func:`planner.frontends.service.store.migrate` at start-up)."""
