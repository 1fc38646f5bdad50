"""Reading the catalog for the fleet twin of the diagnosis (`station diagnose --twin fleet:TYPE`):
the completed calibration sessions of the legs of one type."""

from __future__ import annotations

from dataclasses import dataclass

import sqlalchemy as sa
from sqlalchemy.engine import Engine

from station.catalog.models import Leg, Record, RecordLeg


@dataclass(frozen=True)
class LegSession:
    """One leg in one completed session: the serial, the leg number it had in that session, the
    file (path, sha256) and when it started (UTC text)."""

    serial: str
    leg: int
    path: str | None
    sha256: str | None
    time_utc: str


def completed_sessions_of_type(engine: Engine, leg_type: str) -> list[LegSession]:
    """Every completed session record of a leg whose type is `leg_type`, oldest first."""
    q = (sa.select(RecordLeg.leg_serial, RecordLeg.leg, Record.path, Record.sha256, RecordLeg.time_utc)
         .join(Record, Record.uid == RecordLeg.uid).join(Leg, Leg.serial == RecordLeg.leg_serial)
         .where(Leg.leg_type == leg_type, RecordLeg.kind == "session", RecordLeg.outcome == "completed")
         .order_by(RecordLeg.time_utc, RecordLeg.leg_serial))
    with engine.connect() as conn:
        return [LegSession(r.leg_serial, int(r.leg), r.path, r.sha256, r.time_utc) for r in conn.execute(q)]


def latest_per_serial(sessions: list[LegSession]) -> dict[str, LegSession]:
    """Each serial's last completed session (the state of that leg now)."""
    out: dict[str, LegSession] = {}
    for s in sessions:  # oldest first: the last one wins
        out[s.serial] = s
    return out
