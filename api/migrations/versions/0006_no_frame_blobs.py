"""No row per frame per format: where a frame sits in a stored-ZIP archive comes from the ZIP's
own central directory (api.reading.zip_index), so ``frame_blobs`` goes.

Revision ID: 0006
Revises: 0005
"""

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"


def upgrade() -> None:
    if "frame_blobs" in sa.inspect(op.get_bind()).get_table_names():
        op.drop_table("frame_blobs")


def downgrade() -> None:
    op.create_table(
        "frame_blobs",
        sa.Column("session_id", sa.String(128), sa.ForeignKey("sessions.id", ondelete="CASCADE"), primary_key=True),
        sa.Column("format", sa.String(32), primary_key=True),
        sa.Column("idx", sa.Integer(), primary_key=True),
        sa.Column("file", sa.Text(), nullable=False),
        sa.Column("offset", sa.BigInteger(), nullable=False),
        sa.Column("length", sa.BigInteger(), nullable=False),
        sa.Column("sidecar_offset", sa.BigInteger(), nullable=False),
        sa.Column("sidecar_length", sa.BigInteger(), nullable=False),
        sa.Column("crc32", sa.BigInteger()),
    )
