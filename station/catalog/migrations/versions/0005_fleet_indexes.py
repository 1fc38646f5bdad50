"""covering indexes for the fleet's leg list, its decision filter and the control charts (issue 33.3):
every per-leg lookup of `history.legs` and every chart query reads the index alone, never the rows

- ix_record_legs_last (serial, kind, outcome, stage, time, station, E, B, R): a leg's count of
  as-found calibrations / as-left verifications and its last calibration's station, E and B; the
  charts' aggregates and most recent values of a leg type per stage
- ix_record_legs_calibrations widened to (serial, kind, outcome, time, uid, decision, stage): the
  verdict of a leg's latest completed session (the decision filter) and its count of as-left
  verifications without reading the row; its old columns are its prefix, so every query that
  used it still does

Measured with bench/bench_web.py (docs/web.md, Figures): on SQLite the leg list's query went from
seven index seeks plus seven row reads per leg to seven index-only seeks.

Revision ID: 0005
Revises: 0004
"""
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None

LAST = ["leg_serial", "kind", "outcome", "stage", "time_utc", "station_id", "E_um", "B_um", "R_um"]


def upgrade() -> None:
    op.create_index("ix_record_legs_last", "record_legs", LAST)
    op.drop_index("ix_record_legs_calibrations", "record_legs")
    op.create_index("ix_record_legs_calibrations", "record_legs",
                    ["leg_serial", "kind", "outcome", "time_utc", "uid", "decision", "stage"])


def downgrade() -> None:
    op.drop_index("ix_record_legs_calibrations", "record_legs")
    op.create_index("ix_record_legs_calibrations", "record_legs", ["leg_serial", "kind", "outcome", "time_utc"])
    op.drop_index("ix_record_legs_last", "record_legs")
