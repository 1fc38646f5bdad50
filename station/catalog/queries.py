"""What the web pages read from the catalog beyond `history` and `legs`: the filter values, the
control charts of a leg type per stage (aggregated by the database), the legs measured at more than one station
(comparison), the table files of a leg's pushes. Read-only queries; values in um.

Control chart (individuals), one per stage (as found, as left) against that stage's limit: mean and
sample standard deviation s of the completed sessions of that stage of a leg type, limits mean +- 3 s. The ISO 230-2 values E, B, R are >= 0 with an upper limit only,
so Cpk = (limit - mean) / (3 s) (the one-sided index).

Decision of a leg (the fleet's decision filter): the ISO 14253-1 verdict of its latest completed
session (the one whose E and B the fleet shows) against `[tolerances.TYPE]`, by the same
function the certificate and `station report` use (procedures.reporting.decision.decide_leg), at
the stage of that session (as left for a verification sweep, else as found).

Comparison of station A and B on one leg: E_n = (x_A - x_B) / sqrt(U_A^2 + U_B^2)
(procedures.reporting.compare.e_n, as `station compare`), each station's last completed session
of one stage (as found with as found, as left with as left), and only when the two were measured
within `[catalog] compare_window_days`; |E_n| > 1 flags a disagreement beyond both uncertainties.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from itertools import combinations

import sqlalchemy as sa
from sqlalchemy.engine import Engine

from procedures.io.recording.stage import AS_FOUND
from procedures.reporting import compare as cmp
from procedures.reporting import decision
from station.catalog.history import parse_utc, stage_filter
from station.catalog.models import FIGURES, Leg, Record, RecordLeg

COMPLETED = sa.and_(RecordLeg.kind == "session", RecordLeg.outcome == "completed")


def filter_values(engine: Engine) -> tuple[list[str], list[str]]:
    """(leg types, stations) the catalog knows, sorted."""
    with engine.connect() as conn:
        types = [t for (t,) in conn.execute(sa.select(Leg.leg_type).where(Leg.leg_type.is_not(None)).distinct())]
        stations = [s for (s,) in conn.execute(sa.select(RecordLeg.station_id)
                                                .where(RecordLeg.station_id.is_not(None)).distinct())]
    return sorted(types), sorted(stations)


@dataclass
class Calibration:
    time_utc: str
    serial: str
    station_id: str | None
    values: dict[str, tuple[float | None, float | None]]  # figure -> (value um, U um)
    stage: str | None = None
    uid: str | None = None  # the session's record and its leg number there (its per-target figures)
    leg: int | None = None


def _calibrations(conn, where) -> list[Calibration]:
    cols = [RecordLeg.time_utc, RecordLeg.leg_serial, RecordLeg.station_id, RecordLeg.stage, RecordLeg.uid,
            RecordLeg.leg]
    cols += [getattr(RecordLeg, f"{n}{s}") for n in ("E", "B", "R") for s in ("_um", "_U_um")]
    q = sa.select(*cols).where(COMPLETED, where).order_by(RecordLeg.time_utc)
    out = []
    for r in conn.execute(q):
        m = r._mapping
        out.append(Calibration(m["time_utc"], m["leg_serial"], m["station_id"],
                               {n: (m[f"{n}_um"], m[f"{n}_U_um"]) for n in ("E", "B", "R")}, m["stage"],
                               m["uid"], m["leg"]))
    return out


@dataclass
class Chart:
    figure: str
    values: list[tuple[str, str, str | None, float]]  # (time_utc, serial, station, value um)
    mean: float | None = None
    s: float | None = None
    limit_um: float | None = None
    cpk: float | None = None
    stage: str | None = None  # the stage charted (None: every completed session)
    n: int | None = None  # values the figures use (`values` may hold only the most recent); None: len(values)
    ooc: int | None = None  # of them out of control, counted by the database; None: counted in `values`

    def out_of_control(self, v: float) -> bool:
        """Beyond mean +- 3 s (Shewhart's first rule)."""
        return self.s is not None and self.s > 0 and not (self.lcl <= v <= self.ucl)

    @property
    def count(self) -> int:
        return len(self.values) if self.n is None else self.n

    @property
    def n_out_of_control(self) -> int:
        return sum(self.out_of_control(v) for *_, v in self.values) if self.ooc is None else self.ooc

    @property
    def ucl(self) -> float | None:
        return None if self.mean is None or self.s is None else self.mean + 3 * self.s

    @property
    def lcl(self) -> float | None:
        return None if self.mean is None or self.s is None else self.mean - 3 * self.s


def charts_of_type(engine: Engine, leg_type: str, stages: tuple[str, ...], figures: tuple[str, ...],
                   limits: dict[str, dict[str, float]], points: int) -> list[Chart]:
    """The individuals chart of each figure of each stage over the completed sessions of legs of
    `leg_type`, each stage against its own limit (`limits` {stage: {figure: um}}): n, mean, s and
    the out-of-control count from the database (aggregates over every session: the fleet's tens
    of thousands of rows never travel), the `points` most recent values of each stage to draw."""
    serials = sa.select(Leg.serial).where(Leg.leg_type == leg_type)
    where = sa.and_(COMPLETED, RecordLeg.leg_serial.in_(serials), RecordLeg.stage.in_(stages))
    cols = [RecordLeg.stage]
    for f in figures:
        c = getattr(RecordLeg, f"{f}_um")
        cols += [sa.func.count(c), sa.func.avg(c), sa.func.avg(c * c)]
    out: dict[tuple[str, str], Chart] = {(st, f): Chart(f, [], limit_um=limits.get(st, {}).get(f), stage=st, n=0, ooc=0)
                                         for st in stages for f in figures}
    with engine.connect() as conn:
        for row in conn.execute(sa.select(*cols).where(where).group_by(RecordLeg.stage)):
            st = row[0]
            for i, f in enumerate(figures):
                n, mean, mean_sq = row[1 + 3 * i: 4 + 3 * i]
                c = out[(st, f)]
                c.n = int(n or 0)
                if c.n:
                    c.mean = float(mean)
                if c.n >= 2:  # sample variance from the sums; never below 0 from rounding
                    c.s = math.sqrt(max(0.0, (float(mean_sq) - c.mean * c.mean) * c.n / (c.n - 1)))
                    if c.limit_um is not None and c.s > 0:
                        c.cpk = (c.limit_um - c.mean) / (3 * c.s)
        ooc = []
        for st in stages:
            for f in figures:
                c, col = out[(st, f)], getattr(RecordLeg, f"{f}_um")
                beyond = sa.false() if not c.s else sa.or_(col > c.ucl, col < c.lcl)
                ooc.append(sa.func.sum(sa.case((sa.and_(RecordLeg.stage == st, beyond), 1), else_=0)))
        counts = conn.execute(sa.select(*ooc).where(where)).one()
        for k, (st, f) in enumerate((st, f) for st in stages for f in figures):
            out[(st, f)].ooc = int(counts[k] or 0)
        for st in stages:
            q = (sa.select(RecordLeg.time_utc, RecordLeg.leg_serial, RecordLeg.station_id,
                           *[getattr(RecordLeg, f"{f}_um") for f in figures])
                 .where(where, RecordLeg.stage == st).order_by(RecordLeg.time_utc.desc()).limit(points))
            for row in reversed(conn.execute(q).all()):
                for i, f in enumerate(figures):
                    if row[3 + i] is not None:
                        out[(st, f)].values.append((row[0], row[1], row[2], row[3 + i]))
    return list(out.values())


@dataclass
class StationValue:
    station_id: str
    time_utc: str
    E: tuple[float | None, float | None]
    B: tuple[float | None, float | None]
    flagged: bool = False  # disagrees with more than half of the stations it was compared with
    uid: str | None = None  # the session compared (its record) and the leg's number in it
    leg: int | None = None


@dataclass
class Pair:
    a: str
    b: str
    en: dict[str, float | None]  # figure -> E_n
    days_apart: float = 0.0
    in_window: bool = True  # measured within the comparison window; else not compared (no E_n)

    @property
    def flagged(self) -> bool:
        return self.in_window and any(v is not None and abs(v) > 1 for v in self.en.values())


@dataclass
class Compared:
    serial: str
    leg_type: str | None
    stage: str = AS_FOUND
    stations: list[StationValue] = field(default_factory=list)
    pairs: list[Pair] = field(default_factory=list)

    @property
    def flagged(self) -> bool:
        return any(st.flagged for st in self.stations)


def e_n(a: tuple[float | None, float | None], b: tuple[float | None, float | None]) -> float | None:
    """E_n of two (value, U): procedures.reporting.compare.e_n, the formula `station compare` uses;
    None where it is not finite (both U zero)."""
    v = cmp.e_n(a[0], a[1], b[0], b[1])
    return v if v is not None and math.isfinite(v) else None


def compared_serials(engine: Engine, leg_type: str | None = None, serial: str | None = None,
                     limit: int = 100, offset: int = 0, stage: str = AS_FOUND,
                     window_days: float = 90.0) -> tuple[list[Compared], int]:
    """Legs with completed sessions of `stage` (as found: calibrations; as left: verifications) at
    more than one station (of `leg_type`, or the one `serial`): each station's last session of
    that stage, and E_n of every pair measured at most `window_days` apart (a pair further apart
    compares the leg's drift, not the stations: listed, not compared); a station is flagged when it
    disagrees with more than half of the stations it was compared with (as `station compare`
    does), and how many legs there are."""
    of_stage = sa.and_(COMPLETED, stage_filter(RecordLeg.stage, stage))
    multi = (sa.select(RecordLeg.leg_serial).where(of_stage, RecordLeg.leg_serial.is_not(None))
             .group_by(RecordLeg.leg_serial).having(sa.func.count(sa.distinct(RecordLeg.station_id)) > 1))
    if serial:
        multi = multi.where(RecordLeg.leg_serial == serial)
    if leg_type:
        multi = multi.where(RecordLeg.leg_serial.in_(sa.select(Leg.serial).where(Leg.leg_type == leg_type)))
    with engine.connect() as conn:
        total = int(conn.execute(sa.select(sa.func.count()).select_from(multi.subquery())).scalar_one())
        page = [s for (s,) in conn.execute(multi.order_by(RecordLeg.leg_serial).limit(limit).offset(offset))]
        types = dict(conn.execute(sa.select(Leg.serial, Leg.leg_type).where(Leg.serial.in_(page))).all())
        cals = _calibrations(conn, sa.and_(RecordLeg.leg_serial.in_(page), stage_filter(RecordLeg.stage, stage))) \
            if page else []
    latest: dict[str, dict[str, Calibration]] = {s: {} for s in page}
    for c in cals:  # oldest first: the last one per station stays
        if c.station_id:
            latest[c.serial][c.station_id] = c
    out = []
    for s in page:
        item = Compared(s, types.get(s), stage)
        for st, c in sorted(latest[s].items()):
            item.stations.append(StationValue(st, c.time_utc, c.values["E"], c.values["B"], uid=c.uid, leg=c.leg))
        for a, b in combinations(item.stations, 2):
            days = abs((parse_utc(a.time_utc) - parse_utc(b.time_utc)).total_seconds()) / 86400
            inside = days <= window_days
            en = {"E": e_n(a.E, b.E), "B": e_n(a.B, b.B)} if inside else {"E": None, "B": None}
            item.pairs.append(Pair(a.station_id, b.station_id, en, days, inside))
        for st in item.stations:
            mine = [p for p in item.pairs if p.in_window and st.station_id in (p.a, p.b)]
            st.flagged = bool(mine) and sum(p.flagged for p in mine) > len(mine) / 2
        out.append(item)
    return out, total


@dataclass
class TargetComparison:
    """One pair of stations of a compared leg, target by target: `rows` as
    procedures.reporting.compare.compare_pair gives them (direction, target_mm, x_a_um, U_a_um,
    x_b_um, U_b_um, d_um, E_n), the figures `station compare` prints for the same two sessions;
    `missing` names a side whose record holds no per-target figures (indexed before they were
    kept: `station catalog rebuild` adds them)."""

    a: str
    b: str
    rows: list[dict] = field(default_factory=list)
    exceed: int = 0
    n_targets: int = 0
    disagree: bool = False
    missing: list[str] = field(default_factory=list)


def per_target(engine: Engine, item: Compared) -> list[TargetComparison]:
    """Per-target E_n of every pair of `item`'s stations measured within the window: each
    session's mean deviation and U per target and direction as the evaluation gave them at
    ingest (the record's summary "targets"), compared by procedures.reporting.compare.compare_pair."""
    uids = sorted({st.uid for st in item.stations if st.uid})
    with engine.connect() as conn:
        summaries = dict(conn.execute(sa.select(Record.uid, Record.summary).where(Record.uid.in_(uids))).all()) \
            if uids else {}
    by_station = {st.station_id: ((summaries.get(st.uid) or {}).get("targets") or {}).get(str(st.leg))
                  for st in item.stations}
    out = []
    for p in item.pairs:
        if not p.in_window:
            continue
        ta, tb = by_station.get(p.a), by_station.get(p.b)
        missing = [name for name, t in ((p.a, ta), (p.b, tb)) if not t]
        if missing:
            out.append(TargetComparison(p.a, p.b, missing=missing))
            continue
        c = cmp.compare_pair(p.a, ta, p.b, tb)
        out.append(TargetComparison(p.a, p.b, c["rows"], c["exceed"], c["n_targets"], c["disagree"]))
    return out


def table_files(engine: Engine, sha256s: list[str]) -> dict[str, str]:
    """{sha256: path} of the table records with these sha256."""
    if not sha256s:
        return {}
    with engine.connect() as conn:
        return dict(conn.execute(sa.select(Record.sha256, Record.path)
                                 .where(Record.kind == "table", Record.sha256.in_(sha256s))).all())


# the fleet's decision filter: URL value -> the verdict decide_leg states
DECISIONS = {"conforming": decision.CONFORMS, "not-conforming": decision.NOT_CONFORM,
             "undecided": decision.UNDECIDED, "no-tolerance": decision.NO_TOLERANCE}


def latest_decisions(engine: Engine, leg_types: dict[str, str | None],
                     tolerances: dict[str, decision.Tolerance]) -> dict[str, str]:
    """{serial: overall verdict} of the legs `leg_types` ({serial: leg type}) from their latest
    completed session: the verdict stored at ingest (revision 0004, readers.decide_legs), or for a
    row stored undecided, decided here from its ISO 230-2 values with U against `tolerances`; a leg
    never calibrated has none."""
    if not leg_types:
        return {}
    latest = sa.select(RecordLeg.leg_serial, sa.func.max(RecordLeg.time_utc).label("t")).where(
        COMPLETED, RecordLeg.leg_serial.is_not(None))
    if len(leg_types) <= 500:  # a page of legs: their index seeks only, not the whole fleet's
        latest = latest.where(RecordLeg.leg_serial.in_(sorted(leg_types)))
    latest = latest.group_by(RecordLeg.leg_serial).subquery()
    on_latest = sa.and_(RecordLeg.leg_serial == latest.c.leg_serial, RecordLeg.time_utc == latest.c.t)
    # the stored verdicts first: two columns, no JSON, no deciding (the fleet's 10 000 legs)
    q = (sa.select(RecordLeg.leg_serial, RecordLeg.decision).join(latest, on_latest)
         .where(COMPLETED).order_by(RecordLeg.leg_serial, RecordLeg.uid))
    out: dict[str, str] = {}
    undecided: list[str] = []
    with engine.connect() as conn:
        for serial, verdict in conn.execute(q):
            if serial not in leg_types:
                continue
            if verdict is None:
                undecided.append(serial)
            else:
                out[serial] = verdict
        if undecided:
            out.update(_decide_now(conn, latest, on_latest, {s: leg_types[s] for s in undecided}, tolerances))
    return out


def _decide_now(conn, latest, on_latest, leg_types: dict[str, str | None],
                tolerances: dict[str, decision.Tolerance]) -> dict[str, str]:
    """Verdicts of rows stored without one (indexed before revision 0004, or whose session recorded
    no tolerance for its type): decided from the stored values with U, at the session's stage."""
    cols = [RecordLeg.leg_serial, RecordLeg.uid, RecordLeg.stage, Record.summary]
    cols += [getattr(RecordLeg, f"{n}{s}") for n in FIGURES for s in ("_um", "_U_um")]
    q = (sa.select(*cols).join(Record, Record.uid == RecordLeg.uid).join(latest, on_latest)
         .where(COMPLETED, RecordLeg.decision.is_(None), RecordLeg.leg_serial.in_(sorted(leg_types)))
         .order_by(RecordLeg.leg_serial, RecordLeg.uid))
    out: dict[str, str] = {}
    for r in conn.execute(q):
        m = r._mapping
        values = {n: {"value_um": m[f"{n}_um"], "U_um": m[f"{n}_U_um"]} for n in FIGURES}
        stage = "as_left" if m["stage"] == "as_left" else decision.stage_of((m["summary"] or {}).get("plan_kind"))
        out[m["leg_serial"]] = decision.decide_leg(values, {}, leg_types[m["leg_serial"]], tolerances, stage)["overall"]
    return out
