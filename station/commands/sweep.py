"""`station sweep`: a calibration sweep with a progress bar, recorded to HDF5."""

from __future__ import annotations

import argparse
from pathlib import Path

from procedures.errors import InputError
from procedures.plan_spec import PLAN_KINDS, PlanSpec, plan_from_spec
from procedures.plans import parse_legs, SweepPlan
from station.services.config import load_config
from station.services.jobs import resumable_plan, run_sweep
from station.services.sessions import new_session_problem
from procedures.control import RunControl
from procedures.states import Outcome
from station import interrupt
from station.interrupt import abort_on_sigint
from station.progress import ConsoleProgress
from station.services.wiring import open_rig

NAME = "sweep"
HELP = "run a calibration sweep (ISO 230-2, the paper's, or on the fly) and record it to HDF5"
DESCRIPTION = (
    "Run a bidirectional calibration sweep on one or more legs and record every point to an HDF5 "
    "session file. Ctrl-C stops the motion and leaves a valid file; `--resume FILE.h5` finishes it."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    where = p.add_mutually_exclusive_group()
    where.add_argument("--sim", action="store_true", help="use the simulated rig (default without --config)")
    where.add_argument("--config", help="station TOML naming the real drives and interferometer")
    p.add_argument("--out", help="session file to write (FILE.h5)")
    p.add_argument("--resume", metavar="FILE.h5", help="finish an interrupted session (its plan is reused)")
    p.add_argument("--plan", choices=PLAN_KINDS, default="iso230",
                   help="sweep plan (default iso230); onthefly: constant-speed passes captured at every step "
                        "(0.5 mm), onthefly-adaptive: the same, stopping once the table stops improving")
    p.add_argument("--legs", default="1", help="legs, e.g. 1-6 or 1,3 (default 1)")
    p.add_argument("--cycles", type=int, help="bidirectional cycles (default: 5 iso230, 6 paper, 6 onthefly, "
                                               "at most 8 onthefly-adaptive)")
    spacing = p.add_mutually_exclusive_group()
    spacing.add_argument("--step", type=float, metavar="MM", help="uniform target spacing in mm (on the fly: "
                                                                   "capture spacing, default 0.5)")
    spacing.add_argument("--targets", metavar="FILE", help="targets in mm, one per line or a target_mm column")
    p.add_argument("--n-targets", type=int, help="number of irregularly spaced ISO 230-2 targets (default 11)")
    p.add_argument("--min-mm", type=float, default=-90.0, help="lowest target, mm (default -90)")
    p.add_argument("--max-mm", type=float, default=90.0, help="highest target, mm (default +90)")
    p.add_argument("--dwell", type=float, default=1.0, metavar="S", help="settle time per target, s (default 1)")
    p.add_argument("--averaging", type=float, default=0.1, metavar="S", help="interferometer averaging, s")
    p.add_argument("--overrun", type=float, default=2.0, metavar="MM", help="overrun before reversing, mm")
    p.add_argument("--time-scale", type=float, metavar="S",
                   help="simulated rig only: real seconds per simulated second (0 = no waiting; default 0)")
    p.add_argument("--seed", type=int, help="simulated rig only: plant seed")


def plan_spec(args) -> PlanSpec:
    """The plan `station sweep` is asked for (not for --resume, which reuses the file's plan)."""
    return PlanSpec(
        legs=parse_legs(args.legs), kind=args.plan, cycles=args.cycles, n_targets=args.n_targets, step_mm=args.step,
        targets_file=Path(args.targets) if args.targets else None, min_mm=args.min_mm, max_mm=args.max_mm,
        overrun_mm=args.overrun, dwell_s=args.dwell, averaging_s=args.averaging,
    )


def build_plan(args) -> SweepPlan:
    return plan_from_spec(plan_spec(args))


def run(args) -> int:
    cfg = load_config(args.config)
    cfg.require_devices()
    if args.seed is not None:
        cfg.sim.seed = args.seed
    if args.resume:
        out = Path(args.resume)
        if args.out and Path(args.out) != out:
            raise InputError("--resume appends to the session it names; drop --out")
        plan = resumable_plan(out)
    else:
        if not args.out:
            raise InputError("--out FILE.h5 is required (where to record the session)")
        out = Path(args.out)
        problem = new_session_problem(out)
        if problem == "exists":
            raise InputError(f"{out} exists; choose another --out, or --resume {out} to finish it")
        if problem == "no folder":
            raise InputError(f"--out {out}: the folder {out.parent} does not exist; create it first or choose "
                             "another --out (nothing is created behind your back)")
        plan = build_plan(args)
    for note in plan.notes:
        print(f"note: {note}")
    resume_hint = f"resume with: station sweep --resume {out}" + (" --sim" if cfg.is_sim else f" --config {args.config}")
    with open_rig(cfg, legs=plan.legs, time_scale=args.time_scale) as rig:
        print(f"rig: {rig.description}")
        with abort_on_sigint(RunControl()) as control:
            try:
                result = run_sweep(rig, plan, out, cfg, sinks=[ConsoleProgress()], control=control,
                                   resume=bool(args.resume))
            except KeyboardInterrupt:  # Ctrl-C twice: the runner has finished the session as aborted
                print(f"session: {out} ({Outcome.ABORTED}, interrupted (Ctrl-C twice))\n{resume_hint}")
                return 130
    print(f"session: {out} ({result.outcome}, {result.points} of {plan.total_points} points)")
    if result.outcome == Outcome.COMPLETED:
        print(f"next: station iso230 {out}   |   station fit {out} --out model.json")
        return 0
    print(resume_hint)
    return 130 if control.reason == interrupt.REASON else 1  # Ctrl-C: as every command ends on it

