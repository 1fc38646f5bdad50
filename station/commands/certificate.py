"""`station certificate`: a calibration certificate (PDF and JSON) of one leg from its session(s)."""

from __future__ import annotations

import argparse
from pathlib import Path

from procedures.io.recording.reader import read_session
from station.services.certificate_jobs import COUNTER_NAME, FOLDER_NAME, issue_certificate, pick_leg
from station.services.config import load_config

NAME = "certificate"
HELP = "calibration certificate of a leg (PDF + JSON): report number, as found / as left with U and decisions"
DESCRIPTION = (
    "Issue a calibration certificate of one leg from its calibration session (as found) and, with --as-left, "
    "its verification session (as left): laboratory and customer ([lab] of --config, --customer), the leg and "
    "drive identity, the laser and its calibration (a boxed warning when not traceable), environment, method, "
    "the ISO 230-2 values with U (k = 2) and their ISO 14253-1 decisions against [tolerances.TYPE], per-target "
    "mean deviation, s and B_i, the compensation table's sha256 (--table) and approval fields. Numbered "
    "STATION-YYYYMMDD-NNNN from <recordings_dir>/certificate-counter.json (never reused); files are never "
    "overwritten: --revise REPORT_NO --reason TEXT issues the next revision and marks the old one superseded in "
    "REPORT_NO.index.json. docs/certificate.md."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("session", metavar="SESSION.h5", help="the calibration session (as found)")
    p.add_argument("--as-left", metavar="VERIFY_SESSION.h5", help="the verification session (as left)")
    p.add_argument("--table", metavar="TABLE.csv", help="the compensation table pushed (its sha256 is stated)")
    p.add_argument("--leg", type=int, metavar="N", help="the leg (needed when the session holds several)")
    p.add_argument("--out", metavar="DIR", help="certificates folder (default <recordings_dir>/certificates)")
    p.add_argument("--config", metavar="C", help="station TOML: [lab], [station] recordings_dir, [tolerances]")
    p.add_argument("--customer", help="the customer (default [lab] customer)")
    p.add_argument("--revise", metavar="REPORT_NO", help="issue the next revision of this certificate")
    p.add_argument("--reason", default="", help="with --revise: what the revision corrects")


def run(args) -> int:
    cfg = load_config(args.config)
    as_found = read_session(Path(args.session))
    as_left = read_session(Path(args.as_left)) if args.as_left else None
    tolerances = {k: t.to_json() for k, t in cfg.tolerances.items()} if args.config else None
    folder = Path(args.out) if args.out else Path(cfg.recordings_dir) / FOLDER_NAME
    lab = {"name": cfg.lab.name, "address": cfg.lab.address, "accreditation": cfg.lab.accreditation}
    leg = pick_leg(as_found, args.leg)
    leg_sha = None
    if args.table:  # the leg's rows as its drive (or the station) holds them: compared with the as-left table
        from station.services.table_jobs import expected_tables  # noqa: PLC0415
        from station.services.wiring import leg_table_spec  # noqa: PLC0415

        leg_sha = expected_tables(args.table, (leg,), leg_table_spec(cfg, leg))[leg]
    issued = issue_certificate(as_found, leg=leg, as_left=as_left, table=args.table, lab=lab,
                               customer=args.customer or cfg.lab.customer, folder=folder,
                               counter_path=Path(cfg.recordings_dir) / COUNTER_NAME, revise=args.revise,
                               reason=args.reason, tolerances=tolerances, station_id=cfg.station_id,
                               table_leg_sha256=leg_sha)
    c = issued.content
    print(f"certificate {issued.report_no} revision {issued.revision}: leg {c['item']['leg']} "
          f"serial {c['item']['serial']}, as found {c['as_found']['overall']}"
          + (f", as left {c['as_left']['overall']}" if c["as_left"] else ""))
    if not c["instrument"]["traceable"]:
        print("warning: the laser was not in calibration on the day of the measurement: the certificate says "
              "NOT TRACEABLE")
    if (c["compensation_table"] or {}).get("matches_as_left") is False:
        print("warning: the table active in the as-left session is NOT the --table given; the certificate says so")
    if c["supersedes"]:
        print(f"supersedes revision {c['supersedes']['revision']} (kept; marked superseded in {issued.index})")
    print(f"wrote {issued.pdf}\nwrote {issued.json}\nindex {issued.index}")
    return 0
