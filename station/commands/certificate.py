"""`station certificate`: a calibration certificate (PDF and JSON) of one leg from its session(s)."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
from pathlib import Path

from procedures.vocabulary import InputError

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
    "REPORT_NO.index.json. --serial SERIAL instead of SESSION.h5 finds the leg's latest calibration, the latest "
    "verification after it and the last table pushed since in the catalog (--catalog URL). A certificate is a DRAFT "
    "until `station certificate approve REPORT_NO --by NAME` ([lab] authoriser) writes the approved document, "
    "recorded in the audit log and the catalog. docs/certificate.md."
)


_SESSION = V.SESSION.argtype()


def _session_or_approve(text: str) -> str:
    """The word `approve` (the approval step: `station certificate approve NUMBER --by NAME`), else a
    session file read as SESSION.h5 is everywhere."""
    return text if text == "approve" else _SESSION(text)


_session_or_approve.kind = V.SESSION  # the contract test reads the kind behind an option


def add_arguments(p: argparse.ArgumentParser) -> None:
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument("session", type=_session_or_approve, metavar="SESSION.h5", nargs="?",
                       help="the calibration session (as found); or `approve` followed by a report number")
    p.add_argument("number", type=V.REPORT_NO.argtype(), metavar="REPORT_NO", nargs="?",
                   help="after `approve`: the certificate to approve")
    p.add_argument("--by", type=V.NAME_TEXT.argtype(), metavar="NAME", help="with approve: who approves ([lab] authoriser)")
    which.add_argument("--serial", type=V.SERIAL.argtype(), metavar="SERIAL", help="the leg's serial: its sessions and table found in the "
                       "catalog (latest calibration, the latest verification after it, the last table pushed)")
    p.add_argument("--catalog", type=V.CATALOG.argtype(), metavar="URL", help="with --serial: catalog URL or SQLite file (default: the "
                   "config's shared catalog when set and reachable, else its local one)")
    p.add_argument("--as-left", type=V.SESSION.argtype(), metavar="VERIFY_SESSION.h5", help="the verification session (as left)")
    p.add_argument("--table", type=V.TABLE.argtype(), metavar="TABLE.csv", help="the compensation table pushed (its sha256 is stated)")
    p.add_argument("--leg", type=V.LEG.argtype(), metavar="N", help="the leg (needed when the session holds several)")
    p.add_argument("--out", type=V.OUT_DIR.argtype(), metavar="DIR", help="certificates folder (default <recordings_dir>/certificates)")
    p.add_argument("--config", type=V.CONFIG.argtype(), metavar="C", help="station TOML: [lab], [station] recordings_dir, [tolerances]")
    p.add_argument("--customer", type=V.NAME_TEXT.argtype(), help="the customer (default [lab] customer; a revision keeps the previous one)")
    p.add_argument("--customer-contact", type=V.NAME_TEXT.argtype(), metavar="TEXT",
                   help="the customer's contact (default [lab] customer_contact)")
    p.add_argument("--received", type=V.DATE.argtype(), metavar="DATE", help="the date the item was received, YYYY-MM-DD")
    p.add_argument("--revise", type=V.REPORT_NO.argtype(), metavar="REPORT_NO", help="issue the next revision of this certificate")
    p.add_argument("--reason", type=V.NAME_OR_EMPTY.argtype(), default="", help="with --revise: what the revision corrects")


def _from_catalog(args, cfg) -> tuple[str, str | None, str | None]:
    """The as-found session, as-left session and table of the leg --serial, from the catalog; printed."""
    from station.catalog import db  # noqa: PLC0415
    from station.catalog.store import catalog_of, reading_engine  # noqa: PLC0415
    from station.services.certificate_jobs import sources_from_catalog  # noqa: PLC0415
    from station.web.engine import catalog_url, open_readonly  # noqa: PLC0415

    try:
        if args.catalog:
            url = catalog_url(args.catalog)
            engine, where = open_readonly(url, cfg.catalog.connect_timeout_s), f"catalog: {db.describe(url)}"
        else:
            engine, where = reading_engine(catalog_of(cfg))
    except db.CatalogUnreachable as exc:
        raise InputError(f"{exc}; give --catalog with a reachable catalog (or the local catalog.sqlite)") from None
    found = sources_from_catalog(engine, where, args.serial, as_left=args.as_left, table=args.table, say=print)
    if args.leg is None:
        args.leg = found.leg
    return found.session, found.as_left, found.table


def _approve(args, cfg) -> int:
    from station.services.certificate_jobs import ApproveRequest, approve_certificate  # noqa: PLC0415

    done = approve_certificate(ApproveRequest(args.number, args.by, args.out), cfg)
    a = done.content["approval"]
    print(f"certificate {done.report_no} revision {done.revision} approved by {a['approved_by']}, "
          f"{a['approved_role'] or 'function not stated'} at {a['approved_utc']} (audit entry {a['audit_id']})")
    print(f"wrote {done.pdf}\nwrote {done.json}\nindex {done.index}")
    return 0


def run(args) -> int:
    from station.services.certificate_jobs import CertificateRequest, prepare_certificate  # noqa: PLC0415
    from station.services.config import load_config

    cfg = load_config(args.config)
    if args.session == "approve" and not Path("approve").exists():
        return _approve(args, cfg)
    if args.number or args.by:
        raise InputError("REPORT_NO and --by go with `station certificate approve REPORT_NO --by NAME`")
    if args.catalog and not args.serial:
        raise InputError("--catalog goes with --serial (a session file names its own sessions)")
    if args.serial:
        from station.services.serials import check_serial  # noqa: PLC0415  (the one serial grammar)

        check_serial(args.serial, "--serial")
        session, as_left_path, table = _from_catalog(args, cfg)
    else:
        session, as_left_path, table = args.session, args.as_left, args.table
    job = prepare_certificate(CertificateRequest(
        session, as_left=as_left_path, table=table, leg=args.leg, out=args.out, customer=args.customer,
        customer_contact=args.customer_contact, received=args.received, revise=args.revise, reason=args.reason,
        use_config_tolerances=bool(args.config)), cfg)
    for line in job.run().lines:
        print(line)
    return 0
