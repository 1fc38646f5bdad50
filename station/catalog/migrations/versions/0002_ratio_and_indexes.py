"""verification ratio per leg; indexes for history (serial, time) and leg lists (kind, time)

Revision ID: 0002
Revises: 0001
"""
import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("record_legs") as batch:
        batch.add_column(sa.Column("verification_ratio", sa.Float))
    op.create_index("ix_record_legs_serial_time", "record_legs", ["leg_serial", "time_utc"])
    op.create_index("ix_record_legs_kind_time", "record_legs", ["kind", "time_utc"])


def downgrade() -> None:
    op.drop_index("ix_record_legs_kind_time", "record_legs")
    op.drop_index("ix_record_legs_serial_time", "record_legs")
    with op.batch_alter_table("record_legs") as batch:
        batch.drop_column("verification_ratio")
