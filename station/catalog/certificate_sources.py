"""What a certificate of a leg is made from, found in the catalog by the leg's serial
(`station certificate --serial`, docs/certificate.md):

- as found: the leg's latest completed *calibration* session (stage "as_found"; a session of
  stage "other", e.g. a sweep of the compensated leg or an import, is never one);
- as left: the latest completed *verification* session of the same leg recorded after it (a
  session whose plan kind is "verification", or, for records indexed before the plan kind was
  kept, one a `station verify` audit entry names), when there is one;
- the table: the last table pushed to the leg (push entry outcome "ok") after that calibration,
  when the catalog also indexes the table file the push came from (matched by its sha256).

Reads the catalog only; whether the files are still on disk is the caller's business.
"""

from __future__ import annotations

from dataclasses import dataclass

import sqlalchemy as sa
from sqlalchemy.engine import Engine

from procedures.vocabulary import InputError
from station.catalog.models import Record, RecordLeg


@dataclass(frozen=True)
class Source:
    """One file a certificate is made from: its path as indexed, its time (UTC text) and sha256;
    `leg` the leg number of the serial in that file (sessions)."""

    path: str
    time_utc: str
    sha256: str | None
    leg: int | None = None


@dataclass(frozen=True)
class CertificateSources:
    serial: str
    as_found: Source
    as_left: Source | None
    table: Source | None
    pushed_table_sha256: str | None  # the last push's table file sha256 (also when the file is not indexed)


def _sessions(conn: sa.Connection, serial: str) -> list[tuple[Source, bool | None]]:
    """Completed sessions of the leg, oldest first, each with whether it is a verification (True),
    a calibration (False) or neither (None: stage "other", e.g. a sweep of the compensated leg,
    an import: never certified as found)."""
    verified = set(conn.execute(sa.select(Record.sha256).join(RecordLeg, RecordLeg.uid == Record.uid).where(
        RecordLeg.leg_serial == serial, Record.kind == "verification", Record.sha256.is_not(None))).scalars())
    rows = conn.execute(sa.select(Record.path, Record.time_utc, Record.sha256, Record.summary, RecordLeg.leg, Record.stage)
                        .join(RecordLeg, RecordLeg.uid == Record.uid)
                        .where(RecordLeg.leg_serial == serial, Record.kind == "session", Record.outcome == "completed")
                        .order_by(Record.time_utc, Record.uid))
    out = []
    for path, time_utc, sha, summary, leg, stage in rows:
        kind = (summary or {}).get("plan_kind")
        is_verification = kind == "verification" if kind else sha in verified
        if stage is not None:  # the stage (catalog revision 0003) decides
            is_verification = {"as_left": True, "as_found": False}.get(stage)
        out.append((Source(path or "", time_utc, sha, int(leg)), is_verification))
    return out


def certificate_sources(engine: Engine, serial: str) -> CertificateSources:
    """The sessions and table a certificate of the leg `serial` is made from (see the module).
    InputError when the catalog knows no such leg or no calibration of it."""
    with engine.connect() as conn:
        sessions = _sessions(conn, serial)
        known = sessions or conn.execute(sa.select(RecordLeg.uid).where(RecordLeg.leg_serial == serial).limit(1)).first()
        if not known:
            raise InputError(f"no leg with serial {serial!r} in the catalog; `station legs` lists the serials it holds")
        calibrations = [s for s, verification in sessions if verification is False]
        if not calibrations:
            raise InputError(f"leg {serial}: the catalog holds no completed calibration session of it "
                             f"(`station history {serial}` lists its records); sweep it, then certify")
        found = calibrations[-1]
        later = [s for s, verification in sessions if verification and s.time_utc > found.time_utc]
        push = conn.execute(sa.select(Record.sha256, Record.time_utc).join(RecordLeg, RecordLeg.uid == Record.uid)
                            .where(RecordLeg.leg_serial == serial, Record.kind == "push", Record.outcome == "ok",
                                   Record.time_utc > found.time_utc)
                            .order_by(Record.time_utc.desc()).limit(1)).first()
        table = None
        if push is not None and push.sha256:
            file = conn.execute(sa.select(Record.path).where(Record.kind == "table", Record.sha256 == push.sha256)
                                .limit(1)).scalar()
            if file:
                table = Source(file, push.time_utc, push.sha256)
    return CertificateSources(serial, found, later[-1] if later else None, table, push.sha256 if push else None)
