"""baseline: stations, legs, instruments, records, record_legs, outbox

Revision ID: 0001
Revises:
"""
import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table("stations", sa.Column("id", sa.String(128), primary_key=True), sa.Column("host", sa.String(255)))
    op.create_table("legs", sa.Column("serial", sa.String(128), primary_key=True),
                    sa.Column("part_number", sa.String(128)), sa.Column("leg_type", sa.String(128)),
                    sa.Column("screw_lot", sa.String(128)))
    op.create_index("ix_legs_leg_type", "legs", ["leg_type"])
    op.create_table("instruments", sa.Column("serial", sa.String(128), primary_key=True),
                    sa.Column("model", sa.String(128)), sa.Column("calibration_due", sa.String(32)),
                    sa.Column("calibrated_on", sa.String(32)))
    op.create_table(
        "records",
        sa.Column("uid", sa.String(200), primary_key=True), sa.Column("kind", sa.String(16), nullable=False),
        sa.Column("time_utc", sa.String(32), nullable=False), sa.Column("station_id", sa.String(128)),
        sa.Column("operator", sa.String(128)), sa.Column("software_version", sa.String(64)),
        sa.Column("instrument_serial", sa.String(128)), sa.Column("outcome", sa.String(32)),
        sa.Column("path", sa.Text), sa.Column("sha256", sa.String(64)), sa.Column("source_sha256", sa.String(64)),
        sa.Column("summary", sa.JSON),
    )
    for col in ("kind", "time_utc", "station_id", "sha256"):
        op.create_index(f"ix_records_{col}", "records", [col])
    figures = [sa.Column(f"{n}{s}", sa.Float) for n in ("E", "A", "B", "R", "M") for s in ("_um", "_U_um")]
    op.create_table(
        "record_legs",
        sa.Column("uid", sa.String(200), sa.ForeignKey("records.uid", ondelete="CASCADE"), primary_key=True),
        sa.Column("leg", sa.Integer, primary_key=True), sa.Column("kind", sa.String(16), nullable=False),
        sa.Column("time_utc", sa.String(32), nullable=False), sa.Column("station_id", sa.String(128)),
        sa.Column("leg_serial", sa.String(128)), sa.Column("drive", sa.Text), sa.Column("table_sha256", sa.String(64)),
        *figures, sa.Column("figures", sa.JSON),
    )
    op.create_table("outbox", sa.Column("uid", sa.String(200), primary_key=True))


def downgrade() -> None:
    for name in ("outbox", "record_legs", "records", "instruments", "legs", "stations"):
        op.drop_table(name)
