"""A frame's two sha256 as 32 bytes each instead of 64 hex characters: they were half of the
row that every frame of every session keeps (``api.db.Digest`` reads them back as hex).

Revision ID: 0008
Revises: 0007
"""

from typing import Any

import sqlalchemy as sa
from alembic import op

revision = "0008"
down_revision = "0007"

_COLUMNS = ("sha256", "sidecar_sha256")


def _convert(to_bytes: bool) -> None:
    """Every frame hash to bytes (``to_bytes``) or back to hex, whichever it is now."""
    if "frames" not in sa.inspect(op.get_bind()).get_table_names():  # a fresh schema since 0009
        return
    if op.get_bind().dialect.name == "sqlite":
        # SQLite keeps any value in any column: the values change, the declared type can stay.
        # Before 3.41 it has no unhex(): this does the same on the migration's own connection.
        raw: Any = op.get_bind().connection.dbapi_connection  # sqlite3.Connection
        raw.create_function("thermcap_hexbytes", 1, lambda v: (bytes.fromhex(v) if isinstance(v, str) else v)
                            if to_bytes else (bytes(v).hex() if isinstance(v, bytes) else v), deterministic=True)
        for col in _COLUMNS:
            op.execute(f"UPDATE frames SET {col} = thermcap_hexbytes({col}) "
                       f"WHERE typeof({col}) = '{'text' if to_bytes else 'blob'}'")
        return
    # 0001 creates tables from the current api.db metadata: a fresh database has bytes already
    types = {c["name"]: c["type"] for c in sa.inspect(op.get_bind()).get_columns("frames")}
    for col in _COLUMNS:
        if isinstance(types[col], sa.LargeBinary) != to_bytes:
            op.alter_column("frames", col, type_=sa.LargeBinary() if to_bytes else sa.String(64),
                            existing_type=sa.String(64) if to_bytes else sa.LargeBinary(),
                            postgresql_using=f"{'decode' if to_bytes else 'encode'}({col}, 'hex')")


def upgrade() -> None:
    _convert(to_bytes=True)


def downgrade() -> None:
    _convert(to_bytes=False)
