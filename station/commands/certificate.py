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
    from station.catalog.certificate_sources import certificate_sources  # noqa: PLC0415
    from station.catalog.store import catalog_of, reading_engine  # noqa: PLC0415
    from station.web.engine import catalog_url, open_readonly  # noqa: PLC0415

    try:
        if args.catalog:
            url = catalog_url(args.catalog)
            engine, where = open_readonly(url, cfg.catalog.connect_timeout_s), f"catalog: {db.describe(url)}"
        else:
            engine, where = reading_engine(catalog_of(cfg))
    except db.CatalogUnreachable as exc:
        raise InputError(f"{exc}; give --catalog with a reachable catalog (or the local catalog.sqlite)") from None
    found = certificate_sources(engine, args.serial)
    print(where)
    given = {"as left": args.as_left, "table": args.table}  # given on the command line: those win
    picked = [("as found", found.as_found, "calibration session", "no calibration"),
              ("as left", found.as_left, "verification session", "no verification session after the calibration"),
              ("table", found.table, "last table pushed", "no table pushed after the calibration is indexed")]
    for label, src, what, none in picked:
        if given.get(label):
            print(f"{label}: {given[label]} (given)")
        elif src is None:
            print(f"{label}: none ({none})")
        else:
            print(f"{label}: {src.path} ({what}, {src.time_utc}, sha256 {(src.sha256 or '?')[:16]})")
            if not Path(src.path).is_file():
                raise InputError(f"{src.path}: the catalog lists this {what} of leg {args.serial} but the file is "
                                 "missing; restore it, or re-index with `station catalog check` and `station catalog "
                                 "rebuild DIR`")
    if found.table is None and found.pushed_table_sha256 and not args.table:
        print(f"note: a table (sha256 {found.pushed_table_sha256[:16]}) was pushed after the calibration but its "
              "file is not in the catalog; give it with --table to state it")
    if args.leg is None:
        args.leg = found.as_found.leg
    return (found.as_found.path, args.as_left or (found.as_left.path if found.as_left else None),
            args.table or (found.table.path if found.table else None))


def _approve(args, cfg) -> int:
    from station.catalog.writer import catalog_for  # noqa: PLC0415
    from station.services.certificate_jobs import approve  # noqa: PLC0415
    from station.services.certificate_jobs import FOLDER_NAME  # noqa: PLC0415
    from station.services.config import AUDIT_NAME  # noqa: PLC0415

    if not args.number or not args.by:
        raise InputError("usage: station certificate approve REPORT_NO --by NAME (the [lab] authoriser)")
    folder = Path(args.out) if args.out else Path(cfg.recordings_dir) / FOLDER_NAME
    done = approve(args.number, by=args.by, folder=folder,
                   authoriser={"name": cfg.lab.authoriser, "role": cfg.lab.authoriser_role},
                   audit_path=Path(cfg.recordings_dir) / AUDIT_NAME, catalog=catalog_for(cfg),
                   station_id=cfg.station_id)
    a = done.content["approval"]
    print(f"certificate {done.report_no} revision {done.revision} approved by {a['approved_by']}, "
          f"{a['approved_role'] or 'function not stated'} at {a['approved_utc']} (audit entry {a['audit_id']})")
    print(f"wrote {done.pdf}\nwrote {done.json}\nindex {done.index}")
    return 0


def run(args) -> int:
    from procedures.io.recording.reader import read_session
    from station.services.certificate_jobs import COUNTER_NAME, FOLDER_NAME, issue_certificate, pick_leg
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
    as_found = read_session(Path(session))
    as_left = read_session(Path(as_left_path)) if as_left_path else None
    tolerances = {k: t.to_json() for k, t in cfg.tolerances.items()} if args.config else None
    folder = Path(args.out) if args.out else Path(cfg.recordings_dir) / FOLDER_NAME
    lab = {"name": cfg.lab.name, "address": cfg.lab.address, "accreditation": cfg.lab.accreditation}
    leg = pick_leg(as_found, args.leg)
    leg_sha = None
    if table:  # the leg's rows as its drive (or the station) holds them: compared with the as-left table
        from station.services.table_jobs import expected_tables  # noqa: PLC0415
        from station.services.wiring import leg_table_spec  # noqa: PLC0415

        leg_sha = expected_tables(table, (leg,), leg_table_spec(cfg, leg))[leg]
    from station.catalog.writer import catalog_for  # noqa: PLC0415

    # a revision keeps the customer an earlier revision corrected unless given again
    customer = args.customer if args.customer is not None else (None if args.revise else cfg.lab.customer)
    contact = args.customer_contact if args.customer_contact is not None else (
        None if args.revise else cfg.lab.customer_contact)
    received = None
    if args.received is not None:
        import datetime as dt  # noqa: PLC0415

        try:
            received = dt.date.fromisoformat(args.received).isoformat()
        except ValueError:
            raise InputError(f"--received {args.received!r}: give the date the item was received as YYYY-MM-DD") from None
    issued = issue_certificate(as_found, leg=leg, as_left=as_left, table=table, lab=lab,
                               customer=customer, folder=folder,
                               counter_path=Path(cfg.recordings_dir) / COUNTER_NAME, revise=args.revise,
                               reason=args.reason, tolerances=tolerances, station_id=cfg.station_id,
                               table_leg_sha256=leg_sha, customer_contact=contact,
                               authoriser={"name": cfg.lab.authoriser, "role": cfg.lab.authoriser_role},
                               prepared_by=cfg.operator, catalog=catalog_for(cfg), received=received)
    c = issued.content
    print(f"certificate {issued.report_no} revision {issued.revision} (DRAFT until approved): leg {c['item']['leg']} "
          f"serial {c['item']['serial']}, as found {c['as_found']['overall']}"
          + (f", as left {c['as_left']['overall']}" if c["as_left"] else ""))
    if issued.earlier:
        print(f"warning: these sessions are already certified: {'; '.join(issued.earlier)}; this is another number "
              f"for the same measurement (a correction is `--revise {issued.earlier[0].split(' ')[0]} --reason ...`)")
    if c.get("simulated"):
        print("warning: SIMULATION: " + "; ".join(c["simulated"]) + "; the certificate says so on every page and "
              "states no accreditation")
    if not c["traceability"]["traceable"]:
        print("warning: " + c["traceability"]["statement"].split(". The results")[0] + "; the certificate says "
              "NOT TRACEABLE")
    if (c["compensation_table"] or {}).get("matches_as_left") is False:
        print("warning: the table active in the as-left session is NOT the --table given; the certificate says so")
    if c["supersedes"]:
        print(f"supersedes revision {c['supersedes']['revision']} (kept; marked superseded in {issued.index}); "
              f"{len(c['supersedes'].get('changes') or [])} field(s) changed")
    print(f"wrote {issued.pdf}\nwrote {issued.json}\nindex {issued.index}")
    print(f"approve it: station certificate approve {issued.report_no} --by NAME")
    return 0
