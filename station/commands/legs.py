"""`station legs`: every leg the catalog knows, its last calibration and due date."""

from __future__ import annotations

import argparse
import datetime as dt
import json
from dataclasses import asdict

from procedures.engine.errors import InputError

NAME = "legs"
HELP = "list legs by serial with last calibration and due date (filters: type, station, dates, due)"
DESCRIPTION = (
    "Every leg with a serial number in the catalog: type, number of calibrations, the last one (when, which "
    "station, E and B in um) and its due date ([catalog] calibration_interval_days). docs/catalog.md."
)


def _date(text: str) -> str:
    try:
        return dt.date.fromisoformat(text).isoformat()
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give a date as YYYY-MM-DD") from None


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--type", dest="leg_type", metavar="TYPE", help="only legs of this type")
    p.add_argument("--station", metavar="ID", help="only legs last calibrated by this station")
    p.add_argument("--since", type=_date, metavar="DATE", help="last calibrated on or after DATE (YYYY-MM-DD)")
    p.add_argument("--until", type=_date, metavar="DATE", help="last calibrated on or before DATE")
    p.add_argument("--due", nargs="?", const="today", metavar="DATE",
                   help="only legs due on or before DATE (default today)")
    p.add_argument("--config", metavar="C", help="station TOML ([catalog] url, calibration_interval_days)")
    p.add_argument("--local", action="store_true", help="read this station's local catalog, not the shared one")
    p.add_argument("--json", action="store_true", help="print JSON")


def run(args) -> int:
    from station.catalog.history import legs
    from station.catalog.store import catalog_of, reading_engine
    from station.services.config import load_config

    cfg = load_config(args.config)
    due = args.due
    if due == "today":
        due = dt.date.today().isoformat()
    elif due is not None:
        try:
            due = _date(due)
        except argparse.ArgumentTypeError as exc:
            raise InputError(f"--due {exc}") from None
    engine, where = reading_engine(catalog_of(cfg), args.local)
    rows = legs(engine, leg_type=args.leg_type, station=args.station, since=args.since, until=args.until, due_by=due,
                interval_days=cfg.catalog.calibration_interval_days)
    if args.json:
        print(json.dumps([asdict(r) for r in rows], indent=2))
        return 0
    print(where)
    print(f"{'serial':<16} {'type':<12} {'cal.':>4}  {'last calibration (UTC)':<27} {'station':<10} {'E um':>7} {'B um':>7}  due")
    for r in rows:
        e = f"{r.E_um:.2f}" if r.E_um is not None else "-"
        b = f"{r.B_um:.2f}" if r.B_um is not None else "-"
        print(f"{r.serial:<16} {(r.leg_type or '-'):<12} {r.calibrations:>4}  {(r.last_calibration_utc or 'never'):<27} "
              f"{(r.station_id or '-'):<10} {e:>7} {b:>7}  {r.due or 'now'}")
    print(f"{len(rows)} leg(s)")
    return 0
