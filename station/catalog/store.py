"""The catalog a station writes: a local SQLite file next to its runs (always written first: it is
the index and the backlog), forwarded to the shared catalog (`[catalog] url`, PostgreSQL) when
one is set.

- `ingest(recs)` writes the records locally in one transaction (INSERT ... ON CONFLICT DO
  NOTHING on the natural key "KIND:KEY": ingesting a file twice is harmless), queues them in
  `outbox`, then tries to forward the backlog.
- `forward()` copies the queued records to the shared catalog, idempotently and with their
  original times, and empties the queue only for what the server took. A server that does not
  answer within `connect_timeout_s` leaves everything queued; this process then does not try
  again for `RETRY_AFTER_S`, so a run of writes never waits on a dead server more than once.
- Nothing here raises for an unreachable server: the station's work never depends on it.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import sqlalchemy as sa
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.engine import Engine

from station.catalog import db
from station.catalog.models import Instrument, Leg, Outbox, Record, RecordLeg, Station
from station.catalog.readers import Rec

log = logging.getLogger(__name__)

LOCAL_NAME = "catalog.sqlite"
RETRY_AFTER_S = 30.0
BATCH = 500

_RECORD_COLS = [c.name for c in Record.__table__.columns]
_LEG_COLS = [c.name for c in RecordLeg.__table__.columns]


def insert_ignore(conn: sa.Connection, table: sa.Table, rows: list[dict]) -> None:
    """INSERT rows, skipping those whose primary key is already there (both engines)."""
    if not rows:
        return
    dialect = postgresql if conn.dialect.name == "postgresql" else sqlite
    conn.execute(dialect.insert(table).on_conflict_do_nothing(), rows)


def rows_of(rec: Rec, default_station: str | None) -> dict[str, list[dict]]:
    """The rows a record adds to each table."""
    station = rec.station_id or default_station
    out: dict[str, list[dict]] = {"stations": [], "legs": [], "instruments": [], "records": [], "record_legs": []}
    if station:
        out["stations"].append({"id": station, "host": rec.station_host})
    if rec.instrument:
        out["instruments"].append(dict(rec.instrument))
    out["records"].append({
        "uid": rec.uid, "kind": rec.kind, "time_utc": rec.time_utc, "station_id": station, "operator": rec.operator,
        "software_version": rec.software_version, "instrument_serial": (rec.instrument or {}).get("serial"),
        "outcome": rec.outcome, "path": rec.path, "sha256": rec.sha256, "source_sha256": rec.source_sha256,
        "summary": rec.summary or None})
    for leg, row in sorted(rec.legs.items()):
        full = {c: None for c in _LEG_COLS}
        full.update({k: v for k, v in row.items() if k in full})
        full.update(uid=rec.uid, leg=leg, kind=rec.kind, time_utc=rec.time_utc, station_id=station, outcome=rec.outcome)
        out["record_legs"].append(full)
        serial = row.get("leg_serial")
        if serial:
            info = rec.leg_info.get(serial, {})
            out["legs"].append({"serial": serial, "part_number": info.get("part_number"),
                                "leg_type": info.get("leg_type"), "screw_lot": info.get("screw_lot")})
    return out


def write_recs(conn: sa.Connection, recs: Iterable[Rec], default_station: str | None, queue: bool) -> list[str]:
    """Insert `recs` on `conn` (one transaction is the caller's); the uids given."""
    merged: dict[str, list[dict]] = {k: [] for k in ("stations", "legs", "instruments", "records", "record_legs")}
    uids = []
    for rec in recs:
        uids.append(rec.uid)
        for name, rows in rows_of(rec, default_station).items():
            merged[name].extend(rows)
    for table in (Station, Leg, Instrument, Record, RecordLeg):
        insert_ignore(conn, table.__table__, merged[table.__tablename__])
    if queue:
        insert_ignore(conn, Outbox.__table__, [{"uid": u} for u in uids])
    return uids


@dataclass
class ForwardResult:
    forwarded: int = 0
    left: int = 0
    error: str = ""


@dataclass
class Catalog:
    """A station's catalog: `local` SQLite file, optional shared `url`."""

    local: Path
    url: str = ""
    station_id: str | None = None
    connect_timeout_s: float = 2.0
    _local_engine: Engine | None = field(default=None, repr=False)
    _remote_engine: Engine | None = field(default=None, repr=False)
    _remote_failed_at: float = field(default=-1e18, repr=False)
    last_forward: ForwardResult = field(default_factory=ForwardResult, repr=False)

    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    @property
    def engine(self) -> Engine:
        with self._lock:  # the backlog thread (writer.catalog_for) and the job may both open it
            if self._local_engine is None:
                self._local_engine = db.open_engine(db.sqlite_url(self.local))
            return self._local_engine

    def close(self) -> None:
        for e in (self._local_engine, self._remote_engine):
            if e is not None:
                e.dispose()
        self._local_engine = self._remote_engine = None

    # -- writing --------------------------------------------------------------------------------
    def ingest(self, recs: Iterable[Rec], forward: bool = True) -> list[str]:
        """Write `recs` locally (and queue them for the shared catalog when one is set); then
        forward the backlog. The uids written."""
        recs = list(recs)
        if not recs:
            return []
        with self.engine.begin() as conn:
            uids = write_recs(conn, recs, self.station_id, queue=bool(self.url))
        if forward and self.url:
            self.forward()
        return uids

    def serials_of_source(self, sha256: str) -> dict[int, str]:
        """Leg serials of the session with this sha256 in the local catalog ({} if unknown)."""
        with self.engine.connect() as conn:
            rows = conn.execute(sa.select(RecordLeg.leg, RecordLeg.leg_serial).where(
                RecordLeg.uid == f"session:{sha256}", RecordLeg.leg_serial.is_not(None))).all()
        return {int(leg): serial for leg, serial in rows}

    # -- forwarding -----------------------------------------------------------------------------
    def remote(self) -> Engine:
        """The shared catalog's engine (migrated). db.CatalogUnreachable when it does not answer."""
        with self._lock:
            if self._remote_engine is None:
                self._remote_engine = db.open_engine(self.url, self.connect_timeout_s)
            return self._remote_engine

    def backlog(self) -> int:
        with self.engine.connect() as conn:
            return int(conn.execute(sa.select(sa.func.count()).select_from(Outbox)).scalar_one())

    def forward(self, force: bool = False) -> ForwardResult:
        """Copy the backlog to the shared catalog (nothing to do without `url`)."""
        result = ForwardResult()
        if not self.url:
            return result
        if not force and time.monotonic() - self._remote_failed_at < RETRY_AFTER_S:
            result.left, result.error = self.backlog(), "shared catalog unreachable a moment ago; kept in the backlog"
            self.last_forward = result
            return result
        try:
            remote = self.remote()
            while True:
                with self.engine.connect() as lc:
                    uids = [u for (u,) in lc.execute(sa.select(Outbox.uid).order_by(Outbox.uid).limit(BATCH))]
                    if not uids:
                        break
                    records = [dict(r._mapping) for r in lc.execute(sa.select(Record.__table__).where(Record.uid.in_(uids)))]
                    legs = [dict(r._mapping) for r in lc.execute(sa.select(RecordLeg.__table__).where(RecordLeg.uid.in_(uids)))]
                    serials = sorted({r["leg_serial"] for r in legs if r["leg_serial"]})
                    stations = sorted({r["station_id"] for r in records if r["station_id"]})
                    instruments = sorted({r["instrument_serial"] for r in records if r["instrument_serial"]})
                    extra = {
                        Station: [dict(r._mapping) for r in lc.execute(sa.select(Station.__table__).where(Station.id.in_(stations)))],
                        Leg: [dict(r._mapping) for r in lc.execute(sa.select(Leg.__table__).where(Leg.serial.in_(serials)))],
                        Instrument: [dict(r._mapping) for r in lc.execute(
                            sa.select(Instrument.__table__).where(Instrument.serial.in_(instruments)))],
                    }
                with remote.begin() as rc:
                    for table, rows in extra.items():
                        insert_ignore(rc, table.__table__, rows)
                    insert_ignore(rc, Record.__table__, records)
                    insert_ignore(rc, RecordLeg.__table__, legs)
                with self.engine.begin() as lc:
                    lc.execute(sa.delete(Outbox).where(Outbox.uid.in_(uids)))
                result.forwarded += len(uids)
        except (db.CatalogUnreachable, sa.exc.OperationalError, sa.exc.InterfaceError) as exc:
            self._remote_failed_at = time.monotonic()
            if self._remote_engine is not None:
                self._remote_engine.dispose()
                self._remote_engine = None
            text = str(getattr(exc, "orig", None) or exc).strip().splitlines()
            result.error = text[0] if text else type(exc).__name__
            log.info("catalog: shared catalog not reachable, %s", result.error)
        result.left = self.backlog()
        self.last_forward = result
        return result


def catalog_of(cfg) -> Catalog:
    """The catalog of a station configuration (station.services.config.StationConfig)."""
    c = cfg.catalog
    return Catalog(local=Path(cfg.recordings_dir) / LOCAL_NAME, url=c.url, station_id=cfg.station_id,
                   connect_timeout_s=c.connect_timeout_s)


def reading_engine(catalog: Catalog, local: bool = False) -> tuple[Engine, str]:
    """The engine to read from: the shared catalog when one is set and answers (after forwarding
    this station's backlog), else the local one; and a line saying which."""
    if catalog.url and not local:
        result = catalog.forward(force=True)
        if not result.error:
            return catalog.remote(), f"catalog: {db.describe(catalog.url)} (shared)"
        return catalog.engine, (f"catalog: {catalog.local} (local: the shared catalog {db.describe(catalog.url)} "
                                f"is not reachable: {result.error})")
    return catalog.engine, f"catalog: {catalog.local}"
