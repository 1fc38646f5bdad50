"""`station rollback`: restore the table a leg's drive had before the last successful push."""

from __future__ import annotations

import argparse

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
    from station.commands._table_cli import PlanPrinter, prompt, report, station_config, warn_audit_problems
    from station.services.job import JobRunner
    from station.services.push_jobs import PreparedRefusal, RollbackRequest, prepare_rollback

    cfg = station_config(args)
    job = prepare_rollback(RollbackRequest(leg=int(args.leg), audit=args.audit), cfg)
    if isinstance(job, PreparedRefusal):  # refused before the drive: logged, then said
        return report(JobRunner().run(job), job.audit, cfg)
    for line in job.lines:
        print(line)
    ask = prompt(args.yes)
    job.confirm_plans = lambda plan: ask(plan.question())
    with job.connect():
        warn_audit_problems(job.audit)
        ended = JobRunner().run(job, [PlanPrinter()])
    return report(ended, job.audit, cfg)  # the bank now active and its table, as the UI says it
