"""`station legs`: every leg the catalog knows, its last calibration and due date."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import json
from dataclasses import asdict

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


def run(args) -> int:
    from station.services.config import load_config
    from station.services.fleet_queries import listed_legs, open_catalog

    cfg = load_config(args.config)
    reading = open_catalog(cfg, args.local)
    where = reading.where
    # a --type or --station the catalog has never seen: refused naming the known ones (exit 2)
    rows = listed_legs(reading, leg_type=args.leg_type, station=args.station, since=args.since, until=args.until,
                       due=args.due)
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
