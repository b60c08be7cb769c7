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


def _sqlite_functions() -> None:
    # SQLite before 3.41 has no unhex(); these do the same on the migration's own connection
    raw: Any = op.get_bind().connection.dbapi_connection  # sqlite3.Connection
    raw.create_function("thermcap_unhex", 1, lambda v: bytes.fromhex(v) if isinstance(v, str) else v,
                        deterministic=True)
    raw.create_function("thermcap_hex", 1, lambda v: bytes(v).hex() if isinstance(v, bytes) else v,
                        deterministic=True)


def upgrade() -> None:
    bind = op.get_bind()
    if bind.dialect.name == "sqlite":
        # SQLite keeps any value in any column: the values change, the declared type can stay
        _sqlite_functions()
        for col in _COLUMNS:
            op.execute(f"UPDATE frames SET {col} = thermcap_unhex({col}) WHERE typeof({col}) = 'text'")
    else:
        # 0001 creates tables from the current api.db metadata: a fresh database has them already
        for col in _COLUMNS:
            if not _is_binary(col):
                op.alter_column("frames", col, type_=sa.LargeBinary(), existing_type=sa.String(64),
                                postgresql_using=f"decode({col}, 'hex')")


def _is_binary(col: str) -> bool:
    types = {c["name"]: c["type"] for c in sa.inspect(op.get_bind()).get_columns("frames")}
    return isinstance(types[col], sa.LargeBinary)


def downgrade() -> None:
    bind = op.get_bind()
    if bind.dialect.name == "sqlite":
        _sqlite_functions()
        for col in _COLUMNS:
            op.execute(f"UPDATE frames SET {col} = thermcap_hex({col}) WHERE typeof({col}) = 'blob'")
    else:
        for col in _COLUMNS:
            if _is_binary(col):
                op.alter_column("frames", col, type_=sa.String(64), existing_type=sa.LargeBinary(),
                                postgresql_using=f"encode({col}, 'hex')")
