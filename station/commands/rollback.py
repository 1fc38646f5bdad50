"""`station rollback`: restore the table a leg's drive had before the last successful push."""

from __future__ import annotations

import argparse

from drivers.errors import DriverError
from procedures.errors import InputError
from procedures.push import PushRefused, describe_table, prepare_rollback, rollback
from station.commands.push import (
    add_drive_arguments,
    audit_log,
    check_leg,
    confirm,
    load_profile,
    log_refusal,
    open_drive,
    station_config,
    warn_audit_problems,
)

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
    cfg = station_config(args)
    audit = audit_log(args, cfg)
    leg = int(args.leg)
    url = "sim" if cfg.drive.url == "sim" else cfg.drive.url
    try:
        check_leg(leg)
        profile = load_profile(args, cfg)
    except (InputError, DriverError) as exc:
        log_refusal(audit, "rollback", leg, url, cfg.operator, exc)
        raise
    handle = open_drive(cfg, leg, profile)
    try:
        warn_audit_problems(audit)
        try:
            plan = prepare_rollback(handle.axis, audit, drive_url=handle.url)
        except (PushRefused, InputError) as exc:
            log_refusal(audit, "rollback", leg, handle.url, cfg.operator, exc)
            raise
        print(f"rollback of the push of {plan.details.get('push_time_utc')} (audit log {audit.path})")
        for line in plan.describe():
            print(line)
        try:
            ok = confirm(f"Restore the previous table on leg {leg}?", args.yes)
        except InputError as exc:
            log_refusal(audit, "rollback", leg, handle.url, cfg.operator, exc, drive=plan.drive)
            raise
        if not ok:
            log_refusal(audit, "rollback", leg, handle.url, cfg.operator, "cancelled at the confirmation; nothing written",
                        drive=plan.drive, outcome="cancelled")
            print("cancelled; nothing was written")
            return 1
        result = rollback(handle.axis, audit, plan=plan, operator=cfg.operator)
    finally:
        handle.close()
    print(f"rolled back: leg {leg} bank {result.bank} active (was bank {result.previous_bank}): "
          f"{describe_table(plan.table)}; sha256 {result.table_sha256}")
    return 0
