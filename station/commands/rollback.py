"""`station rollback`: restore the table a leg's drive had before the last successful push."""

from __future__ import annotations

import argparse

from procedures.vocabulary import InputError
from procedures.compensation.audit import Action
from station.commands._table_cli import add_drive_arguments

NAME = "rollback"
HELP = "restore the table a drive had before the last successful push (from the audit log)"
DESCRIPTION = (
    "Find the last successful push of this leg to this drive (by its identity) in the audit log and "
    "restore the table it backed up, the same safe way as a push: inactive bank, read back, switch. "
    "Refused when the drive's active table is not the one that push wrote. See docs/compensation.md."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_drive_arguments(p)


def run(args) -> int:
    from procedures.compensation.push import TablePlanned, describe_table
    from station.catalog.writer import catalog_for
    from station.commands._table_cli import (
        PlanPrinter, audit_log, drive_text, prompt, refuse, report, station_config, warn_audit_problems,
    )
    from station.services.config import LEG_COUNT
    from station.services.table_jobs import controller_refusal, rollback_job, target_text
    from station.services.wiring import open_drive

    cfg = station_config(args)
    audit = audit_log(args, cfg)
    leg = int(args.leg)
    if not 1 <= leg <= LEG_COUNT:
        return refuse(args, cfg, audit, Action.ROLLBACK, leg,
                      InputError(f"--leg {leg}: leg numbers run from 1 to {LEG_COUNT}"))
    controller = controller_refusal(cfg, (leg,), Action.ROLLBACK)
    if controller:
        return refuse(args, cfg, audit, Action.ROLLBACK, leg, InputError(controller[1]))
    print(f"drive: {drive_text(cfg)}")
    if cfg.compensation.target_of(leg) != "drive":
        print(f"compensation target of leg {leg}: {target_text(cfg, leg)}")
    with open_drive(cfg, leg) as drive:
        warn_audit_problems(audit)
        ask = prompt(args.yes)
        job = rollback_job(drive.axis, audit=audit, drive_url=drive.url, confirm=lambda plan: ask(plan.question()),
                           sinks=[PlanPrinter()], catalog=catalog_for(cfg))
    code = report(job, audit)
    if code:
        return code
    result = job.finished.result
    plan = job.of(TablePlanned)[-1].plan
    print(f"rolled back: leg {leg} bank {result.bank} active (was bank {result.previous_bank}): "
          f"{describe_table(plan.table)}; sha256 {result.table_sha256}")
    return 0
