"""The catalog's tables (SQLAlchemy 2 declarative models).

One physical table `records` holds every kind of record (single-table inheritance: `SessionRecord`,
`ModelRecord`, `TableRecord`, `PushRecord`, `VerificationRecord`, `RollbackRecord`,
`ReportRecord`), so the history of a leg is one indexed query. Its primary key `uid` is the
natural key "KIND:KEY" (KEY: the file's sha256, or the audit entry's id), the same in every
station's local catalog and in the shared one: forwarding is INSERT ... ON CONFLICT DO NOTHING.
`record_legs` holds one row per leg a record concerns, with the key figures (ISO 230-2 values
with U, micrometres; the verification ratio) and the record's kind, time and station copied in,
so history and leg lists need no join. `outbox` (local catalogs only) lists the uids not yet
forwarded to the shared catalog.

Times are text "YYYY-MM-DDTHH:MM:SS[.ffffff]Z" (UTC, as in the files: they sort as text and are
kept exactly, whatever the engine).
"""

from __future__ import annotations

from sqlalchemy import JSON, Float, ForeignKey, Index, Integer, String, Text
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

KINDS = ("session", "model", "table", "push", "verification", "rollback", "report", "certificate")
FIGURES = ("E", "A", "B", "R", "M")
"""ISO 230-2 values (bidirectional) kept as columns with their U; all values go in `figures`."""


class Base(DeclarativeBase):
    type_annotation_map = {dict: JSON}


class Station(Base):
    __tablename__ = "stations"
    id: Mapped[str] = mapped_column(String(128), primary_key=True)
    host: Mapped[str | None] = mapped_column(String(255))


class Leg(Base):
    __tablename__ = "legs"
    serial: Mapped[str] = mapped_column(String(128), primary_key=True)
    part_number: Mapped[str | None] = mapped_column(String(128))
    leg_type: Mapped[str | None] = mapped_column(String(128), index=True)
    screw_lot: Mapped[str | None] = mapped_column(String(128))


class Instrument(Base):
    __tablename__ = "instruments"
    serial: Mapped[str] = mapped_column(String(128), primary_key=True)
    model: Mapped[str | None] = mapped_column(String(128))
    calibration_due: Mapped[str | None] = mapped_column(String(32))
    calibrated_on: Mapped[str | None] = mapped_column(String(32))


class Record(Base):
    __tablename__ = "records"
    uid: Mapped[str] = mapped_column(String(200), primary_key=True)
    kind: Mapped[str] = mapped_column(String(16), index=True)
    time_utc: Mapped[str] = mapped_column(String(32), index=True)
    station_id: Mapped[str | None] = mapped_column(String(128), index=True)
    operator: Mapped[str | None] = mapped_column(String(128))
    software_version: Mapped[str | None] = mapped_column(String(64))
    instrument_serial: Mapped[str | None] = mapped_column(String(128))
    outcome: Mapped[str | None] = mapped_column(String(32))
    path: Mapped[str | None] = mapped_column(Text)
    sha256: Mapped[str | None] = mapped_column(String(64), index=True)
    source_sha256: Mapped[str | None] = mapped_column(String(64))
    summary: Mapped[dict | None] = mapped_column(JSON)
    # added by revision 0003: the stage of the leg's life (procedures/io/recording/stage.py:
    # as_found, adjustment, as_left, other; None for models, tables, reports), and the uids of
    # the records this one replaced at the same path (a file rewritten in place: a resumed
    # session, `fit --force`), retired wherever this record goes
    stage: Mapped[str | None] = mapped_column(String(16))
    supersedes: Mapped[list | None] = mapped_column(JSON)
    __mapper_args__ = {"polymorphic_on": "kind"}


class SessionRecord(Record):
    __mapper_args__ = {"polymorphic_identity": "session"}


class ModelRecord(Record):
    __mapper_args__ = {"polymorphic_identity": "model"}


class TableRecord(Record):
    __mapper_args__ = {"polymorphic_identity": "table"}


class PushRecord(Record):
    __mapper_args__ = {"polymorphic_identity": "push"}


class VerificationRecord(Record):
    __mapper_args__ = {"polymorphic_identity": "verification"}


class RollbackRecord(Record):
    __mapper_args__ = {"polymorphic_identity": "rollback"}


class ReportRecord(Record):
    __mapper_args__ = {"polymorphic_identity": "report"}


class CertificateRecord(Record):
    """A calibration certificate's PDF (station.catalog.certificates); no migration: `kind` is text."""

    __mapper_args__ = {"polymorphic_identity": "certificate"}


class RecordLeg(Base):
    """One leg of a record: its serial (None when the file names none), the drive and table it
    concerns, and the key figures (um; U with k = 2)."""

    __tablename__ = "record_legs"
    uid: Mapped[str] = mapped_column(ForeignKey("records.uid", ondelete="CASCADE"), primary_key=True)
    leg: Mapped[int] = mapped_column(Integer, primary_key=True)
    kind: Mapped[str] = mapped_column(String(16))
    time_utc: Mapped[str] = mapped_column(String(32))
    station_id: Mapped[str | None] = mapped_column(String(128))
    leg_serial: Mapped[str | None] = mapped_column(String(128))
    drive: Mapped[str | None] = mapped_column(Text)
    table_sha256: Mapped[str | None] = mapped_column(String(64))
    E_um: Mapped[float | None] = mapped_column(Float)
    E_U_um: Mapped[float | None] = mapped_column(Float)
    A_um: Mapped[float | None] = mapped_column(Float)
    A_U_um: Mapped[float | None] = mapped_column(Float)
    B_um: Mapped[float | None] = mapped_column(Float)
    B_U_um: Mapped[float | None] = mapped_column(Float)
    R_um: Mapped[float | None] = mapped_column(Float)
    R_U_um: Mapped[float | None] = mapped_column(Float)
    M_um: Mapped[float | None] = mapped_column(Float)
    M_U_um: Mapped[float | None] = mapped_column(Float)
    figures: Mapped[dict | None] = mapped_column(JSON)
    # added by revision 0002: the verification ratio (residual RMS / noise floor of a
    # verification) and the record's outcome (leg lists need no join)
    verification_ratio: Mapped[float | None] = mapped_column(Float)
    outcome: Mapped[str | None] = mapped_column(String(32))
    stage: Mapped[str | None] = mapped_column(String(16))  # revision 0003: the record's stage, copied in
    # revision 0004: the session's ISO 14253-1 overall verdict of this leg, decided at ingest
    # (readers.decide_legs); NULL when not decided then (no recorded tolerance, older rows)
    decision: Mapped[str | None] = mapped_column(String(32))


# revision 0002: history reads by serial and time; leg lists the last completed calibration per serial
Index("ix_record_legs_serial_time", RecordLeg.leg_serial, RecordLeg.time_utc)
# (revision 0005 widened it by uid, decision and stage: the latest session's verdict read from the index alone)
Index("ix_record_legs_calibrations", RecordLeg.leg_serial, RecordLeg.kind, RecordLeg.outcome, RecordLeg.time_utc,
      RecordLeg.uid, RecordLeg.decision, RecordLeg.stage)
# revision 0003: a leg's as-found calibrations by stage; a file's records by kind and path (retiring)
Index("ix_record_legs_stage", RecordLeg.leg_serial, RecordLeg.stage, RecordLeg.outcome, RecordLeg.time_utc)
Index("ix_records_kind_path", Record.kind, Record.path)
# revision 0005: covering (index-only) for the fleet's leg list and the control charts per stage
Index("ix_record_legs_last", RecordLeg.leg_serial, RecordLeg.kind, RecordLeg.outcome, RecordLeg.stage,
      RecordLeg.time_utc, RecordLeg.station_id, RecordLeg.E_um, RecordLeg.B_um, RecordLeg.R_um)


class Outbox(Base):
    """Records of a local catalog not yet forwarded to the shared one."""

    __tablename__ = "outbox"
    uid: Mapped[str] = mapped_column(String(200), primary_key=True)
