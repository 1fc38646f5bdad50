"""`station push`: write one leg's compensation table to its drive, safely, with an audit entry.

Also holds what `station rollback` and `station verify` share: reaching one leg's drive
(--sim / --drive URL / --config), the audit log location, and the confirmation prompt.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from drivers.errors import DriverError
from procedures.audit import AuditEntry, AuditError, AuditLog
from procedures.errors import InputError
from procedures.push import PushRefused, prepare_push, push_table
from procedures.recording.reader import file_sha256
from procedures.table import TableLimits, read_table_csv
from station.config import StationConfig, load_config

NAME = "push"
HELP = "write a leg's compensation table to its drive (inactive bank, read back, switch), with an audit entry"
DESCRIPTION = (
    "Push the rows of one leg of a table CSV (from `station table`) to that leg's drive: show what will "
    "be written and ask to confirm (unless --yes), refuse while the axis moves, back up the drive's "
    "active table into the audit log, write the inactive bank, read it back and compare, then switch "
    "banks. On any failure the previous table stays active. See docs/compensation.md."
)

LEG_COUNT = 6
"""Legs of the platform this station calibrates (a Gough-Stewart hexapod)."""

SIM_NV_NAME = "sim-drive-nv.json"
AUDIT_NAME = "audit.jsonl"


def add_drive_arguments(p: argparse.ArgumentParser) -> None:
    """--leg, where the drive is (--sim | --drive URL | --config C), --profile, --audit, --yes."""
    p.add_argument("--leg", type=int, required=True, metavar="N", help=f"leg number (1..{LEG_COUNT})")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--sim", action="store_true",
                       help=f"the simulated drive; its table memory is <recordings_dir>/{SIM_NV_NAME} "
                            "(runs/ by default; config [sim] nv_path overrides)")
    where.add_argument("--drive", metavar="URL", help="the drive's bus: tcp://HOST:PORT or rtu:///dev/ttyUSB0?baud=115200")
    where.add_argument("--config", metavar="C", help="station TOML naming the drives ([drive] url, profile, timeout)")
    p.add_argument("--profile", metavar="PROFILE.toml", help="drive profile (default: the config's, or the built-in one)")
    p.add_argument("--audit", metavar="FILE", help=f"audit log (default <recordings_dir>/{AUDIT_NAME}, i.e. runs/{AUDIT_NAME})")
    p.add_argument("--yes", action="store_true", help="do not ask for confirmation (needed when stdin is not a terminal)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("table", metavar="TABLE.csv", help="table CSV from `station table` (it may hold several legs)")
    add_drive_arguments(p)


# -- shared by push / rollback / verify ------------------------------------------------------------

def station_config(args) -> StationConfig:
    """The config of --config (or the built-in one), with --drive applied and the simulated
    drive's table memory defaulted to <recordings_dir>/sim-drive-nv.json."""
    cfg = load_config(getattr(args, "config", None))
    drive = getattr(args, "drive", None)
    if drive:
        if drive.strip().lower() == "sim":
            raise InputError("--drive sim: use --sim for the simulated drive")
        cfg.drive.url = drive
    if getattr(args, "sim", False):
        cfg.drive.url = "sim"
    if cfg.drive.url == "sim" and not cfg.sim.nv_path:
        cfg.sim.nv_path = str(Path(cfg.recordings_dir) / SIM_NV_NAME)
    if cfg.drive.url == "sim":
        Path(cfg.sim.nv_path).parent.mkdir(parents=True, exist_ok=True)
    return cfg


def audit_log(args, cfg: StationConfig) -> AuditLog:
    path = Path(args.audit) if getattr(args, "audit", None) else Path(cfg.recordings_dir) / AUDIT_NAME
    return AuditLog(path, operator=cfg.operator)


def check_leg(leg: int) -> None:
    if not 1 <= leg <= LEG_COUNT:
        raise InputError(f"--leg {leg}: leg numbers run from 1 to {LEG_COUNT}")


def load_profile(args, cfg: StationConfig):
    from drivers.modbus.profile import DriveProfile

    return DriveProfile.load(getattr(args, "profile", None) or cfg.drive.profile or None)


def table_limits(profile) -> TableLimits:
    return TableLimits(max_points=profile.table.max_points, max_correction_um=profile.table.max_correction_um)


@dataclass
class DriveHandle:
    """One leg's drive, opened for a push/rollback; `close()` releases it (and the simulated rig)."""

    axis: Any
    url: str
    close: Callable[[], None]


def open_drive(cfg: StationConfig, leg: int, profile) -> DriveHandle:
    """Connect to `leg`'s drive: on the simulated rig (its drive memory in cfg.sim.nv_path), or
    on the bus at cfg.drive.url. Only the drive is opened, never the interferometer."""
    if cfg.drive.url == "sim":
        from drivers.sim.rig import SimRig
        from drivers.modbus.client import connect_axes

        sim = SimRig(time_scale=0.0, seed=cfg.sim.seed, nv_path=Path(cfg.sim.nv_path), profile=profile)
        port = sim.drive_server.start_tcp()
        sim.drive_url = f"tcp://127.0.0.1:{port}"
        try:
            axis = connect_axes(sim.drive_url, [leg], profile, timeout_s=cfg.drive.timeout_s, clock=sim.clock)[leg]
        except BaseException:
            sim.drive_server.stop()
            raise

        def close() -> None:
            axis.close()
            sim.drive_server.stop()

        return DriveHandle(axis, f"sim ({cfg.sim.nv_path})", close)
    from drivers.modbus.client import connect_axes

    axis = connect_axes(cfg.drive.url, [leg], profile, timeout_s=cfg.drive.timeout_s)[leg]
    return DriveHandle(axis, cfg.drive.url, axis.close)


def confirm(question: str, yes: bool, stdin=None, stdout=None) -> bool:
    """True when --yes, or the user types y/yes at the terminal. InputError when stdin is not a
    terminal and --yes was not given (nobody can answer: refuse rather than guess)."""
    if yes:
        return True
    stdin = stdin or sys.stdin
    stdout = stdout or sys.stdout
    if not (hasattr(stdin, "isatty") and stdin.isatty()):
        raise InputError("not confirmed: stdin is not a terminal, so nobody can answer the question; "
                         "run it in a terminal, or add --yes to confirm on the command line. Nothing was written.")
    stdout.write(f"{question} [y/N] ")
    stdout.flush()
    answer = stdin.readline().strip().lower()
    return answer in ("y", "yes")


def log_refusal(audit: AuditLog, action: str, leg: int, url: str, operator: str, exc: BaseException,
                source: dict | None = None, drive: str = "", outcome: str = "refused") -> None:
    """Audit a refusal found by the command itself (bad input, not confirmed); best effort."""
    try:
        audit.append(AuditEntry(action, leg, outcome, str(exc), drive, url, operator, source=source))
    except AuditError as aexc:
        print(f"warning: {aexc}", file=sys.stderr)


def warn_audit_problems(audit: AuditLog) -> None:
    try:
        _, problems = audit.read()
    except AuditError:
        return
    for p in problems[:3]:
        print(f"warning: {audit.path}, line {p.line}: {p.reason} (left as is: the log is append-only)", file=sys.stderr)


# -- push -----------------------------------------------------------------------------------------

def run(args) -> int:
    cfg = station_config(args)
    audit = audit_log(args, cfg)
    leg = int(args.leg)
    url = "sim" if cfg.drive.url == "sim" else cfg.drive.url
    source: dict | None = {"path": str(args.table), "leg": leg}
    try:
        check_leg(leg)
        profile = load_profile(args, cfg)
        limits = table_limits(profile)
        table = read_table_csv(args.table, limits)
        other = [x for x in table.legs if x > LEG_COUNT]
        if other:
            raise InputError(f"{args.table}: the table has legs {list(table.legs)}, but this station drives legs 1-{LEG_COUNT}: "
                             "it was made for a platform with another leg count; make the table from a model of these legs")
        if leg not in table.legs:
            raise InputError(f"{args.table}: the table has no rows for leg {leg} (it has legs {list(table.legs)})")
        source["sha256"] = file_sha256(args.table)
    except (InputError, DriverError, OSError) as exc:
        log_refusal(audit, "push", leg, url, cfg.operator, exc, source)
        raise
    leg_table = table.legs[leg]
    handle = open_drive(cfg, leg, profile)
    try:
        warn_audit_problems(audit)
        try:
            plan = prepare_push(handle.axis, leg_table, table_limits=limits, quantum_um=profile.table.entry_scale_um,
                                drive_url=handle.url, source=source)
        except PushRefused as exc:
            log_refusal(audit, "push", leg, handle.url, cfg.operator, exc, source)
            raise
        print(f"table: {args.table} (sha256 {source['sha256'][:12]}…), rows of leg {leg}")
        for line in plan.describe():
            print(line)
        print(f"audit log: {audit.path}")
        try:
            ok = confirm(f"Push this table to leg {leg}?", args.yes)
        except InputError as exc:
            log_refusal(audit, "push", leg, handle.url, cfg.operator, exc, source, plan.drive)
            raise
        if not ok:
            log_refusal(audit, "push", leg, handle.url, cfg.operator, "cancelled at the confirmation; nothing written",
                        source, plan.drive, outcome="cancelled")
            print("cancelled; nothing was written")
            return 1
        result = push_table(handle.axis, plan=plan, audit=audit, operator=cfg.operator)
    finally:
        handle.close()
    print(f"pushed: leg {leg} bank {result.bank} active (was bank {result.previous_bank}); "
          f"table sha256 {result.table_sha256}")
    print(f"backup of the previous table (sha256 {result.previous_sha256[:12]}…) is in {audit.path}")
    if not result.table_enabled:
        print("warning: the drive does not apply its table (table_enable = 0); switch it on before relying on it")
    if cfg.drive.url == "sim":
        verify_where = undo_where = "--sim"
    elif args.config:
        verify_where = undo_where = f"--config {args.config}"
    else:
        verify_where, undo_where = "--config C", f"--drive {cfg.drive.url}"
    print(f"next: station verify --leg {leg} {verify_where} --before CALIBRATION.h5 --out VERIFY.h5"
          f"   |   undo: station rollback --leg {leg} {undo_where}")
    return 0
