"""`station history SERIAL`: every calibration, table, push and verification of one leg."""

from __future__ import annotations

import argparse
import json


NAME = "history"
HELP = "a leg's history by serial: calibrations (ISO 230-2 with U), tables, pushes, verifications, drift"
DESCRIPTION = (
    "Everything the catalog holds of the leg with this serial number, oldest first: each calibration "
    "with its ISO 230-2 values E, B, M (um, with expanded uncertainty U, k = 2), each table and which drive it "
    "was pushed to, each verification and its ratio; the drift of E, B and M in um per month between "
    "neighbouring calibrations, and the due date ([catalog] calibration_interval_days). docs/catalog.md."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("serial", metavar="SERIAL", help="the leg's serial number, e.g. HX-0042")
    p.add_argument("--config", metavar="C", help="station TOML ([catalog] url, calibration_interval_days)")
    p.add_argument("--local", action="store_true", help="read this station's local catalog, not the shared one")
    p.add_argument("--json", action="store_true", help="print JSON")


def run(args) -> int:
    from station.catalog.history import history, row_detail, value_with_u
    from station.catalog.store import catalog_of, reading_engine
    from station.services.config import load_config

    cfg = load_config(args.config)
    engine, where = reading_engine(catalog_of(cfg), args.local)
    h = history(engine, args.serial, cfg.catalog.calibration_interval_days)
    if args.json:
        print(json.dumps(h.to_json(), indent=2))
        return 0 if h.rows else 1
    print(where)
    if not h.rows:
        print(f"no records of a leg with serial {args.serial!r}")
        return 1
    info = ", ".join(f"{k} {v}" for k, v in h.leg_info.items() if v)
    print(f"leg {args.serial}" + (f" ({info})" if info else ""))
    print(f"{'time (UTC)':<27} {'kind':<12} {'station':<10} {'outcome':<10} {'E um':>12} {'B um':>12} {'M um':>12}  detail")
    for r in h.rows:
        print(f"{r.time_utc:<27} {r.kind:<12} {(r.station_id or '-'):<10} {(r.outcome or '-'):<10} "
              f"{value_with_u(r.figures, 'E'):>12} {value_with_u(r.figures, 'B'):>12} {value_with_u(r.figures, 'M'):>12}  {row_detail(r)}")
    for d in h.drift:
        rates = ", ".join(f"{n} {v:+.3f}" if v is not None else f"{n} -" for n, v in d.um_per_month.items())
        print(f"drift {d.from_utc[:10]} -> {d.to_utc[:10]} ({d.months:.1f} months): {rates} um/month")
    if h.due:
        print(f"last calibration {h.last_calibration_utc}; due {h.due} "
              f"(interval {cfg.catalog.calibration_interval_days} days)")
    else:
        print("never calibrated (no completed session)")
    return 0
