"""`station verify`: a verification sweep with the compensation table active, before vs after."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import json
import os
import secrets
import sys
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from procedures.engine import events as ev
from procedures.reporting.decision import decision_lines
from procedures.vocabulary import InputError
from procedures.io.outputs import check_output_file
from procedures.compensation.audit import Action
from procedures.vocabulary import Outcome as AuditOutcome
from station.progress import ConsoleProgress

if TYPE_CHECKING:
    from procedures.acquisition.plans import SweepPlan

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


NOISE_SEED_ENV = "STATION_SIM_NOISE_SEED"
"""Simulated rig only: the verification's noise seed when --noise-seed is not given (a demo or a
test that repeats exactly: tests/station/test_readme_calibration.py); unset = a new seed each time."""


def default_noise_seed() -> int:
    """$STATION_SIM_NOISE_SEED when set (InputError unless a whole number), else a new random seed."""
    text = os.environ.get(NOISE_SEED_ENV, "").strip()
    if not text:
        return secrets.randbelow(1 << 31)
    try:
        return int(text)
    except ValueError:
        raise InputError(f"${NOISE_SEED_ENV} = {text!r}: give a whole number (or unset it for a new seed)") from None


def _plan(args, legs: tuple[int, ...], before) -> SweepPlan:
    from procedures.acquisition.plans import SweepPlan, iso230_plan

    if before is None:
        return iso230_plan(legs, cycles=5 if args.cycles is None else args.cycles)
    if args.cycles is not None:
        raise InputError("--cycles applies without --before only (the calibration's plan is repeated as it was)")
    try:
        plan = SweepPlan.from_dict(before.plan)
    except (InputError, TypeError, ValueError) as exc:
        raise InputError(f"{before.path}: its sweep plan cannot be repeated ({exc}); verify without --before") from None
    missing = [leg for leg in legs if leg not in before.legs]
    if missing:
        raise InputError(f"{before.path}: no calibration points for leg(s) {missing} (it has legs {before.legs})")
    return replace(plan, legs=legs, kind="verification", notes=())


class LegPrinter:
    """Runner sink: prints each leg's active table as the verification finds it."""

    critical = False

    def handle(self, event: ev.Event) -> None:
        from procedures.compensation.verify import LegChecked

        if isinstance(event, LegChecked):
            print(f"leg {event.leg}: bank {event.bank} active, {event.description}, sha256 {event.table_sha256[:12]}…")

    def close(self, outcome: str) -> None:
        pass


def run(args) -> int:
    from procedures.compensation.verify import Verified
    from procedures.io.recording.reader import read_session
    from station.commands._table_cli import audit_log, parse_leg_choice, station_config
    from station.commands.sweep import check_time_scale
    from station.services.report_jobs import session_decisions
    from station.services.table_jobs import controller_refusal, expected_tables, refusal_job, target_text, verify_job
    from station.services.wiring import drive_url_of, leg_table_spec, open_rig

    legs = parse_leg_choice(args.leg)
    cfg = station_config(args, interferometer=True)
    if not cfg.is_sim and (args.seed is not None or args.noise_seed is not None):
        raise InputError("--seed/--noise-seed apply to the simulated rig (--sim, or a config naming \"sim\") only")
    if args.seed is not None:
        cfg.sim.seed = args.seed
    audit = audit_log(args, cfg)
    controller = controller_refusal(cfg, legs, Action.VERIFY)
    if controller:
        job = refusal_job(Action.VERIFY, controller[0], controller[1], audit=audit, drive_url=drive_url_of(cfg))
        raise InputError(job.finished.message)
    check_time_scale(args.time_scale)
    # every output checked before anything connects or moves (procedures/io/outputs.py)
    out = check_output_file(args.out, force=args.force, suffixes=(".h5",))
    if args.json:
        check_output_file(args.json, force=args.force, option="--json")
    before = read_session(args.before) if args.before else None
    if before is None:  # sized first against the config's [limits], as `station sweep` sizes its plan
        from procedures.acquisition.plan_size import check_plan_size
        from procedures.acquisition.plan_spec import PlanSpec

        size = check_plan_size(PlanSpec(legs=legs, kind="iso230", cycles=5 if args.cycles is None else args.cycles),
                               cfg.limits)
        print(f"plan: {size.describe()}")
    plan = _plan(args, legs, before)
    expected: dict[int, str] = {}
    if args.table:
        for leg in legs:  # as the leg's table holder stores it: the drive, or the station (its target)
            expected.update(expected_tables(args.table, (leg,), leg_table_spec(cfg, leg)))
    noise_seed = None
    if cfg.is_sim:
        noise_seed = args.noise_seed if args.noise_seed is not None else default_noise_seed()
        if noise_seed == cfg.sim.seed:
            print(f"note: noise seed {noise_seed} = plant seed: the sweep repeats the noise of a `station sweep --sim` "
                  "of the same plan exactly, so it is not an independent verification")
    if args.force and out.exists():
        out.unlink()  # --force: the new verification session replaces it
    with open_rig(cfg, legs=plan.legs, time_scale=args.time_scale, noise_seed=noise_seed) as rig:
        print(f"rig: {rig.description}" + (f"; plant seed {cfg.sim.seed}, noise seed {noise_seed}" if cfg.is_sim else ""))
        for leg in plan.legs:
            print(f"compensation target of leg {leg}: {target_text(cfg, leg)}")
        job = verify_job(rig, plan, out, cfg, audit=audit, before=before, expected_sha256=expected,
                         expected_source=str(args.table), drive_url=drive_url_of(cfg),
                         sinks=[LegPrinter(), ConsoleProgress()], normalise=not args.raw)
    for problem in job.audit_problems:
        print(f"warning: {problem}", file=sys.stderr)
    end = job.finished
    if end is None or end.outcome == AuditOutcome.REFUSED:
        raise InputError(end.message if end is not None else "the verification ended without an outcome")
    verified = job.of(Verified)[-1]
    doc = {"session": verified.session, "before": None if before is None else {"path": str(before.path), "sha256": before.sha256},
           "legs": {str(leg): r.to_json() for leg, r in verified.results.items()}}
    print(f"session: {out} ({verified.session['outcome']}, {job.run.points} of {plan.total_points} points)")
    print()
    print(verified.report)
    # as-left: the verification's ISO 230-2 values with U against [tolerances.TYPE] as_left (docs/decisions.md)
    as_left = session_decisions(read_session(out), raw=args.raw, stage="as_left")["decisions"]
    print(f"As-left decisions ({as_left['rule']}):")
    for line in decision_lines(as_left["legs"]):
        print(f"  {line}")
    doc["decisions"] = as_left
    if args.json:
        Path(args.json).write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")
        print(f"figures: {args.json}")
    print(f"audit log: {audit.path}")
    if end.outcome != AuditOutcome.COMPLETED or any(not r.passed for r in verified.results.values()):
        print(end.message + ("; see above" if end.outcome == AuditOutcome.COMPLETED else ""), file=sys.stderr)
        return 1
    return 0
