"""`station push`: write one leg's compensation table to its drive, safely, with an audit entry.

What it shares with `station rollback`, `verify` and `audit` (the drive arguments, the
confirmation prompt, the report) is in station/commands/_table_cli.py. The work itself is procedures.compensation.push run by station.services.table_jobs, as in the terminal UI.
"""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse

from procedures.compensation.audit import AuditLog
from procedures.vocabulary import InputError
from procedures.compensation.audit import Action
from station.commands._table_cli import add_drive_arguments
from station.services.devices import DriverError

NAME = "push"
HELP = "write a leg's compensation table to its drive (inactive bank, read back, switch), with an audit entry"
DESCRIPTION = (
    "Push the rows of one leg of a table CSV (from `station table`) to that leg's drive: show what will "
    "be written and ask to confirm (unless --yes), refuse while the axis moves, back up the drive's "
    "active table into the audit log, write the inactive bank, read it back and compare, then switch "
    "banks. On any failure the previous table stays active. See docs/compensation.md."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("table", type=V.TABLE_TO_PUSH.argtype(), metavar="TABLE.csv", help="table CSV from `station table` (it may hold several legs)")
    add_drive_arguments(p, several=True)
    p.add_argument("--accept-implausible", action="store_true",
                   help="push corrections beyond 100 um (refused by default: most likely nm in the um columns)")


# -- push -----------------------------------------------------------------------------------------

def run(args) -> int:
    from procedures.compensation.push import OperationFinished
    from procedures.io.plausibility import ImplausibleError
    from station.catalog.writer import catalog_for
    from station.commands._table_cli import (
        PlanPrinter, audit_log, drive_text, parse_leg_choice, prompt, refuse, report, station_config,
        warn_audit_problems,
    )
    from station.services.identity import configured_serials
    from station.services.table_jobs import (
        check_push_values, controller_refusal, load_leg_table, push_job, push_legs_job, target_text,
        unverified_table_line,
    )
    from station.services.wiring import open_drive

    cfg = station_config(args)
    audit = audit_log(args, cfg)
    try:
        legs = parse_leg_choice(args.leg)
    except InputError as exc:
        first = int(args.leg) if str(args.leg).isdigit() else 0
        return refuse(args, cfg, audit, Action.PUSH, first, exc, {"path": str(args.table)})
    tables, sources = {}, {}
    for leg in legs:
        source: dict | None = {"path": str(args.table), "leg": leg}
        try:
            tables[leg], sources[leg] = load_leg_table(args.table, leg)
        except (InputError, DriverError, OSError) as exc:
            return refuse(args, cfg, audit, Action.PUSH, leg, exc, source)
    unverified = unverified_table_line(args.table, tables, next(iter(sources.values())).get("table_integrity", ""))
    if unverified:  # a file without its integrity record: said once; the push checks it covers the stroke
        print(unverified)
    controller = controller_refusal(cfg, legs, Action.PUSH)
    if controller:
        return refuse(args, cfg, audit, Action.PUSH, controller[0], InputError(controller[1]), sources[controller[0]])
    try:  # a unit slip (nm in the um columns) never reaches a drive unasked: refused before connecting,
        # against what each leg's holder takes by the config (the push job checks again against the drive's)
        accepted = check_push_values(tables, str(args.table), {leg: _configured_limit_um(cfg, leg) for leg in legs},
                                     accept_implausible=args.accept_implausible)
    except ImplausibleError as exc:
        return refuse(args, cfg, audit, Action.PUSH, exc.leg, exc, sources[exc.leg])
    warned = [line for lines in accepted.values() for line in lines]
    for line in warned:
        print(line)
    print(f"drive: {drive_text(cfg)}")
    for leg in legs:  # the plan names every leg's target; said first where it is not the drive
        if cfg.compensation.target_of(leg) != "drive":
            print(f"compensation target of leg {leg}: {target_text(cfg, leg)}")
    sha = next(iter(sources.values()))["sha256"]
    serials = configured_serials(cfg)
    with open_drive(cfg, legs) as drive:
        warn_audit_problems(audit)
        if len(legs) == 1:
            leg = legs[0]
            job = push_job(drive.axis, tables[leg], audit=audit, drive_url=drive.url, source=sources[leg],
                           confirm=_with_audit_line(prompt(args.yes), audit), leg_serial=serials.get(leg),
                           sinks=[PlanPrinter(f"table: {args.table} (sha256 {sha[:12]}…), rows of leg {leg}")],
                           catalog=catalog_for(cfg), accept_implausible=args.accept_implausible, table_name=str(args.table))
        else:
            job = push_legs_job(drive.axes, tables, audit=audit, drive_url=drive.url, sources=sources,
                                confirm=_with_audit_line(prompt(args.yes), audit), leg_serials=serials,
                                sinks=[PlanPrinter(f"table: {args.table} (sha256 {sha[:12]}…)")], catalog=catalog_for(cfg),
                                accept_implausible=args.accept_implausible, table_name=str(args.table))
    for line in job.warnings:  # found only against the drive's own limit
        if line not in warned:
            print(line)
    for end in job.of(OperationFinished):
        result = end.result
        if end.leg is not None and result is not None:
            print(f"pushed: leg {result.leg} bank {result.bank} active (was bank {result.previous_bank}); "
                  f"table sha256 {result.table_sha256}; compensation target {target_text(cfg, result.leg)}")
            if not result.table_enabled:
                print(f"warning: leg {result.leg}: the drive does not apply its table (table_enable = 0); switch it on "
                      "before relying on it")
    code = report(job, audit)
    if code:
        return code
    print(f"backup of the previous table(s) is in {audit.path}")
    if args.config:  # before --sim: the config holds the legs' compensation targets
        verify_where = undo_where = f"--config {args.config}"
    elif cfg.drive.url == "sim":
        verify_where = undo_where = "--sim"
    else:
        verify_where, undo_where = "--config C", f"--drive {cfg.drive.url}"
    which = args.leg if len(legs) > 1 else str(legs[0])
    print(f"next: station verify --leg {which} {verify_where} --before CALIBRATION.h5 --out VERIFY.h5"
          f"   |   undo: station rollback --leg N {undo_where}")
    return 0


def _configured_limit_um(cfg, leg: int) -> float:
    """What leg `leg`'s table holder takes by the config, without connecting (inf when unknown)."""
    from station.services.wiring import leg_table_spec

    try:
        return leg_table_spec(cfg, leg).max_correction_um
    except InputError:
        return float("inf")


def _with_audit_line(ask, audit: AuditLog):
    """A `Confirm` for one plan or several: say where the audit log is, then ask."""
    from procedures.compensation.push import PushPlan

    def confirm(plans) -> bool:
        print(f"audit log: {audit.path}")
        if isinstance(plans, PushPlan):
            return ask(plans.question())
        return ask(f"Push these tables to legs {', '.join(str(p.leg) for p in plans)}?")

    return confirm
