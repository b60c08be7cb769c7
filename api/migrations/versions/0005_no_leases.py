"""The lease loop is retired (jobs run on Dask; the manifest, the parts and the locks are the
durable truth, the jobs table the record): its table goes.

Revision ID: 0005
Revises: 0004
"""

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"


def upgrade() -> None:
    if "leases" in sa.inspect(op.get_bind()).get_table_names():
        op.drop_table("leases")


def downgrade() -> None:
    op.create_table("leases", sa.Column("session_id", sa.String(128), primary_key=True),
                    sa.Column("owner", sa.String(128), nullable=False),
                    sa.Column("expires_ns", sa.BigInteger(), nullable=False))
