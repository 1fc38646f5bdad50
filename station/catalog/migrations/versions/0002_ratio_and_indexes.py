"""verification ratio and outcome per leg row; indexes for history (serial, time) and leg lists
(serial, kind, outcome, time: a leg's last calibration and their count by two index seeks)

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
        batch.add_column(sa.Column("outcome", sa.String(32)))
    # rows written before: their record's outcome
    op.execute("UPDATE record_legs SET outcome = (SELECT outcome FROM records WHERE records.uid = record_legs.uid)")
    op.create_index("ix_record_legs_serial_time", "record_legs", ["leg_serial", "time_utc"])
    op.create_index("ix_record_legs_calibrations", "record_legs", ["leg_serial", "kind", "outcome", "time_utc"])


def downgrade() -> None:
    op.drop_index("ix_record_legs_calibrations", "record_legs")
    op.drop_index("ix_record_legs_serial_time", "record_legs")
    with op.batch_alter_table("record_legs") as batch:
        batch.drop_column("outcome")
        batch.drop_column("verification_ratio")
