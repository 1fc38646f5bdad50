"""`station push`: write one leg's compensation table to its drive, safely, with an audit entry.

Also holds what `station rollback` shares: the drive arguments and the confirmation prompt.
The work itself is procedures.push run by station.services.table_jobs, as in the terminal UI.
"""

from __future__ import annotations

import argparse
import sys

from drivers.errors import DriverError
from procedures import events as ev
from procedures.audit import AuditError, AuditLog
from procedures.errors import InputError
from procedures.plans import parse_legs
from procedures.push import PushPlan
from procedures.states import Action, AuditOutcome
from station.services.config import LEG_COUNT, SIM_NV_NAME, StationConfig, load_config
from station.services.table_jobs import (
    JobOutcome,
    controller_refusal,
    load_leg_table,
    push_job,
    push_legs_job,
    refusal_job,
    target_text,
)
from station.services.wiring import drive_url_of, open_drive

NAME = "push"
HELP = "write a leg's compensation table to its drive (inactive bank, read back, switch), with an audit entry"
DESCRIPTION = (
    "Push the rows of one leg of a table CSV (from `station table`) to that leg's drive: show what will "
    "be written and ask to confirm (unless --yes), refuse while the axis moves, back up the drive's "
    "active table into the audit log, write the inactive bank, read it back and compare, then switch "
    "banks. On any failure the previous table stays active. See docs/compensation.md."
)


def add_drive_arguments(p: argparse.ArgumentParser, several: bool = False) -> None:
    """--leg, where the drive is (--sim | --drive URL | --config C), --profile, --audit, --yes."""
    if several:
        p.add_argument("--leg", required=True, metavar="N|1-6|all",
                       help=f"leg number (1..{LEG_COUNT}), or several (1-6, 1,4, all): one confirmation for all")
    else:
        p.add_argument("--leg", type=int, required=True, metavar="N", help=f"leg number (1..{LEG_COUNT})")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--sim", action="store_true",
                       help=f"the simulated drive; its table memory is <recordings_dir>/{SIM_NV_NAME} "
                            "(runs/ by default; config [sim] nv_path overrides)")
    where.add_argument("--drive", metavar="URL", help="the drive's bus: tcp://HOST:PORT or rtu:///dev/ttyUSB0?baud=115200")
    where.add_argument("--config", metavar="C", help="station TOML naming the drives ([drive] url, profile, timeout)")
    p.add_argument("--profile", metavar="PROFILE.toml", help="drive profile (default: the config's, or the built-in one)")
    p.add_argument("--audit", metavar="FILE", help="audit log (default <recordings_dir>/audit.jsonl, i.e. runs/audit.jsonl)")
    p.add_argument("--yes", action="store_true", help="do not ask for confirmation (needed when stdin is not a terminal)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("table", metavar="TABLE.csv", help="table CSV from `station table` (it may hold several legs)")
    add_drive_arguments(p, several=True)


# -- shared by push / rollback / verify ------------------------------------------------------------

def station_config(args, interferometer: bool = False) -> StationConfig:
    """The config of --config (or the built-in one), with --drive, --sim and --profile applied
    and the simulated drive's table memory defaulted (StationConfig.with_sim_memory). A config
    file must name the drive (and the interferometer when `interferometer`)."""
    cfg = load_config(getattr(args, "config", None))
    cfg.require_devices(interferometer=interferometer)
    drive = getattr(args, "drive", None)
    if drive:
        if drive.strip().lower() == "sim":
            raise InputError("--drive sim: use --sim for the simulated drive")
        cfg.drive.url = drive
    if getattr(args, "sim", False):
        cfg.drive.url = "sim"
    if getattr(args, "profile", None):
        cfg.drive.profile = args.profile
    return cfg.with_sim_memory()


def audit_log(args, cfg: StationConfig) -> AuditLog:
    return AuditLog(getattr(args, "audit", None) or cfg.audit_path, operator=cfg.operator)


def prompt(yes: bool, stdin=None, stdout=None):
    """`ask(question) -> bool` for the command line: True with --yes, else the user types y/yes at
    the terminal. InputError when stdin is not a terminal and --yes was not given (nobody can
    answer: refuse rather than guess)."""

    def ask(question: str) -> bool:
        if yes:
            return True
        inp = stdin or sys.stdin
        out = stdout or sys.stdout
        if not (hasattr(inp, "isatty") and inp.isatty()):
            raise InputError("not confirmed: stdin is not a terminal, so nobody can answer the question; "
                             "run it in a terminal, or add --yes to confirm on the command line. Nothing was written.")
        out.write(f"{question} [y/N] ")
        out.flush()
        return inp.readline().strip().lower() in ("y", "yes")

    return ask


class PlanPrinter:
    """Runner sink: prints a push or rollback plan before the confirmation question."""

    critical = False

    def __init__(self, header: str = "") -> None:
        self.header = header

    def handle(self, event: ev.Event) -> None:
        if isinstance(event, ev.TablePlanned):
            plan = event.plan
            if plan.action == Action.ROLLBACK:
                print(f"rollback of the push of {plan.details.get('push_time_utc')}")
            elif self.header:
                print(self.header)
            for line in plan.describe():
                print(line)
            sys.stdout.flush()

    def close(self, outcome: str) -> None:
        pass


def drive_text(cfg: StationConfig) -> str:
    """Which drive a push or rollback writes to, said before anything else."""
    if cfg.drive.url == "sim":
        return f"the SIMULATED drive (its table memory {cfg.sim.nv_path}); not a real drive"
    return f"{cfg.drive.url}" + (f" (config {cfg.source})" if cfg.from_file else "")


def warn_audit_problems(audit: AuditLog) -> None:
    try:
        _, problems = audit.read()
    except AuditError:
        return
    for p in problems[:3]:
        print(f"warning: {audit.path}, line {p.line}: {p.reason} (left as is: the log is append-only)", file=sys.stderr)


def report(job: JobOutcome, audit: AuditLog) -> int:
    """Print how a push or rollback ended; the exit code (0 ok, 1 cancelled, else an error)."""
    for problem in job.audit_problems:
        print(f"warning: {problem}", file=sys.stderr)
    end = job.finished
    if end is None:
        raise InputError("the operation ended without an outcome")
    if end.outcome == AuditOutcome.OK:
        return 0
    if end.outcome == AuditOutcome.CANCELLED:
        print("cancelled; nothing was written")
        return 1
    if end.outcome == AuditOutcome.FAILED:
        raise OperationFailed(end.message)
    raise InputError(end.message)


class OperationFailed(DriverError):
    """A push or rollback failed after it started writing (the message says which table is active)."""


def refuse(args, cfg: StationConfig, audit: AuditLog, action: Action, leg: int, exc: BaseException,
           source: dict | None = None) -> int:
    """A refusal found before the drive is opened: logged through the audit sink, then reported."""
    job = refusal_job(action, leg, exc, audit=audit, drive_url=drive_url_of(cfg), source=source)
    return report(job, audit)


# -- push -----------------------------------------------------------------------------------------

def run(args) -> int:
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
    controller = controller_refusal(cfg, legs, Action.PUSH)
    if controller:
        return refuse(args, cfg, audit, Action.PUSH, controller[0], InputError(controller[1]), sources[controller[0]])
    print(f"drive: {drive_text(cfg)}")
    for leg in legs:  # the plan names every leg's target; said first where it is not the drive
        if cfg.compensation.target_of(leg) != "drive":
            print(f"compensation target of leg {leg}: {target_text(cfg, leg)}")
    sha = next(iter(sources.values()))["sha256"]
    with open_drive(cfg, legs) as drive:
        warn_audit_problems(audit)
        if len(legs) == 1:
            leg = legs[0]
            job = push_job(drive.axis, tables[leg], audit=audit, drive_url=drive.url, source=sources[leg],
                           confirm=_with_audit_line(prompt(args.yes), audit),
                           sinks=[PlanPrinter(f"table: {args.table} (sha256 {sha[:12]}…), rows of leg {leg}")])
        else:
            job = push_legs_job(drive.axes, tables, audit=audit, drive_url=drive.url, sources=sources,
                                confirm=_with_audit_line(prompt(args.yes), audit),
                                sinks=[PlanPrinter(f"table: {args.table} (sha256 {sha[:12]}…)")])
    for end in job.of(ev.OperationFinished):
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


def parse_leg_choice(text: str) -> tuple[int, ...]:
    """"3", "1-6", "1,4" or "all" as leg numbers; InputError naming what is wrong."""
    if str(text).strip().lower() == "all":
        return tuple(range(1, LEG_COUNT + 1))
    try:
        return parse_legs(str(text))
    except InputError:
        raise InputError(f"--leg {text}: give a leg number from 1 to {LEG_COUNT}, a range (1-6), a list (1,4) "
                         "or all") from None


def _with_audit_line(ask, audit: AuditLog):
    """A `Confirm` for one plan or several: say where the audit log is, then ask."""

    def confirm(plans) -> bool:
        print(f"audit log: {audit.path}")
        if isinstance(plans, PushPlan):
            return ask(plans.question())
        return ask(f"Push these tables to legs {', '.join(str(p.leg) for p in plans)}?")

    return confirm
