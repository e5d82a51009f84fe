"""Alembic migrations of the job store (run by :func:`planner.service.store.migrate` at start-up)."""
