"""`station sweep`: a calibration sweep with a progress bar, recorded to HDF5."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import math
import shlex
import sys
from pathlib import Path

from typing import TYPE_CHECKING

from procedures.engine.errors import InputError
from procedures.acquisition.plan_spec import PLAN_KINDS

if TYPE_CHECKING:
    from procedures.acquisition.plan_spec import PlanSpec
    from procedures.acquisition.plans import SweepPlan

# What a run needs is imported inside the functions (the recorder, the catalog, the rig's
# drivers): `station sweep --help`, an argument error and a refusal load none of it.

NAME = "sweep"
HELP = "run a calibration sweep (ISO 230-2, the paper's, or on the fly) and record it to HDF5"
DESCRIPTION = (
    "Run a bidirectional calibration sweep on one or more legs and record every point to an HDF5 "
    "session file. Ctrl-C stops the motion and leaves a valid file; `--resume FILE.h5` finishes it."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    where = p.add_mutually_exclusive_group()
    where.add_argument("--sim", action="store_true", help="use the simulated rig (default without --config)")
    where.add_argument("--config", type=V.CONFIG.argtype(), help="station TOML naming the real drives and interferometer")
    p.add_argument("--out", type=V.OUT_FILE.argtype(), help="session file to write (FILE.h5)")
    p.add_argument("--force", action="store_true", help="replace --out if it exists (default: refused)")
    p.add_argument("--resume", type=V.SESSION_TO_RESUME.argtype(), metavar="FILE.h5", help="finish an interrupted session (its plan is reused)")
    p.add_argument("--plan", choices=PLAN_KINDS, default="iso230",
                   help="sweep plan (default iso230); onthefly: constant-speed passes captured at every step "
                        "(0.5 mm), onthefly-adaptive: the same, stopping once the table stops improving")
    p.add_argument("--legs", type=V.LEGS.argtype(), default="1", help="legs, e.g. 1-6 or 1,3 (default 1)")
    p.add_argument("--cycles", type=V.CYCLES.argtype(), help="bidirectional cycles (default: 5 iso230, 6 paper, 6 onthefly, "
                                               "at most 8 onthefly-adaptive)")
    spacing = p.add_mutually_exclusive_group()
    spacing.add_argument("--step", type=V.STEP_MM.argtype(), metavar="MM", help="uniform target spacing in mm (on the fly: "
                                                                   "capture spacing, default 0.5)")
    spacing.add_argument("--targets", type=V.TARGETS_FILE.argtype(), metavar="FILE", help="targets in mm, one per line or a target_mm column")
    p.add_argument("--n-targets", type=V.TARGET_COUNT.argtype(), help="number of irregularly spaced ISO 230-2 targets (default 11)")
    p.add_argument("--min-mm", type=V.POSITION_MM.argtype(), default=-90.0, help="lowest target, mm (default -90)")
    p.add_argument("--max-mm", type=V.POSITION_MM.argtype(), default=90.0, help="highest target, mm (default +90)")
    p.add_argument("--dwell", type=V.TIME_S.argtype(), default=1.0, metavar="S", help="settle time per target, s (default 1)")
    p.add_argument("--averaging", type=V.TIME_S.argtype(), default=0.1, metavar="S", help="interferometer averaging, s")
    p.add_argument("--overrun", type=V.OVERRUN_MM.argtype(), default=2.0, metavar="MM", help="overrun before reversing, mm")
    p.add_argument("--time-scale", type=V.TIME_SCALE.argtype(), metavar="S",
                   help="simulated rig only: real seconds per simulated second (0 = no waiting; default 0)")
    p.add_argument("--seed", type=V.SEED.argtype(), help="simulated rig only: plant seed")
    p.add_argument("--serial", type=V.LEG_SERIAL.argtype(), action="append", default=[], metavar="LEG=SERIAL",
                   help="the serial number of a leg, e.g. --serial 3=HX-0042 (repeatable); recorded in the session "
                        "and checked by push")
    p.add_argument("--serials", type=V.SERIALS_FILE.argtype(), metavar="FILE", help="CSV leg,serial[,part_number,leg_type,screw_lot] with the legs' "
                                                     "serials (default: [station] serials_file)")
    p.add_argument("--yes", action="store_true",
                   help="sweep a leg whose compensation table is active without asking (the session records the "
                        "tables and is stage 'other', not an as-found calibration); without it the question is asked "
                        "at the terminal, and refused when stdin is not one")


def plan_spec(args) -> PlanSpec:
    """The plan `station sweep` is asked for (not for --resume, which reuses the file's plan)."""
    from procedures.acquisition.plan_spec import PlanSpec
    from procedures.acquisition.plans import parse_legs

    return PlanSpec(
        legs=parse_legs(args.legs), kind=args.plan, cycles=args.cycles, n_targets=args.n_targets, step_mm=args.step,
        targets_file=Path(args.targets) if args.targets else None, min_mm=args.min_mm, max_mm=args.max_mm,
        overrun_mm=args.overrun, dwell_s=args.dwell, averaging_s=args.averaging,
    )


def build_plan(args, limits=None) -> SweepPlan:
    """The plan asked for; with `limits` (the config's [limits]) sized first and refused beyond
    them before anything is built (procedures/acquisition/plan_size.py)."""
    from procedures.acquisition.plan_spec import plan_from_spec

    return plan_from_spec(plan_spec(args), limits)


def check_time_scale(time_scale: float | None) -> None:
    """--time-scale: real seconds per simulated second, a finite number >= 0 (or not given)."""
    if time_scale is not None and not (math.isfinite(time_scale) and time_scale >= 0):
        raise InputError(f"--time-scale must be a number >= 0 (real seconds per simulated second; 0 = no "
                         f"waiting), got {time_scale:g}")


def resume_command(out: Path, cfg, config: str | None) -> str:
    """The line that finishes `out`, its paths quoted for the shell (a space in a folder name)."""
    where = "--sim" if config is None else f"--config {shlex.quote(str(config))}"
    return f"resume with: station sweep --resume {shlex.quote(str(out))} {where}"


def _confirm(yes: bool):
    """How a sweep of a compensated leg is confirmed here: --yes; else the question at the
    terminal; else (no terminal) None: refused in one line naming the legs and --yes."""
    from station.commands._table_cli import prompt

    if yes:
        return lambda question: True
    return prompt(False) if sys.stdin is not None and sys.stdin.isatty() else None


def run(args) -> int:
    from procedures.io.outputs import check_appendable, check_output_file
    from station.services.config import load_config
    from station.services.identity import leg_fields
    from station.services.serials import parse_serial_args, serials_unverified_line

    cfg = load_config(args.config)
    cfg.require_devices()
    serials = parse_serial_args(args.serial)
    leg_fields(cfg, serials, args.serials)  # a bad serials file is refused before anything moves
    unverified = serials_unverified_line(args.serials or cfg.serials_file)
    if unverified:  # a list typed by hand: read whole, but nothing proves it (procedures/io/integrity.py)
        print(unverified)
    check_time_scale(args.time_scale)
    if args.seed is not None:
        cfg.sim.seed = args.seed
    # every output is checked before anything connects or moves (procedures/io/outputs.py)
    if args.resume:
        if args.serial or args.serials:
            raise InputError("--serial/--serials name the legs of a new session; a resumed session keeps the identity "
                             "it was created with: drop them")
        out = check_appendable(args.resume)
        if args.out and Path(args.out) != out:
            raise InputError("--resume appends to the session it names; drop --out")
        from station.services.jobs import resumable_plan

        plan = resumable_plan(out)
    else:
        if not args.out:
            raise InputError("--out FILE.h5 is required (where to record the session)")
        if Path(args.out).exists() and not args.force and Path(args.out).suffix.lower() == ".h5":
            raise InputError(f"--out {args.out}: exists; add --force to replace it, choose another --out, or "
                             f"--resume {args.out} to finish it; nothing was written")
        out = check_output_file(args.out, force=args.force, suffixes=(".h5",))
        plan = build_plan(args, cfg.limits)  # sized (and refused when huge) before anything connects
        from procedures.acquisition.plan_size import plan_size

        print(f"plan: {plan_size(plan_spec(args)).describe()}")
        if args.force and out.exists():
            out.unlink()  # --force: the new session replaces it (after the plan was accepted)
    for note in plan.notes:
        print(f"note: {note}")
    resume_hint = resume_command(out, cfg, args.config)
    from procedures.engine.control import RunControl
    from procedures.engine.states import Outcome
    from station import interrupt
    from station.interrupt import abort_on_sigint
    from station.progress import ConsoleProgress
    from station.services.jobs import run_sweep
    from station.services.wiring import open_rig

    # the simulated drives keep their tables where push/verify/rollback --sim and the UI find them
    # (its folder made only now, when everything was accepted): a leg pushed a table is swept
    # compensated here as in the UI, asked first (services.jobs.check_compensation)
    cfg.with_sim_memory()
    with open_rig(cfg, legs=plan.legs, time_scale=args.time_scale) as rig:
        print(f"rig: {rig.description}")
        with abort_on_sigint(RunControl()) as control:
            try:
                result = run_sweep(rig, plan, out, cfg, sinks=[ConsoleProgress()], control=control,
                                   resume=bool(args.resume), serials=serials, serials_file=args.serials,
                                   confirm_compensated=_confirm(args.yes))
            except KeyboardInterrupt:  # Ctrl-C twice: the runner has finished the session as aborted
                print(f"session: {out} ({Outcome.ABORTED}, interrupted (Ctrl-C twice))")
                if out.exists():  # a hint never names a file that was not written
                    print(resume_hint)
                return 130
    print(f"session: {out} ({result.outcome}, {result.points} of {plan.total_points} points)")
    if result.outcome == Outcome.COMPLETED:
        print(f"next: station iso230 {out}   |   station fit {out} --out model.json")
        return 0
    if out.exists():
        print(resume_hint)
    return 130 if control.reason == interrupt.REASON else 1  # Ctrl-C: as every command ends on it

