"""Frame hashes in the index (pixels and sidecar sha256, the ZIP entry's CRC-32), so every copy
is checked before it is served.

Revision ID: 0003
Revises: 0002
"""

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"

_COLUMNS: dict[str, list[tuple[str, sa.types.TypeEngine]]] = {
    "frames": [("sha256", sa.String(64)), ("sidecar_sha256", sa.String(64))],
    "frame_blobs": [("crc32", sa.BigInteger())],
}


def upgrade() -> None:
    # 0001 creates tables from the current api.db metadata, so a fresh database may have them already.
    inspector = sa.inspect(op.get_bind())
    for table, columns in _COLUMNS.items():
        if table not in inspector.get_table_names():  # frame_blobs is gone from a fresh schema (0006)
            continue
        have = {c["name"] for c in inspector.get_columns(table)}
        for name, type_ in columns:
            if name not in have:
                op.add_column(table, sa.Column(name, type_, nullable=True))


def downgrade() -> None:
    for table, columns in _COLUMNS.items():
        for name, _ in columns:
            op.drop_column(table, name)
