"""One task layer: the columns jobs and executions share (attempts, holder, heartbeat_at), a job's bytes in the
database (job_data: the uploaded input and the saved plan) and the worker processes of the celery backend.

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-28
"""

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("jobs") as t:
        t.add_column(sa.Column("holder", sa.String(64), nullable=True))
        t.add_column(sa.Column("heartbeat_at", sa.Float, nullable=True))
    with op.batch_alter_table("executions") as t:
        t.add_column(sa.Column("attempts", sa.Integer, nullable=False, server_default="0"))
        t.add_column(sa.Column("holder", sa.String(64), nullable=True))
        t.add_column(sa.Column("heartbeat_at", sa.Float, nullable=True))
    op.create_table(
        "job_data",
        sa.Column("job_id", sa.String(32), primary_key=True),
        sa.Column("name", sa.String(16), primary_key=True),
        sa.Column("data", sa.LargeBinary, nullable=False),
        sa.Column("bytes", sa.Integer, nullable=False),
        sa.Column("created_at", sa.Float, nullable=False),
    )
    op.create_table(
        "workers",
        sa.Column("id", sa.String(64), primary_key=True),
        sa.Column("queues", sa.String(200), nullable=False),
        sa.Column("concurrency", sa.Integer, nullable=False),
        sa.Column("started_at", sa.Float, nullable=False),
        sa.Column("heartbeat_at", sa.Float, nullable=False),
        sa.Column("busy", sa.Integer, nullable=False, server_default="0"),
    )


def downgrade() -> None:
    op.drop_table("workers")
    op.drop_table("job_data")
    with op.batch_alter_table("executions") as t:
        t.drop_column("heartbeat_at")
        t.drop_column("holder")
        t.drop_column("attempts")
    with op.batch_alter_table("jobs") as t:
        t.drop_column("heartbeat_at")
        t.drop_column("holder")
