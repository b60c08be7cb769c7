"""A session's frames leave the database: their per-frame facts go to one columnar file per
session in the blob store (``sessions.frames_key``), and a search across sessions reads
``target_seconds``, a row per second that holds a target. 157 bytes a frame (34 MB a
camera-hour) become a few per second.

The rows an older index holds are not dropped here: the table is renamed ``frames_legacy`` and
the next scan (``api.indexing.convert_legacy_frames``) writes each session's file from them,
so a session the index serves from a bucket alone, whose folder is gone, keeps its frames.

Revision ID: 0009
Revises: 0008
"""

import sqlalchemy as sa
from alembic import op

revision = "0009"
down_revision = "0008"


def _session_key() -> sa.Column:
    """The first half of a per-session table's key: its rows go with their session."""
    return sa.Column("session_id", sa.String(128), sa.ForeignKey("sessions.id", ondelete="CASCADE"),
                     primary_key=True)


def upgrade() -> None:
    inspector = sa.inspect(op.get_bind())
    tables = inspector.get_table_names()
    if "frames_key" not in {c["name"] for c in inspector.get_columns("sessions")}:
        op.add_column("sessions", sa.Column("frames_key", sa.Text(), nullable=True))
    if "target_seconds" not in tables:  # 0001 made it already on a fresh database
        op.create_table(
            "target_seconds",
            _session_key(),
            sa.Column("second", sa.BigInteger(), primary_key=True),
            sa.Column("max_target_temp_c", sa.Float(), nullable=False),
            sa.Column("min_target_temp_c", sa.Float(), nullable=False),
            sa.Column("min_grade", sa.Float()),
            sa.Column("frames", sa.LargeBinary(), nullable=False),
        )
        op.create_index("ix_target_seconds_hot", "target_seconds",
                        [sa.text("max_target_temp_c DESC"), "session_id", "second"])
    if "frames" in tables:
        for index in inspector.get_indexes("frames"):
            if index["name"]:
                op.drop_index(index["name"], "frames")
        op.rename_table("frames", "frames_legacy")


def _frames_indexes() -> None:
    """The indexes ``frames`` had at 0008 (0001's and 0007's): upgrade dropped them with its name."""
    op.create_index("ix_frames_time", "frames", ["session_id", "timestamp_ns"])
    op.create_index("ix_frames_hot", "frames", [sa.text("max_target_temp_c DESC"), "session_id", "idx", "grade"],
                    sqlite_where=sa.text("max_target_temp_c IS NOT NULL"),
                    postgresql_where=sa.text("max_target_temp_c IS NOT NULL"))
    op.create_index("ix_frames_graded", "frames", ["grade"], sqlite_where=sa.text("grade IS NOT NULL"),
                    postgresql_where=sa.text("grade IS NOT NULL"))


def downgrade() -> None:
    """Back to a row per frame, for the code before 0009.

    The rows an index kept aside and no scan has converted yet come back as they were. A session
    whose frames went to a file has no rows, or only rows older than that file: the file is not
    turned back into rows. Its fingerprint is cleared instead, so the older code's next scan
    indexes it again from its folder. A session served from a bucket alone has no folder to scan,
    so it has no frame rows under the older code. Its frames file stays in the store."""
    tables = sa.inspect(op.get_bind()).get_table_names()
    op.execute(sa.text("UPDATE sessions SET fingerprint = '' WHERE frames_key IS NOT NULL"))
    if "frames_legacy" in tables:
        op.rename_table("frames_legacy", "frames")
    else:
        op.create_table(
            "frames",
            _session_key(),
            sa.Column("idx", sa.Integer(), primary_key=True),
            sa.Column("timestamp_ns", sa.BigInteger(), nullable=False),
            sa.Column("segment", sa.String(64)),
            sa.Column("grade", sa.Float()),
            sa.Column("slew_to_cue", sa.Boolean(), nullable=False, server_default=sa.false()),
            sa.Column("target_count", sa.Integer(), nullable=False, server_default="0"),
            sa.Column("max_target_temp_c", sa.Float()),
            sa.Column("sha256", sa.LargeBinary()),  # 32 bytes since 0008
            sa.Column("sidecar_sha256", sa.LargeBinary()),
        )
    _frames_indexes()
    op.drop_index("ix_target_seconds_hot", "target_seconds")
    op.drop_table("target_seconds")
    op.drop_column("sessions", "frames_key")
