"""What the table commands share (`station push`, `rollback`, `verify`, `audit`): the drive
arguments, the config they make, the audit log, the confirmation prompt, the plan printer and
how an operation's end is reported. Command-line only (argparse, stdin, print); the work itself
is station.services.table_jobs, as in the terminal UI. (Not a command: cli.py skips "_" modules.)"""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import sys
from typing import TYPE_CHECKING

from procedures.vocabulary import InputError
from station.services.config import LEG_COUNT, SIM_NV_NAME, StationConfig, load_config

if TYPE_CHECKING:
    from station.services.job import JobOutcome

# The drive's, the catalog's and the jobs' modules are imported inside the functions that use
# them: `station push --help` and an argument error load none of them (issue 32).


def add_drive_arguments(p: argparse.ArgumentParser, several: bool = False) -> None:
    """--leg, where the drive is (--sim | --drive URL | --config C), --profile, --audit, --yes."""
    if several:
        p.add_argument("--leg", required=True, metavar="N|1-6|all", type=V.LEGS_AUDITED.argtype(),
                       help=f"leg number (1..{LEG_COUNT}), or several (1-6, 1,4, all): one confirmation for all")
    else:
        p.add_argument("--leg", type=V.LEG.argtype(), required=True, metavar="N", help=f"leg number (1..{LEG_COUNT})")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--sim", action="store_true",
                       help=f"the simulated drive; its table memory is <recordings_dir>/{SIM_NV_NAME} "
                            "(runs/ by default; config [sim] nv_path overrides)")
    where.add_argument("--drive", type=V.DRIVE_URL.argtype(), metavar="URL", help="the drive's bus: tcp://HOST:PORT or rtu:///dev/ttyUSB0?baud=115200")
    where.add_argument("--config", type=V.CONFIG.argtype(), metavar="C", help="station TOML naming the drives ([drive] url, profile, timeout)")
    p.add_argument("--profile", type=V.PROFILE.argtype(), metavar="PROFILE.toml", help="drive profile (default: the config's, or the built-in one)")
    p.add_argument("--audit", type=V.LOG_FILE.argtype(), metavar="FILE", help="audit log (default <recordings_dir>/audit.jsonl, i.e. runs/audit.jsonl)")
    p.add_argument("--yes", action="store_true", help="do not ask for confirmation (needed when stdin is not a terminal)")


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


def audit_log(args, cfg: StationConfig):
    from station.services.session_identity import station_audit_log

    return station_audit_log(cfg, getattr(args, "audit", None))


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

    def handle(self, event) -> None:
        from station.services.push_jobs import planned, plan_lines

        plan = planned(event)
        if plan is not None:
            if plan.action == "rollback":
                print(f"rollback of the push of {plan.details.get('push_time_utc')}")
            elif self.header:
                print(self.header)
            for line in plan_lines(plan):
                print(line)
            sys.stdout.flush()

    def close(self, outcome: str) -> None:
        pass


def warn_audit_problems(audit) -> None:
    from station.services.push_jobs import audit_problem_lines

    for line in audit_problem_lines(audit):
        print(f"warning: {line}", file=sys.stderr)


def report(job: JobOutcome, audit, cfg: StationConfig) -> int:
    """Print how a push or rollback ended, in the words the terminal UI shows too
    (station.services.push_jobs.outcome_lines); the exit code (0 ok, 1 cancelled), or the
    refusal's or failure's message raised as the error to print (its last line)."""
    from station.services.push_jobs import outcome_lines
    from station.services.table_jobs import OperationFailed

    for problem in job.audit_problems:
        print(f"warning: {problem}", file=sys.stderr)
    end = job.finished
    if end is None:
        raise InputError("the operation ended without an outcome")
    lines = outcome_lines(job, cfg, audit)
    if end.outcome in ("ok", "cancelled"):
        for line in lines:
            print(line)
        return 0 if end.outcome == "ok" else 1
    for line in lines[:-1]:  # the legs pushed before a refusal or failure of several legs
        print(line)
    raise (OperationFailed if end.outcome == "failed" else InputError)(lines[-1])
