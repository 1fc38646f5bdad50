"""`station push`: write one leg's compensation table to its drive, safely, with an audit entry.

What it shares with `station rollback`, `verify` and `audit` (the drive arguments, the
confirmation prompt, the report) is in station/commands/_table_cli.py. The work itself is procedures.compensation.push run by station.services.table_jobs, as in the terminal UI.
"""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse

from station.commands._table_cli import add_drive_arguments

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
    from station.commands._table_cli import PlanPrinter, prompt, report, station_config, warn_audit_problems
    from station.services.job import JobRunner
    from station.services.push_jobs import PreparedRefusal, PushRequest, prepare_push

    cfg = station_config(args)
    job = prepare_push(PushRequest(legs=args.leg, table=args.table, accept_implausible=args.accept_implausible,
                                   audit=args.audit), cfg)
    if isinstance(job, PreparedRefusal):  # refused before any drive: logged, then said
        return report(JobRunner().run(job), job.audit, cfg)
    for line in job.lines:
        print(line)
    sha = next(iter(job.sources.values()))["sha256"]
    which = f"rows of leg {job.legs[0]}" if len(job.legs) == 1 else ""
    job.confirm_plans = _with_audit_line(prompt(args.yes), job.audit)
    with job.connect():
        warn_audit_problems(job.audit)
        ended = JobRunner().run(job, [PlanPrinter(f"table: {args.table} (sha256 {sha[:12]}…)" + (f", {which}" if which else ""))])
    for line in ended.warnings:  # found only against the drive's own limit
        if line not in job.warned:
            print(line)
    code = report(ended, job.audit, cfg)  # the pushed legs and where the backup is, as the UI says it
    if code:
        return code
    if args.config:  # before --sim: the config holds the legs' compensation targets
        verify_where = undo_where = f"--config {args.config}"
    elif cfg.drive.url == "sim":
        verify_where = undo_where = "--sim"
    else:
        verify_where, undo_where = "--config C", f"--drive {cfg.drive.url}"
    which = args.leg if len(job.legs) > 1 else str(job.legs[0])
    print(f"next: station verify --leg {which} {verify_where} --before CALIBRATION.h5 --out VERIFY.h5"
          f"   |   undo: station rollback --leg N {undo_where}")
    return 0


def _with_audit_line(ask, audit):
    """How the plans are confirmed here: say where the audit log is, then ask (one plan, or several)."""

    def confirm(plans) -> bool:
        print(f"audit log: {audit.path}")
        if isinstance(plans, (list, tuple)):
            return ask(f"Push these tables to legs {', '.join(str(p.leg) for p in plans)}?")
        return ask(plans.question())

    return confirm
