"""`station certificates`: the calibration certificates the catalog knows, wherever they were written."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import json
from dataclasses import asdict

from procedures.vocabulary import InputError
from station.services.config import load_config

NAME = "certificates"
HELP = "list issued calibration certificates (number, revision, draft/approved/superseded, serial, file)"
DESCRIPTION = (
    "Every certificate revision `station certificate` issued and indexed in the catalog, wherever its PDF was "
    "written (--out): its number and revision, whether it is a draft, approved (by whom, when) or superseded by a "
    "later revision, the leg's serial, the date of issue and the PDF's path. --serial S: only that leg's. Reads "
    "the shared catalog when set and reachable, else the local one (--local: the local one). docs/certificate.md."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--serial", type=V.SERIAL.argtype(), metavar="SERIAL", help="only the certificates of this leg")
    p.add_argument("--catalog", type=V.CATALOG.argtype(), metavar="URL", help="catalog URL or SQLite file (default: the config's)")
    p.add_argument("--config", type=V.CONFIG.argtype(), metavar="C", help="station TOML ([catalog] url, [station] recordings_dir)")
    p.add_argument("--local", action="store_true", help="read this station's local catalog, not the shared one")
    p.add_argument("--json", action="store_true", help="print JSON")


def run(args) -> int:
    from station.catalog import db  # noqa: PLC0415
    from station.services.fleet_queries import CatalogReading, issued_certificates, open_catalog  # noqa: PLC0415

    cfg = load_config(args.config)
    if args.serial:
        from station.services.serials import check_serial  # noqa: PLC0415

        check_serial(args.serial, "--serial")
    try:
        if args.catalog:
            from station.web.engine import catalog_url, open_readonly  # noqa: PLC0415

            url = catalog_url(args.catalog)
            reading = CatalogReading(open_readonly(url, cfg.catalog.connect_timeout_s), f"catalog: {db.describe(url)}",
                                     cfg)
        else:
            reading = open_catalog(cfg, args.local)
        where = reading.where
        rows = issued_certificates(reading, args.serial)
    except db.CatalogUnreachable as exc:
        raise InputError(f"{exc}; give --catalog with a reachable catalog (or --local)") from None
    if args.json:
        print(json.dumps([asdict(r) for r in rows], indent=2))
        return 0
    print(where)
    print(f"{'certificate':<26} {'rev':>3}  {'status':<10} {'serial':<16} {'issued (UTC)':<20} approved by / file")
    for r in rows:
        who = f"{r.approved_by} {r.approved_utc[:19]}  " if r.status == "approved" and r.approved_by else ""
        sim = "SIMULATION  " if r.simulated else ""
        print(f"{r.report_no:<26} {r.revision:>3}  {r.status:<10} {r.serial:<16} {r.issued_utc[:19]:<20} "
              f"{sim}{who}{r.path}")
    print(f"{len(rows)} certificate revision(s)" + (f" of leg {args.serial}" if args.serial else ""))
    return 0
