"""Teams: a key belongs to a team, a job and its executions to the team of the key that submitted the job; keys, jobs
and executions made before are the "default" team's, which may use every configured robot.

Revision ID: 0004
Revises: 0003
Create Date: 2026-12-02
"""

import time

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None

#: The team of everything made before teams (planner.frontends.service.store.DEFAULT_TEAM, written out: a migration
#: keeps the value it was written with).
DEFAULT_TEAM = "default"


def upgrade() -> None:
    teams = op.create_table(
        "teams",
        sa.Column("name", sa.String(32), primary_key=True),
        sa.Column("robots", sa.Text, nullable=True),  # JSON list of robot names; NULL: every configured robot
        sa.Column("created_at", sa.Float, nullable=False),
    )
    op.bulk_insert(teams, [{"name": DEFAULT_TEAM, "robots": None, "created_at": time.time()}])
    for table in ("api_keys", "jobs", "executions"):  # (an added column: no copy of the table on SQLite)
        with op.batch_alter_table(table) as t:
            t.add_column(sa.Column("team", sa.String(32), nullable=False, server_default=DEFAULT_TEAM))
    op.drop_index("ix_jobs_owner_seq", "jobs")
    op.create_index("ix_jobs_team_seq", "jobs", ["team", "seq"])
    op.drop_index("ix_executions_owner_seq", "executions")
    op.create_index("ix_executions_team_seq", "executions", ["team", "seq"])


def downgrade() -> None:
    op.drop_index("ix_executions_team_seq", "executions")
    op.create_index("ix_executions_owner_seq", "executions", ["owner", "seq"])
    op.drop_index("ix_jobs_team_seq", "jobs")
    op.create_index("ix_jobs_owner_seq", "jobs", ["owner", "seq"])
    for table in ("executions", "jobs", "api_keys"):
        with op.batch_alter_table(table) as t:
            t.drop_column("team")
    op.drop_table("teams")
