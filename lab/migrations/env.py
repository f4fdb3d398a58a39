"""Alembic's environment for the lab record: always run from hopkinson.lab.database with an open
connection (config.attributes["connection"]); no alembic.ini, no URL of its own."""

from __future__ import annotations

from alembic import context

from hopkinson.lab.schema import Base

connection = context.config.attributes["connection"]
context.configure(connection=connection, target_metadata=Base.metadata, render_as_batch=True)
with context.begin_transaction():
    context.run_migrations()
