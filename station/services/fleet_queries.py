"""The fleet's questions to the catalog, for every front end (issue 32 part 1: front ends only
fill requests and present): a leg's history (`station history`), the legs with their last
calibration and due date (`station legs`, the web's fleet page), the certificates issued
(`station certificates`). The commands open the catalog from the station config
(`open_catalog`); the web has its own read-only engine and asks the same functions of it
(`fleet_legs`). The queries themselves are the catalog's readers (station/catalog/history.py,
certificates.py)."""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from typing import TYPE_CHECKING

from procedures.vocabulary import InputError

if TYPE_CHECKING:
    from sqlalchemy.engine import Engine

    from station.catalog.certificates import Listed
    from station.catalog.history import History, LegRow
    from station.services.config import StationConfig


@dataclass
class CatalogReading:
    """The catalog a command reads: `engine`, `where` (the line saying which catalog: the shared
    one when set and answering, else the local one) and the station config `cfg`."""

    engine: "Engine"
    where: str
    cfg: "StationConfig"


def open_catalog(cfg: "StationConfig", local: bool = False) -> CatalogReading:
    """The catalog of the station config `cfg` (station.services.config.load_config): the shared
    one when set and reachable, else the local one (`local`: the local one)."""
    from station.catalog.store import catalog_of, reading_engine  # noqa: PLC0415

    engine, where = reading_engine(catalog_of(cfg), local)
    return CatalogReading(engine, where, cfg)


def leg_history(reading: CatalogReading, serial: str) -> "History":
    """Everything the catalog holds of the leg `serial`, with drift and due date by the config's
    [catalog] intervals; a serial the catalog never saw is a typo, refused (InputError) as
    `station legs --type NOPE` is."""
    from station.catalog.history import history  # noqa: PLC0415

    c = reading.cfg.catalog
    h = history(reading.engine, serial, c.calibration_interval_days, c.min_drift_interval_days)
    if not h.rows:
        raise InputError(f"{serial}: no records of a leg with this serial in the catalog ({reading.where}); "
                         "`station legs` lists the serials it knows")
    return h


def due_date(due: str | None) -> str | None:
    """The `due` filter as an ISO date: "today" is today's date; anything else as given."""
    return dt.date.today().isoformat() if due == "today" else due


def fleet_legs(engine: "Engine", *, interval_days: int, leg_type: str | None = None, station: str | None = None,
               since: str | None = None, until: str | None = None, due: str | None = None) -> list["LegRow"]:
    """The legs with a serial the filters keep (station.catalog.history.legs; `due`: an ISO date or
    "today"), as `station legs` lists them and the web's fleet page shows them."""
    from station.catalog.history import legs  # noqa: PLC0415

    return legs(engine, leg_type=leg_type, station=station, since=since, until=until, due_by=due_date(due),
                interval_days=interval_days)


def listed_legs(reading: CatalogReading, *, leg_type: str | None = None, station: str | None = None,
                since: str | None = None, until: str | None = None, due: str | None = None) -> list["LegRow"]:
    """`station legs`: fleet_legs by the config's calibration interval. A --type or --station the
    catalog has never seen is a typo, not an empty answer: refused in one line (InputError) naming
    the known ones, as `station history` refuses an unknown serial and the web view answers 400; a
    known one that matches nothing with the other filters lists 0 legs."""
    interval = reading.cfg.catalog.calibration_interval_days
    rows = fleet_legs(reading.engine, interval_days=interval, leg_type=leg_type, station=station, since=since,
                      until=until, due=due)
    if not rows and (leg_type or station):
        every = fleet_legs(reading.engine, interval_days=interval)
        for given, name, option, of in ((leg_type, "type", "--type", lambda r: r.leg_type),
                                        (station, "station", "--station", lambda r: r.station_id)):
            known = sorted({of(r) for r in every if of(r)})
            if given and given not in known:
                raise InputError(f"{option} {given}: no leg of this {name} in the catalog ({reading.where}); known: "
                                 f"{', '.join(known) or 'none'}")
    return rows


def issued_certificates(reading: CatalogReading, serial: str | None = None) -> list["Listed"]:
    """Every certificate revision indexed in the catalog (station.catalog.certificates.issued),
    only leg `serial`'s when given."""
    from station.catalog.certificates import issued  # noqa: PLC0415

    return issued(reading.engine, serial)
