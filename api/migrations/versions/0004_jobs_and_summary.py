"""The jobs table (what was asked, its state, attempts and error) and each session's frame
summary, which region series read instead of decoding every frame.

Revision ID: 0004
Revises: 0003
"""

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"


def upgrade() -> None:
    # 0001 creates tables from the current api.db metadata, so a fresh database may have them already.
    inspector = sa.inspect(op.get_bind())
    if "summary" not in {c["name"] for c in inspector.get_columns("sessions")}:
        op.add_column("sessions", sa.Column("summary", sa.Text(), nullable=True))
    if "jobs" not in inspector.get_table_names():
        op.create_table(
            "jobs",
            sa.Column("id", sa.String(96), primary_key=True),
            sa.Column("kind", sa.String(32), nullable=False),
            sa.Column("session_id", sa.String(128)),
            sa.Column("params", sa.Text(), nullable=False),
            sa.Column("state", sa.String(16), nullable=False),
            sa.Column("attempts", sa.Integer(), nullable=False),
            sa.Column("worker", sa.String(128)),
            sa.Column("error", sa.Text()),
            sa.Column("result", sa.Text()),
            sa.Column("created_ns", sa.BigInteger(), nullable=False),
            sa.Column("started_ns", sa.BigInteger()),
            sa.Column("finished_ns", sa.BigInteger()),
        )
        op.create_index("jobs_by_state", "jobs", ["state", "created_ns"])


def downgrade() -> None:
    op.drop_index("jobs_by_state", "jobs")
    op.drop_table("jobs")
    op.drop_column("sessions", "summary")
