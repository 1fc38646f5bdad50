"""the stage of a leg's life on every record (as_found, adjustment, as_left, other) and on its leg
rows; `supersedes`: the uids of the records a file rewritten in place replaced (a resumed session,
`fit --force`), which the shared catalog retires when the record is forwarded

Records indexed before are classified from what the catalog holds of them: push and rollback
entries are adjustments, verification entries as left; a session whose plan kind is
"verification", or which a verification entry names, as left; an import "other"; any other
session as found. The catalog holds nothing of the tables active when a session started, so a
compensated-leg sweep indexed before this revision reads as found until the catalog is rebuilt
from the files (`station catalog rebuild`), which reads the stage the file records or derives it
from the file (procedures/io/recording/stage.py).

Revision ID: 0003
Revises: 0002
"""
import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None

_AUDIT_STAGES = {"push": "adjustment", "rollback": "adjustment", "verification": "as_left"}


def upgrade() -> None:
    with op.batch_alter_table("records") as batch:
        batch.add_column(sa.Column("stage", sa.String(16)))
        batch.add_column(sa.Column("supersedes", sa.JSON))
    with op.batch_alter_table("record_legs") as batch:
        batch.add_column(sa.Column("stage", sa.String(16)))
    conn = op.get_bind()
    records = sa.table("records", sa.column("uid", sa.String), sa.column("kind", sa.String),
                       sa.column("sha256", sa.String), sa.column("summary", sa.JSON), sa.column("stage", sa.String))
    for kind, stage in _AUDIT_STAGES.items():
        conn.execute(records.update().where(records.c.kind == kind).values(stage=stage))
    verified = set(conn.execute(sa.select(records.c.sha256).where(records.c.kind == "verification",
                                                                  records.c.sha256.is_not(None))).scalars())
    updates = []
    for uid, sha, summary in conn.execute(sa.select(records.c.uid, records.c.sha256, records.c.summary)
                                          .where(records.c.kind == "session")):
        plan_kind = (summary or {}).get("plan_kind") if isinstance(summary, dict) else None
        if plan_kind == "verification" or (not plan_kind and sha in verified):
            stage = "as_left"
        elif plan_kind == "import" or (isinstance(summary, dict) and summary.get("rig") in ("import", "replay")):
            stage = "other"
        else:
            stage = "as_found"
        updates.append({"u": uid, "s": stage})
    if updates:
        conn.execute(sa.text("UPDATE records SET stage = :s WHERE uid = :u"), updates)
    op.execute("UPDATE record_legs SET stage = (SELECT stage FROM records WHERE records.uid = record_legs.uid)")
    # history and leg lists: a leg's as-found calibrations (their count, the last one) by index seeks
    op.create_index("ix_record_legs_stage", "record_legs", ["leg_serial", "stage", "outcome", "time_utc"])
    op.create_index("ix_records_kind_path", "records", ["kind", "path"])


def downgrade() -> None:
    op.drop_index("ix_records_kind_path", "records")
    op.drop_index("ix_record_legs_stage", "record_legs")
    with op.batch_alter_table("record_legs") as batch:
        batch.drop_column("stage")
    with op.batch_alter_table("records") as batch:
        batch.drop_column("supersedes")
        batch.drop_column("stage")
