"""Alembic environment: runs on the connection ``api.db.migrate`` hands it."""

from alembic import context

from thermcap.api.db import metadata

connection = context.config.attributes["connection"]
context.configure(connection=connection, target_metadata=metadata)
with context.begin_transaction():
    context.run_migrations()
