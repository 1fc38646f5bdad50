"""`station verify`: a verification sweep with the compensation table active, before vs after."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import sys

from procedures.vocabulary import InputError

NAME = "verify"
HELP = "verification sweep with the table active: compensated error and ISO 230-2 before vs after"
# A plain string, so `station verify --help` shows it without loading the verification (h5py);
# tests/station/test_cli_startup.py holds it to ACCEPT_RATIO.
DESCRIPTION = (
    "Sweep the leg(s) with their compensation table active (the plan of the calibration session given "
    "with --before, or an ISO 230-2 plan), record it to HDF5, and report the compensated error (residual "
    "RMS about the mean, range) and the ISO 230-2 values before (the calibration) and after, side by "
    "side, with the residual RMS divided by the noise floor (pass: <= 1.1). Each leg gets an "
    "audit entry. Exit code 0 = completed and every leg passed. See docs/compensation.md."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--leg", type=V.LEG_CHOICE.argtype(), required=True, metavar="N", help="leg(s) to verify: 2, 1-3, 1,4 or all")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--sim", action="store_true",
                       help="the simulated rig, with the drive table memory `station push --sim` wrote")
    where.add_argument("--config", type=V.CONFIG.argtype(), metavar="C", help="station TOML naming the drives and the interferometer")
    p.add_argument("--out", type=V.OUT_FILE.argtype(), required=True, metavar="FILE.h5", help="session file for the verification sweep")
    p.add_argument("--before", type=V.SESSION.argtype(), metavar="FILE.h5", help="the calibration session: its plan is repeated and its "
                   "figures are the 'before' column")
    p.add_argument("--table", type=V.TABLE.argtype(), metavar="TABLE.csv", help="refuse unless each leg's active table is this table's rows")
    p.add_argument("--cycles", type=V.CYCLES.argtype(), help="without --before: ISO 230-2 cycles (default 5)")
    p.add_argument("--audit", type=V.LOG_FILE.argtype(), metavar="FILE", help="audit log (default <recordings_dir>/audit.jsonl)")
    p.add_argument("--json", type=V.OUT_FILE.argtype(), metavar="FILE", help="also write the figures as JSON")
    p.add_argument("--force", action="store_true", help="replace --out / --json if they exist (default: refused)")
    p.add_argument("--profile", type=V.PROFILE.argtype(), metavar="PROFILE.toml", help="drive profile (default: the config's, or the built-in one)")
    p.add_argument("--time-scale", type=V.TIME_SCALE.argtype(), metavar="S", help="simulated rig only: real seconds per simulated second")
    p.add_argument("--seed", type=V.SEED.argtype(), help="simulated rig only: plant seed (as for `station sweep`)")
    p.add_argument("--noise-seed", type=V.SEED.argtype(), metavar="N",
                   help="simulated rig only: seed of the measurement noise (default: a new one, so the verification "
                        "does not repeat the calibration's noise; printed for reproduction)")
    p.add_argument("--raw", action="store_true",
                   help="compare the raw errors (default: both sessions normalised to 20 degC material temperature, "
                        "docs/metrology.md)")


class LegPrinter:
    """Runner sink: prints each leg's active table as the verification finds it."""

    critical = False

    def handle(self, event) -> None:
        from station.services.verify_job import leg_checked_line

        line = leg_checked_line(event)
        if line is not None:
            print(line)

    def close(self, outcome: str) -> None:
        pass


def run(args) -> int:
    from station.commands._table_cli import station_config
    from station.progress import ConsoleProgress
    from station.services.job import JobRunner
    from station.services.verify_job import VerifyRequest, prepare_verify

    request = VerifyRequest(legs=args.leg, out=args.out, before=args.before, table=args.table, cycles=args.cycles,
                            json_out=args.json, force=args.force, raw=args.raw, audit=args.audit,
                            time_scale=args.time_scale, seed=args.seed, noise_seed=args.noise_seed)
    job = prepare_verify(request, station_config(args, interferometer=True))  # every refusal, before the rig
    for line in job.lines:
        print(line)
    with job.connect():
        for line in job.rig_lines():
            print(line)
        ended = JobRunner().run(job, [LegPrinter(), ConsoleProgress()])
    for problem in ended.audit_problems:
        print(f"warning: {problem}", file=sys.stderr)
    end = ended.finished
    if end is None or ended.data is None:
        raise InputError(end.message if end is not None else "the verification ended without an outcome")
    verification = ended.data
    print(f"session: {job.out} ({verification.session['outcome']}, {ended.points} of {job.total_points} points)")
    print()
    print(verification.report)
    for line in verification.as_left:
        print(line)
    if args.json:
        print(f"figures: {args.json}")
    print(f"audit log: {job.audit.path}")
    if end.outcome != "completed" or not verification.passed:
        print(end.message + ("; see above" if end.outcome == "completed" else ""), file=sys.stderr)
        return 1
    return 0
