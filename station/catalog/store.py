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
from typing import TYPE_CHECKING, Iterable

import sqlalchemy as sa
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.engine import Engine

from station.catalog import db
from station.catalog.models import Instrument, Leg, Outbox, Record, RecordLeg, Station
from station.catalog.readers import Rec

if TYPE_CHECKING:
    from station.services.config import StationConfig

log = logging.getLogger(__name__)
outbox_log = logging.getLogger("station.catalog.outbox")  # the one line a job says when its records wait

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
        "summary": rec.summary or None, "stage": rec.stage_or_default, "supersedes": rec.supersedes or None})
    for leg, row in sorted(rec.legs.items()):
        full = {c: None for c in _LEG_COLS}
        full.update({k: v for k, v in row.items() if k in full})
        full.update(uid=rec.uid, leg=leg, kind=rec.kind, time_utc=rec.time_utc, station_id=station, outcome=rec.outcome,
                    stage=rec.stage_or_default)
        out["record_legs"].append(full)
        serial = row.get("leg_serial")
        if serial:
            info = rec.leg_info.get(serial, {})
            out["legs"].append({"serial": serial, "part_number": info.get("part_number"),
                                "leg_type": info.get("leg_type"), "screw_lot": info.get("screw_lot")})
    return out


FILE_KINDS = ("session", "model", "table", "report")
"""Records of one file each (path = the file, or a report's folder): a file rewritten in place
retires the record of its earlier content (audit entries share their log's path: never)."""


def retire_replaced(conn: sa.Connection, rec: Rec) -> list[str]:
    """Delete the records of `rec`'s kind at `rec`'s path with another uid (the file's earlier
    content: a resumed session, a model written again with --force) from this catalog and its
    outbox; the uids retired, also kept in `rec.supersedes` so the shared catalog retires them
    when `rec` is forwarded."""
    if rec.kind not in FILE_KINDS or not rec.path:
        return []
    old = list(conn.execute(sa.select(Record.uid).where(Record.kind == rec.kind, Record.path == rec.path,
                                                         Record.uid != rec.uid)).scalars())
    if old:
        conn.execute(sa.delete(RecordLeg).where(RecordLeg.uid.in_(old)))
        conn.execute(sa.delete(Record).where(Record.uid.in_(old)))
        conn.execute(sa.delete(Outbox).where(Outbox.uid.in_(old)))
        rec.supersedes = sorted(set(rec.supersedes or ()) | set(old))
    return old


def write_recs(conn: sa.Connection, recs: Iterable[Rec], default_station: str | None, queue: bool) -> list[str]:
    """Insert `recs` on `conn` (one transaction is the caller's); the uids given. Records already
    there are left as they are and not queued again (a sync of an indexed folder forwards
    nothing twice); a record that replaces others at its path (retire_replaced) is queued so the
    shared catalog retires them too."""
    recs = list(recs)
    merged: dict[str, list[dict]] = {k: [] for k in ("stations", "legs", "instruments", "records", "record_legs")}
    uids = [rec.uid for rec in recs]
    existing: set[str] = set()
    for i in range(0, len(uids), BATCH):
        existing.update(conn.execute(sa.select(Record.uid).where(Record.uid.in_(uids[i:i + BATCH]))).scalars())
    to_queue = []
    for rec in recs:
        retired = retire_replaced(conn, rec)
        if rec.uid in existing:
            if retired:  # the same content indexed before under this path: it now stands for the file
                conn.execute(sa.update(Record).where(Record.uid == rec.uid).values(supersedes=rec.supersedes))
                to_queue.append(rec.uid)
            continue
        to_queue.append(rec.uid)
        for name, rows in rows_of(rec, default_station).items():
            merged[name].extend(rows)
    for table in (Station, Leg, Instrument, Record, RecordLeg):
        insert_ignore(conn, table.__table__, merged[table.__tablename__])
    if queue:
        insert_ignore(conn, Outbox.__table__, [{"uid": u} for u in dict.fromkeys(to_queue)])
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
    statement_timeout_s: float = 5.0
    _local_engine: Engine | None = field(default=None, repr=False)
    _remote_engine: Engine | None = field(default=None, repr=False)
    _remote_failed_at: float = field(default=-1e18, repr=False)
    last_forward: ForwardResult = field(default_factory=ForwardResult, repr=False)
    _told_waiting: bool = field(default=False, repr=False)
    _last_error: str = field(default="", repr=False)

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
            self._say_waiting(uids)
        return uids

    def _say_waiting(self, uids: list[str]) -> None:
        """One line (a warning: the command line prints it on stderr, the UI logs it) when records
        this process wrote stay in the outbox, once per catalog object: the job is done and its
        files are the records, but the shared catalog does not hold them yet."""
        if self._told_waiting or not self.last_forward.error:
            return
        with self.engine.connect() as conn:
            waiting = conn.execute(sa.select(sa.func.count()).select_from(Outbox).where(Outbox.uid.in_(uids))).scalar_one()
        if waiting:
            self._told_waiting = True
            where = db.describe(self.url)
            why = self.last_forward.error.removeprefix(f"catalog {where}: ")  # CatalogUnreachable names it already
            outbox_log.warning("catalog: %d record(s) of this job wait in the outbox of %s (shared catalog %s: %s); "
                               "`station catalog sync` forwards them", waiting, self.local, where, why)

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
                self._remote_engine = db.open_engine(self.url, self.connect_timeout_s, self.statement_timeout_s)
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
            result.left = self.backlog()
            result.error = "shared catalog unreachable a moment ago" + (f" ({self._last_error})" if self._last_error else "")
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
                # records a file rewritten in place replaced, retired here as they were locally
                retired = sorted({u for r in records for u in (r.get("supersedes") or ())} - set(uids))
                with remote.begin() as rc:
                    for table, rows in extra.items():
                        insert_ignore(rc, table.__table__, rows)
                    if retired:
                        rc.execute(sa.delete(RecordLeg).where(RecordLeg.uid.in_(retired)))
                        rc.execute(sa.delete(Record).where(Record.uid.in_(retired)))
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
            self._last_error = result.error.removeprefix(f"catalog {db.describe(self.url)}: ")
            log.info("catalog: shared catalog not reachable, %s", result.error)
        result.left = self.backlog()
        self.last_forward = result
        return result


def catalog_of(cfg: StationConfig) -> Catalog:
    """The catalog of a station configuration."""
    c = cfg.catalog
    return Catalog(local=Path(cfg.recordings_dir) / LOCAL_NAME, url=c.url, station_id=cfg.station_id,
                   connect_timeout_s=c.connect_timeout_s, statement_timeout_s=c.statement_timeout_s)


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
