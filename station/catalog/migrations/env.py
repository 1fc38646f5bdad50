"""Alembic environment of the catalog: run on the connection station.catalog.db hands over
(config.attributes["connection"]); batch mode so SQLite can alter tables."""

from alembic import context

from station.catalog.models import Base

connection = context.config.attributes["connection"]
context.configure(connection=connection, target_metadata=Base.metadata, render_as_batch=True)
with context.begin_transaction():
    context.run_migrations()
