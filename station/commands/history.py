"""`station history SERIAL`: every calibration, table, push and verification of one leg."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import json


NAME = "history"
HELP = "a leg's history by serial: calibrations (ISO 230-2 with U), tables, pushes, verifications, drift"
DESCRIPTION = (
    "Everything the catalog holds of the leg with this serial number, oldest first, each record with its stage "
    "(as found, adjustment, as left, other): each calibration with its ISO 230-2 values E, B, M (um, with expanded "
    "uncertainty U, k = 2), each table and which drive it was pushed to, each verification and its ratio; the "
    "drift of E, B and M in um per month between neighbouring as-found calibrations (none under [catalog] "
    "min_drift_interval_days), and the due date ([catalog] calibration_interval_days). docs/catalog.md."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("serial", type=V.SERIAL.argtype(), metavar="SERIAL", help="the leg's serial number, e.g. HX-0042")
    p.add_argument("--config", type=V.CONFIG.argtype(), metavar="C", help="station TOML ([catalog] url, calibration_interval_days)")
    p.add_argument("--local", action="store_true", help="read this station's local catalog, not the shared one")
    p.add_argument("--json", action="store_true", help="print JSON")


def run(args) -> int:
    from station.catalog.history import row_detail, stage_label, value_with_u
    from station.services.config import load_config
    from station.services.fleet_queries import leg_history, open_catalog

    cfg = load_config(args.config)
    reading = open_catalog(cfg, args.local)
    where = reading.where
    h = leg_history(reading, args.serial)  # a serial the catalog never saw: refused (exit 2)
    if args.json:
        print(json.dumps(h.to_json(), indent=2))
        return 0
    print(where)
    info = ", ".join(f"{k} {v}" for k, v in h.leg_info.items() if v)
    print(f"leg {args.serial}" + (f" ({info})" if info else ""))
    print(f"{'time (UTC)':<27} {'kind':<12} {'stage':<10} {'station':<10} {'outcome':<10} {'E um':>12} {'B um':>12} "
          f"{'M um':>12}  detail")
    for r in h.rows:
        print(f"{r.time_utc:<27} {r.kind:<12} {stage_label(r.stage):<10} {(r.station_id or '-'):<10} {(r.outcome or '-'):<10} "
              f"{value_with_u(r.figures, 'E'):>12} {value_with_u(r.figures, 'B'):>12} {value_with_u(r.figures, 'M'):>12}  {row_detail(r)}")
    print(f"{len(h.calibrations)} calibration(s) as found, {len(h.verifications)} verification(s) as left")
    for d in h.drift:
        if d.refused:
            print(f"drift {d.from_utc[:10]} -> {d.to_utc[:10]}: not computed ({d.refused})")
            continue
        rates = ", ".join(f"{n} {v:+.3f}" if v is not None else f"{n} -" for n, v in d.um_per_month.items())
        print(f"drift {d.from_utc[:10]} -> {d.to_utc[:10]} ({d.days:.1f} days, {d.months:.2f} months): {rates} um/month")
    if h.due:
        print(f"last calibration (as found) {h.last_calibration_utc}; due {h.due} "
              f"(interval {cfg.catalog.calibration_interval_days} days)")
    else:
        print("never calibrated (no completed as-found session)")
    return 0
