"""Alembic environment: runs on the connection :func:`planner.frontends.service.store.migrate` passes in, or on the
``sqlalchemy.url`` of an ``alembic.ini`` (for ``alembic revision --autogenerate`` by developers)."""

from alembic import context
from sqlalchemy import engine_from_config, pool

from planner.frontends.service.store import Base

config = context.config
target_metadata = Base.metadata


def run() -> None:
    connection = config.attributes.get("connection")
    if connection is not None:
        context.configure(connection=connection, target_metadata=target_metadata, render_as_batch=True)
        with context.begin_transaction():
            context.run_migrations()
        return
    engine = engine_from_config(config.get_section(config.config_ini_section) or {}, prefix="sqlalchemy.",
                                poolclass=pool.NullPool)
    with engine.connect() as conn:
        context.configure(connection=conn, target_metadata=target_metadata, render_as_batch=True)
        with context.begin_transaction():
            context.run_migrations()


run()
