"""`station legs`: every leg the catalog knows, its last calibration and due date."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import datetime as dt
import json
from dataclasses import asdict

from procedures.vocabulary import InputError

NAME = "legs"
HELP = "list legs by serial with last calibration and due date (filters: type, station, dates, due)"
DESCRIPTION = (
    "Every leg with a serial number in the catalog: type, number of as-found calibrations and of as-left "
    "verifications, the last calibration (when, which station, E and B in um) and its due date ([catalog] "
    "calibration_interval_days). docs/catalog.md."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--type", type=V.NAME_TEXT.argtype(), dest="leg_type", metavar="TYPE", help="only legs of this type")
    p.add_argument("--station", type=V.NAME_TEXT.argtype(), metavar="ID", help="only legs last calibrated by this station")
    p.add_argument("--since", type=V.DATE.argtype(), metavar="DATE", help="last calibrated on or after DATE (YYYY-MM-DD)")
    p.add_argument("--until", type=V.DATE.argtype(), metavar="DATE", help="last calibrated on or before DATE")
    p.add_argument("--due", type=V.DATE_OR_TODAY.argtype(), nargs="?", const="today", metavar="DATE",
                   help="only legs due on or before DATE (default today)")
    p.add_argument("--config", type=V.CONFIG.argtype(), metavar="C", help="station TOML ([catalog] url, calibration_interval_days)")
    p.add_argument("--local", action="store_true", help="read this station's local catalog, not the shared one")
    p.add_argument("--json", action="store_true", help="print JSON")


def _refuse_unknown(engine, where: str, args, interval_days: int) -> None:
    """A --type or --station the catalog has never seen is a typo, not an empty answer: refused in
    one line (exit 2) naming the known ones, as `station history` refuses an unknown serial and the
    web view answers 400. A known one that matches nothing with the other filters lists 0 legs."""
    from station.catalog.history import legs

    every = legs(engine, interval_days=interval_days)
    for given, name, option, of in ((args.leg_type, "type", "--type", lambda r: r.leg_type),
                                    (args.station, "station", "--station", lambda r: r.station_id)):
        known = sorted({of(r) for r in every if of(r)})
        if given and given not in known:
            raise InputError(f"{option} {given}: no leg of this {name} in the catalog ({where}); known: "
                             f"{', '.join(known) or 'none'}")


def run(args) -> int:
    from station.catalog.history import legs
    from station.catalog.store import catalog_of, reading_engine
    from station.services.config import load_config

    cfg = load_config(args.config)
    due = args.due
    if due == "today":
        due = dt.date.today().isoformat()
    engine, where = reading_engine(catalog_of(cfg), args.local)
    rows = legs(engine, leg_type=args.leg_type, station=args.station, since=args.since, until=args.until, due_by=due,
                interval_days=cfg.catalog.calibration_interval_days)
    if not rows and (args.leg_type or args.station):
        _refuse_unknown(engine, where, args, cfg.catalog.calibration_interval_days)
    if args.json:
        print(json.dumps([asdict(r) for r in rows], indent=2))
        return 0
    print(where)
    # cal. = as-found calibrations, ver. = as-left verifications (docs/catalog.md, stages)
    print(f"{'serial':<16} {'type':<12} {'cal.':>4} {'ver.':>4}  {'last calibration (UTC)':<27} {'station':<10} "
          f"{'E um':>7} {'B um':>7}  due")
    for r in rows:
        e = f"{r.E_um:.2f}" if r.E_um is not None else "-"
        b = f"{r.B_um:.2f}" if r.B_um is not None else "-"
        print(f"{r.serial:<16} {(r.leg_type or '-'):<12} {r.calibrations:>4} {r.verifications:>4}  "
              f"{(r.last_calibration_utc or 'never'):<27} "
              f"{(r.station_id or '-'):<10} {e:>7} {b:>7}  {r.due or 'now'}")
    print(f"{len(rows)} leg(s)")
    return 0
