"""the ISO 14253-1 verdict of each leg row of a session, decided at ingest (station.catalog.readers
.decide_legs: the session's ISO 230-2 values with U against the tolerances the session recorded, at
its stage), so the web's decision filter and charts read a column instead of deciding every leg of
the fleet on each request

Rows indexed before stay NULL: the web decides those at request time against its own
[tolerances] as it did before this revision, and `station catalog rebuild` decides them from the files.

Revision ID: 0004
Revises: 0003
"""
import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("record_legs") as batch:
        batch.add_column(sa.Column("decision", sa.String(32)))


def downgrade() -> None:
    with op.batch_alter_table("record_legs") as batch:
        batch.drop_column("decision")
