"""Reading the catalog: a leg's history (every calibration, table, push and verification, ISO 230-2
values with U over time, which table went to which drive, drift of E, B and M per month between
calibrations) and the list of legs with their last calibration and due date.

Every record carries the stage of the leg's life it belongs to (`stage`,
procedures/io/recording/stage.py): as found, adjustment (push, rollback), as left (verification),
other (a sweep of a compensated leg, an import, a replay). A *calibration* is a completed
as-found session of the leg; a *verification* a completed as-left one (its session and its audit
entry count once); the due date is the last calibration plus `[catalog]
calibration_interval_days`. Drift is computed between neighbouring calibrations only, over their
real span: (value_now - value_before) / months between them (a month = 30.4375 days), um/month,
and not at all when they are closer than `[catalog] min_drift_interval_days` (a figure over
minutes is noise divided by nearly nothing).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from datetime import date, datetime, timedelta, timezone
from typing import Any

import sqlalchemy as sa
import sqlalchemy.orm  # noqa: F401  (sa.orm.aliased)
from sqlalchemy.engine import Engine

from procedures.io.recording.stage import AS_FOUND, AS_LEFT, LABELS, STAGES
from station.catalog.models import FIGURES, Leg, Record, RecordLeg

MONTH_DAYS = 30.4375
MIN_DRIFT_INTERVAL_DAYS = 30.0  # [catalog] min_drift_interval_days (station/services/config.py)


def stage_label(stage: str | None) -> str:
    """How a record's stage is printed ("as found", ...; "-" for models, tables, reports)."""
    return LABELS.get(stage or "", "-")


def stage_filter(column, stage: str):
    """A WHERE clause keeping `stage` ("as_found", "adjustment", "as_left", "other") on a `stage`
    column of records or record_legs: what the web's pages and charts per stage ask (33.2).
    ValueError for an unknown stage."""
    if stage not in STAGES:
        raise ValueError(f"unknown stage {stage!r} (one of {', '.join(STAGES)})")
    return column == stage
DRIFT_FIGURES = ("E", "B", "M")


def parse_utc(text: str) -> datetime:
    t = datetime.fromisoformat(str(text).replace("Z", "+00:00"))
    return t if t.tzinfo else t.replace(tzinfo=timezone.utc)


def due_of(last_utc: str | None, interval_days: int) -> str | None:
    if not last_utc:
        return None
    return (parse_utc(last_utc) + timedelta(days=interval_days)).date().isoformat()


@dataclass
class HistoryRow:
    time_utc: str
    kind: str
    leg: int
    station_id: str | None
    outcome: str | None
    path: str | None
    sha256: str | None
    drive: str | None
    table_sha256: str | None
    figures: dict[str, dict[str, float | None]]
    verification_ratio: float | None = None
    operator: str | None = None
    stage: str | None = None


def value_with_u(figures: dict, name: str) -> str:
    """'2.75±0.31' (um) for figure `name` of a history row, '-' when absent."""
    v = figures.get(name)
    if not v or v.get("value_um") is None:
        return "-"
    return f"{v['value_um']:.2f}" + (f"±{v['U_um']:.2f}" if v.get("U_um") is not None else "")


def row_detail(r: "HistoryRow") -> str:
    """What a history row adds: a verification's ratio, which table went to which drive, the file."""
    if r.kind == "verification":
        return f"ratio {r.verification_ratio:.2f}" if r.verification_ratio is not None else ""
    if r.kind in ("push", "rollback"):
        return f"table {(r.table_sha256 or '?')[:12]} -> {r.drive or 'drive ?'}"
    return r.path or ""


@dataclass
class Drift:
    """Drift between two neighbouring as-found calibrations; `refused` says why no figure was
    computed (closer than the minimum interval), with every rate None then."""

    from_utc: str
    to_utc: str
    months: float
    um_per_month: dict[str, float | None]
    days: float = 0.0
    refused: str = ""


@dataclass
class History:
    serial: str
    leg_info: dict[str, Any] = field(default_factory=dict)
    rows: list[HistoryRow] = field(default_factory=list)
    drift: list[Drift] = field(default_factory=list)
    last_calibration_utc: str | None = None
    due: str | None = None

    @property
    def calibrations(self) -> list[HistoryRow]:
        """Completed as-found sessions: the leg as it was found, before any adjustment."""
        return [r for r in self.rows if r.kind == "session" and r.outcome == "completed" and r.stage == AS_FOUND]

    @property
    def verifications(self) -> list[HistoryRow]:
        """Completed as-left verifications, once each: the session where the catalog holds it,
        else the verification's audit entry (both name the session's sha256)."""
        out: dict[str, HistoryRow] = {}
        for r in self.rows:
            if r.stage == AS_LEFT and r.outcome == "completed" and r.kind in ("session", "verification"):
                key = r.sha256 or f"{r.kind}@{r.time_utc}"
                if key not in out or r.kind == "session":
                    out[key] = r
        return sorted(out.values(), key=lambda r: r.time_utc)

    def to_json(self) -> dict:
        d = asdict(self)
        d["counts"] = {"calibrations": len(self.calibrations), "verifications": len(self.verifications)}
        return d


def history(engine: Engine, serial: str, interval_days: int = 365,
            min_drift_days: float = MIN_DRIFT_INTERVAL_DAYS) -> History:
    """Everything the catalog holds of the leg with serial `serial`, oldest first; drift between
    neighbouring as-found calibrations at least `min_drift_days` apart."""
    cols = [RecordLeg.time_utc, RecordLeg.kind, RecordLeg.leg, RecordLeg.station_id, Record.outcome, Record.path,
            Record.sha256, RecordLeg.drive, RecordLeg.table_sha256, RecordLeg.verification_ratio, Record.operator,
            Record.stage]
    cols += [getattr(RecordLeg, f"{n}{s}") for n in FIGURES for s in ("_um", "_U_um")]
    # a push's or rollback's "started" entry is the same operation as its final one: not a row of its own
    q = (sa.select(*cols).join(Record, Record.uid == RecordLeg.uid)
         .where(RecordLeg.leg_serial == serial, sa.or_(Record.outcome.is_(None), Record.outcome != "started"))
         .order_by(RecordLeg.time_utc, RecordLeg.kind))
    out = History(serial=serial)
    with engine.connect() as conn:
        info = conn.execute(sa.select(Leg.part_number, Leg.leg_type, Leg.screw_lot).where(Leg.serial == serial)).first()
        if info is not None:
            out.leg_info = dict(info._mapping)
        for r in conn.execute(q):
            m = r._mapping
            figures = {n: {"value_um": m[f"{n}_um"], "U_um": m[f"{n}_U_um"]} for n in FIGURES if m[f"{n}_um"] is not None}
            out.rows.append(HistoryRow(time_utc=m["time_utc"], kind=m["kind"], leg=m["leg"], station_id=m["station_id"],
                                       outcome=m["outcome"], path=m["path"], sha256=m["sha256"], drive=m["drive"],
                                       table_sha256=m["table_sha256"], figures=figures,
                                       verification_ratio=m["verification_ratio"], operator=m["operator"],
                                       stage=m["stage"]))
    cals = out.calibrations
    out.drift = drift_between(cals, min_drift_days)
    if cals:
        out.last_calibration_utc = cals[-1].time_utc
        out.due = due_of(out.last_calibration_utc, interval_days)
    return out


def drift_between(cals: list[HistoryRow], min_days: float = MIN_DRIFT_INTERVAL_DAYS) -> list[Drift]:
    """Drift of E, B, M between neighbouring as-found calibrations `cals` (oldest first), over
    their real span; refused (rates None, `refused` saying why) under `min_days`."""
    out = []
    for a, b in zip(cals, cals[1:]):
        days = (parse_utc(b.time_utc) - parse_utc(a.time_utc)).total_seconds() / 86400.0
        months = days / MONTH_DAYS
        rate: dict[str, float | None] = {n: None for n in DRIFT_FIGURES}
        refused = ""
        if days < min_days:
            refused = (f"calibrations {days:.2f} days apart, under the minimum interval of {min_days:g} days "
                       "([catalog] min_drift_interval_days)")
        else:
            for n in DRIFT_FIGURES:
                va, vb = (a.figures.get(n) or {}).get("value_um"), (b.figures.get(n) or {}).get("value_um")
                rate[n] = (vb - va) / months if (va is not None and vb is not None) else None
        out.append(Drift(a.time_utc, b.time_utc, months, rate, days, refused))
    return out


@dataclass
class LegRow:
    serial: str
    leg_type: str | None
    part_number: str | None
    calibrations: int
    last_calibration_utc: str | None
    station_id: str | None
    due: str | None
    E_um: float | None = None
    B_um: float | None = None
    verifications: int = 0  # completed as-left sessions
    # the verdict stored at ingest (revision 0004) of its latest completed session, any stage
    # (as left after a verification): None when that row was stored undecided, or no session
    decision: str | None = None


def legs(engine: Engine, *, leg_type: str | None = None, station: str | None = None, since: str | None = None,
         until: str | None = None, due_by: str | None = None, interval_days: int = 365,
         decision: str | None = None) -> list[LegRow]:
    """Every leg with a serial: its count of as-found calibrations and as-left verifications, its
    last completed as-found calibration (filtered by `since`/`until` on that time, `station` that
    made it, `leg_type`), and its due date; `due_by` (an ISO date) keeps the legs due on or before
    it (or never calibrated). The stored verdict of its latest completed session; `decision` keeps
    the legs with that verdict and those whose verdict was not stored (the caller decides those)."""
    # per leg a few index-only seeks (revision 0005: ix_record_legs_last holds serial, kind,
    # outcome, stage, time, station, E, B; ix_record_legs_calibrations serial, kind, outcome, time,
    # uid, decision) for its last completed calibration, their count and the latest verdict; the
    # rows are never read. Filters on the legs table cut the seeks.
    # PostgreSQL: LATERAL joins (one seek each); SQLite, which has none: scalar subqueries.
    r = sa.orm.aliased(RecordLeg)
    is_cal = sa.and_(r.leg_serial == Leg.serial, r.stage == AS_FOUND, r.outcome == "completed", r.kind == "session")
    is_ver = sa.and_(r.leg_serial == Leg.serial, r.stage == AS_LEFT, r.outcome == "completed", r.kind == "session")
    count = sa.select(sa.func.count().label("n")).select_from(r).where(is_cal)
    count_ver = sa.select(sa.func.count().label("nv")).select_from(r).where(is_ver)
    # ix_record_legs_calibrations (serial, kind, outcome, time, uid, decision, stage): one seek for the latest verdict
    is_done = sa.and_(r.leg_serial == Leg.serial, r.kind == "session", r.outcome == "completed")
    verdict = sa.select(r.decision).where(is_done).order_by(r.time_utc.desc(), r.uid.desc()).limit(1)
    if engine.dialect.name == "postgresql":
        # two LATERAL index-only scans per leg: its as-found calibrations, newest first, give the
        # last one and (a window count over the same rows) how many; its completed sessions give
        # the latest verdict and how many were as-left verifications
        latest = (sa.select(r.time_utc.label("last"), r.station_id, r.E_um, r.B_um,
                            sa.func.count().over().label("n")).where(is_cal)
                  .order_by(r.time_utc.desc()).limit(1).lateral("latest"))
        dv = (sa.select(r.decision, sa.func.count().filter(r.stage == AS_LEFT).over().label("nv")).where(is_done)
              .order_by(r.time_utc.desc(), r.uid.desc()).limit(1).lateral("dv"))
        inner = (sa.select(Leg.serial, Leg.leg_type, Leg.part_number, latest.c.n, dv.c.nv, latest.c.last,
                           latest.c.station_id, latest.c.E_um, latest.c.B_um, dv.c.decision)
                 .select_from(Leg).outerjoin(latest, sa.true()).outerjoin(dv, sa.true()))
    else:
        # SQLite has no LATERAL: the last calibration's row is found by one seek for its rowid
        # and read once (three seeks for its time, station, E and B otherwise); counts and the
        # verdict are scalar subqueries, each one index-only seek
        r_sq = sa.orm.aliased(RecordLeg, name="r_last")
        lc = sa.orm.aliased(RecordLeg, name="lc")
        last_rowid = (sa.select(sa.literal_column("r_last.rowid"))
                      .where(r_sq.leg_serial == Leg.serial, r_sq.kind == "session", r_sq.outcome == "completed",
                             r_sq.stage == AS_FOUND)
                      .order_by(r_sq.time_utc.desc()).limit(1).scalar_subquery())
        inner = (sa.select(Leg.serial, Leg.leg_type, Leg.part_number, count.scalar_subquery().label("n"),
                           count_ver.scalar_subquery().label("nv"), lc.time_utc.label("last"), lc.station_id,
                           lc.E_um, lc.B_um, verdict.scalar_subquery().label("decision"))
                 .select_from(Leg).outerjoin(lc, sa.literal_column("lc.rowid") == last_rowid))
    if leg_type:
        inner = inner.where(Leg.leg_type == leg_type)
    t = inner.subquery()
    q = sa.select(t)
    if station:
        q = q.where(t.c.station_id == station)
    if since:
        q = q.where(t.c.last >= since)
    if until:
        q = q.where(t.c.last < _next_day(until))
    if due_by:
        cutoff = (datetime.fromisoformat(due_by) - timedelta(days=interval_days)).date().isoformat()
        q = q.where(sa.or_(t.c.last.is_(None), t.c.last < _next_day(cutoff)))
    if decision:
        q = q.where(sa.or_(t.c.decision == decision, t.c.decision.is_(None)))
    q = q.order_by(t.c.serial)
    rows: dict[str, LegRow] = {}
    due = _DueDates(interval_days)
    with engine.connect() as conn:
        # rows unpacked as tuples, fetched at once: the fleet's 10 000 rows cost attribute lookups per column otherwise
        for serial, leg_type, part, n, nv, last, station_id, e_um, b_um, verdict in conn.execute(q).all():
            rows[serial] = LegRow(serial, leg_type, part, int(n or 0), last, station_id, due(last), e_um, b_um,
                                  int(nv or 0), verdict)
    return list(rows.values())


class _DueDates:
    """due_of for many legs: a UTC time ("...Z") falls due on its calendar date plus the interval
    (no time zone to convert), one date computation per day, however many legs share it."""

    def __init__(self, interval_days: int) -> None:
        self.interval = timedelta(days=interval_days)
        self.interval_days = interval_days
        self.by_day: dict[str, str | None] = {}

    def __call__(self, last_utc: str | None) -> str | None:
        if not last_utc or not last_utc.endswith("Z"):
            return due_of(last_utc, self.interval_days)
        day = last_utc[:10]
        due = self.by_day.get(day)
        if due is None:
            try:
                due = self.by_day[day] = (date.fromisoformat(day) + self.interval).isoformat()
            except ValueError:  # not a date where one is expected: the general parser says so
                return due_of(last_utc, self.interval_days)
        return due


def _next_day(date_text: str) -> str:
    """The ISO date after `date_text` (YYYY-MM-DD...): an `until` date includes that whole day."""
    return (datetime.fromisoformat(date_text[:10]) + timedelta(days=1)).date().isoformat()
