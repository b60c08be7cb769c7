"""The first index schema: sessions, segments, archives, frames, frame_blobs, events.

Revision ID: 0001
Revises:
"""

from alembic import op

revision = "0001"
down_revision = None


def upgrade() -> None:
    # The initial revision creates api.db's tables as they stood at 0001; later revisions alter
    # them with explicit operations, never by editing this one.
    from thermcap.api.db import metadata

    metadata.create_all(op.get_bind(), tables=[t for t in metadata.sorted_tables
                                                  if t.name not in ("leases", "jobs")])


def downgrade() -> None:
    from thermcap.api.db import metadata

    metadata.drop_all(op.get_bind())
