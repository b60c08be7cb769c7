"""Indexes for a fleet-sized catalog: the session list's order (newest first) without a sort of
every session, and the frames a search asks for (graded frames, frames with a target) without a
scan of every frame. Partial indexes: most frames have no target, so those entries cost nothing.

Revision ID: 0007
Revises: 0006
"""

import sqlalchemy as sa
from alembic import op

revision = "0007"
down_revision = "0006"


def upgrade() -> None:
    inspector = sa.inspect(op.get_bind())
    tables = [t for t in ("sessions", "frames") if t in inspector.get_table_names()]  # no frames table since 0009
    have = {i["name"] for t in tables for i in inspector.get_indexes(t)}
    if "ix_sessions_catalog" not in have:
        op.create_index("ix_sessions_catalog", "sessions", [sa.text("coalesce(start_ns, 0)"), "id"])
    if "frames" not in tables:
        return
    if "ix_frames_hot" not in have:
        # In the search's own order (hottest first, then session and frame), with the grade in it:
        # a search walks it from the top and stops at a page, never fetching the frames it skips.
        op.create_index("ix_frames_hot", "frames", [sa.text("max_target_temp_c DESC"), "session_id", "idx", "grade"],
                        sqlite_where=sa.text("max_target_temp_c IS NOT NULL"),
                        postgresql_where=sa.text("max_target_temp_c IS NOT NULL"))
    if "ix_frames_graded" not in have:
        op.create_index("ix_frames_graded", "frames", ["grade"], sqlite_where=sa.text("grade IS NOT NULL"),
                        postgresql_where=sa.text("grade IS NOT NULL"))


def downgrade() -> None:
    for name, table in (("ix_frames_graded", "frames"), ("ix_frames_hot", "frames"),
                        ("ix_sessions_catalog", "sessions")):
        op.drop_index(name, table)
