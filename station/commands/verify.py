"""`station verify`: a verification sweep with the compensation table active, before vs after."""

from __future__ import annotations

import argparse
import json
import secrets
import sys
from dataclasses import replace
from pathlib import Path

from procedures.audit import AuditEntry, AuditError
from procedures.errors import InputError
from procedures.plans import SweepPlan, iso230_plan, parse_legs
from procedures.push import describe_table, quantize, table_sha256
from procedures.recording.reader import read_session
from procedures.table import read_table_csv
from procedures.verify import ACCEPT_RATIO, format_report, verify
from station.commands.push import audit_log, load_profile, station_config, table_limits
from station.jobs import run_sweep
from station.progress import ConsoleProgress
from station.wiring import open_rig

NAME = "verify"
HELP = "verification sweep with the table active: compensated error and ISO 230-2 before vs after"
DESCRIPTION = (
    "Sweep the leg(s) with their compensation table active (the plan of the calibration session given "
    "with --before, or an ISO 230-2 plan), record it to HDF5, and report the compensated error (residual "
    "RMS about the mean, range) and the ISO 230-2 values before (the calibration) and after, side by "
    f"side, with the residual RMS divided by the noise floor (pass: <= {ACCEPT_RATIO:g}). Each leg gets an "
    "audit entry. Exit code 0 = completed and every leg passed. See docs/compensation.md."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--leg", required=True, metavar="N", help="leg(s) to verify: 2, 1-3 or 1,4")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--sim", action="store_true",
                       help="the simulated rig, with the drive table memory `station push --sim` wrote")
    where.add_argument("--config", metavar="C", help="station TOML naming the drives and the interferometer")
    p.add_argument("--out", required=True, metavar="FILE.h5", help="session file for the verification sweep")
    p.add_argument("--before", metavar="FILE.h5", help="the calibration session: its plan is repeated and its "
                   "figures are the 'before' column")
    p.add_argument("--table", metavar="TABLE.csv", help="refuse unless each leg's active table is this table's rows")
    p.add_argument("--cycles", type=int, help="without --before: ISO 230-2 cycles (default 5)")
    p.add_argument("--audit", metavar="FILE", help="audit log (default <recordings_dir>/audit.jsonl)")
    p.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    p.add_argument("--profile", metavar="PROFILE.toml", help="drive profile (default: the config's, or the built-in one)")
    p.add_argument("--time-scale", type=float, metavar="S", help="simulated rig only: real seconds per simulated second")
    p.add_argument("--seed", type=int, help="simulated rig only: plant seed (as for `station sweep`)")
    p.add_argument("--noise-seed", type=int, metavar="N",
                   help="simulated rig only: seed of the measurement noise (default: a new one, so the verification "
                        "does not repeat the calibration's noise; printed for reproduction)")


def _plan(args, legs: tuple[int, ...], before) -> SweepPlan:
    if before is None:
        return iso230_plan(legs, cycles=args.cycles or 5)
    if args.cycles:
        raise InputError("--cycles applies without --before only (the calibration's plan is repeated as it was)")
    try:
        plan = SweepPlan.from_dict(before.plan)
    except (InputError, TypeError, ValueError) as exc:
        raise InputError(f"{before.path}: its sweep plan cannot be repeated ({exc}); verify without --before") from None
    missing = [leg for leg in legs if leg not in before.legs]
    if missing:
        raise InputError(f"{before.path}: no calibration points for leg(s) {missing} (it has legs {before.legs})")
    return replace(plan, legs=legs, kind="verification", notes=())


def run(args) -> int:
    legs = parse_legs(args.leg)
    if args.config and (args.seed is not None or args.noise_seed is not None):
        raise InputError("--seed/--noise-seed apply to the simulated rig (--sim) only")
    cfg = station_config(args)
    if args.seed is not None:
        cfg.sim.seed = args.seed
    audit = audit_log(args, cfg)
    out = Path(args.out)
    if out.exists():
        raise InputError(f"{out}: exists; choose another --out (a verification is a new session)")
    before = read_session(args.before) if args.before else None
    plan = _plan(args, legs, before)
    profile = load_profile(args, cfg)
    expected: dict[int, str] = {}
    if args.table:
        table = read_table_csv(args.table, table_limits(profile))
        missing = [leg for leg in legs if leg not in table.legs]
        if missing:
            raise InputError(f"{args.table}: no rows for leg(s) {missing} (it has legs {list(table.legs)})")
        expected = {leg: table_sha256(quantize(table.legs[leg].to_bank(), profile.table.entry_scale_um)) for leg in legs}
    noise_seed = None
    if cfg.is_sim:
        noise_seed = args.noise_seed if args.noise_seed is not None else secrets.randbelow(1 << 31)
        if noise_seed == cfg.sim.seed:
            print(f"note: noise seed {noise_seed} = plant seed: the sweep repeats the noise of a `station sweep --sim` "
                  "of the same plan exactly, so it is not an independent verification")
    with open_rig(cfg, legs=plan.legs, time_scale=args.time_scale, noise_seed=noise_seed) as rig:
        print(f"rig: {rig.description}" + (f"; plant seed {cfg.sim.seed}, noise seed {noise_seed}" if cfg.is_sim else ""))
        active = {}
        for leg in legs:
            axis = rig.axes[leg]
            st = axis.status()
            bank = axis.active_bank()
            t = axis.read_table(bank)
            sha = table_sha256(t)
            active[leg] = (axis.identity(), bank, sha, cfg.drive.url)
            problem = None
            if t.point_count == 0:
                problem = f"leg {leg}: the drive's active table (bank {bank}) is empty; push a table first (`station push`)"
            elif not st.table_enabled:
                problem = f"leg {leg}: the drive does not apply its table (table_enable = 0); switch it on first"
            elif leg in expected and expected[leg] != sha:
                problem = (f"leg {leg}: the drive's active table (sha256 {sha[:12]}…) is not the leg's rows of {args.table} "
                           f"(sha256 {expected[leg][:12]}…); push it first")
            if problem:
                _log(audit, "verify", leg, active[leg], "refused", problem, cfg.operator)
                raise InputError(problem)
            print(f"leg {leg}: bank {bank} active, {describe_table(t)}, sha256 {sha[:12]}…")
        try:
            result = run_sweep(rig, plan, out, cfg, sinks=[ConsoleProgress()])
        except (Exception, KeyboardInterrupt) as exc:
            for leg in legs:
                _log(audit, "verify", leg, active[leg], "failed", f"verification sweep failed: {exc}", cfg.operator,
                     {"session": str(out)})
            raise
    session = read_session(out)
    results = verify(session.points, before.points if before is not None else None, legs,
                     after_source=str(out), before_source=str(before.path) if before is not None else "")
    print(f"session: {out} ({result.outcome}, {result.points} of {plan.total_points} points)")
    print()
    print(format_report(results))
    doc = {
        "session": {"path": str(out), "sha256": session.sha256, "outcome": result.outcome},
        "before": None if before is None else {"path": str(before.path), "sha256": before.sha256},
        "legs": {str(leg): r.to_json() for leg, r in results.items()},
    }
    for leg, r in results.items():
        ratio = r.ratio
        msg = (f"verification {result.outcome}: residual RMS {r.after.rms_um:.4f} um, noise floor "
               + (f"{r.after.noise_floor_um:.4f} um, ratio {ratio:.3f} ({'pass' if r.passed else 'above'} {ACCEPT_RATIO:g})"
                  if ratio is not None else "n/a"))
        details = {"session": str(out), "session_sha256": session.sha256, **r.to_json()}
        if before is not None:
            details["before_session"] = {"path": str(before.path), "sha256": before.sha256}
        _log(audit, "verify", leg, active[leg], result.outcome, msg, cfg.operator, details)
    if args.json:
        Path(args.json).write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")
        print(f"figures: {args.json}")
    print(f"audit log: {audit.path}")
    if result.outcome != "completed":
        print(f"the verification sweep did not complete ({result.outcome}: {result.reason})", file=sys.stderr)
        return 1
    failed = [leg for leg, r in results.items() if not r.passed]
    if failed:
        print(f"leg(s) {failed}: residual RMS above {ACCEPT_RATIO:g} x the noise floor (or no floor); see above",
              file=sys.stderr)
        return 1
    return 0


def _log(audit, action: str, leg: int, drive: tuple[str, int, str, str], outcome: str, message: str, operator: str,
         details: dict | None = None) -> None:
    identity, bank, sha, url = drive
    try:
        audit.append(AuditEntry(action, leg, outcome, message, identity, url, operator, table_sha256=sha, bank=bank,
                                details=details or {}))
    except AuditError as exc:
        print(f"warning: {exc}", file=sys.stderr)
