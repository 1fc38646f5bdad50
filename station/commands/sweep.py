"""`station sweep`: a calibration sweep with a progress bar, recorded to HDF5."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import shlex
import sys
from pathlib import Path

from typing import TYPE_CHECKING

from procedures.vocabulary import InputError
from station.services.sweep_job import PLAN_KINDS

if TYPE_CHECKING:
    from station.services.sweep_job import SweepRequest

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


def request(args) -> SweepRequest:
    """The sweep `station sweep` is asked for, as the services' request."""
    from station.services.sweep_job import SweepRequest

    return SweepRequest(
        out=args.resume or args.out, resume=bool(args.resume), force=args.force, legs=args.legs, kind=args.plan,
        cycles=args.cycles, n_targets=args.n_targets, step_mm=args.step, targets_file=args.targets,
        min_mm=args.min_mm, max_mm=args.max_mm, overrun_mm=args.overrun, dwell_s=args.dwell,
        averaging_s=args.averaging, serials=_serials(args), serials_file=args.serials, time_scale=args.time_scale,
        seed=args.seed, ways_out=WAYS_OUT,
    )


WAYS_OUT = {"rollback": "station rollback --leg N", "confirm": "station sweep --yes"}
"""The ways out of a refused sweep of a compensated leg, as this command line takes them."""


def _serials(args) -> dict:
    from station.services.serials import parse_serial_args

    return parse_serial_args(args.serial)


def plan_spec(args):
    """The plan `station sweep` is asked for (procedures.acquisition.plan_spec.PlanSpec; not for
    --resume, which reuses the file's plan)."""
    from station.services.sweep_job import plan_spec_of

    return plan_spec_of(request(args))


def build_plan(args, limits=None):
    """The plan asked for; with `limits` (the config's [limits]) sized first and refused beyond
    them before anything is built (procedures/acquisition/plan_size.py)."""
    from station.services.sweep_job import build_plan_of

    return build_plan_of(request(args), limits)


def resume_command(out: Path, cfg, config: str | None) -> str:
    """The line that finishes `out`, its paths quoted for the shell (a space in a folder name)."""
    where = "--sim" if config is None else f"--config {shlex.quote(str(config))}"
    return f"resume with: station sweep --resume {shlex.quote(str(out))} {where}"


def _confirm(yes: bool):
    """How a question (a sweep of a compensated leg) is confirmed here: --yes; else the question
    at the terminal; else (no terminal) None: refused in one line naming the legs and --yes."""
    from station.commands._table_cli import prompt

    if yes:
        return lambda question: True
    return prompt(False) if sys.stdin is not None and sys.stdin.isatty() else None


def run(args) -> int:
    from station.services.config import load_config
    from station.services.sweep_job import OutputExists, prepare_sweep

    cfg = load_config(args.config)
    cfg.require_devices()
    if args.resume:
        if args.out and Path(args.out) != Path(args.resume):
            raise InputError("--resume appends to the session it names; drop --out")
    elif not args.out:
        raise InputError("--out FILE.h5 is required (where to record the session)")
    # every refusal is made before anything connects or moves (station/services/sweep_job.py)
    try:
        job = prepare_sweep(request(args), cfg)
    except OutputExists:
        raise InputError(f"--out {args.out}: exists; add --force to replace it, choose another --out, or "
                         f"--resume {args.out} to finish it; nothing was written") from None
    for line in job.lines:
        print(line)
    return run_prepared(job, cfg, args.config, _confirm(args.yes))


def run_prepared(job, cfg, config: str | None, confirm) -> int:
    """Run the prepared sweep `job` on the rig the config names, with a progress bar and Ctrl-C
    as an abort; print how it ended (the session line, what next). The exit code."""
    from station import interrupt
    from station.commands._rig_cli import run_on_rig

    out = job.out
    resume_hint = resume_command(out, cfg, config)
    try:
        ended, control = run_on_rig(job, confirm)
    except KeyboardInterrupt:  # Ctrl-C twice: the runner has finished the session as aborted
        print(f"session: {out} (aborted, interrupted (Ctrl-C twice))")
        if out.exists():  # a hint never names a file that was not written
            print(resume_hint)
        return 130
    print(f"session: {out} ({ended.status}, {ended.points} of {job.total_points} points)")
    if ended.status == "completed":
        print(f"next: station iso230 {out}   |   station fit {out} --out model.json")
        return 0
    if out.exists():
        print(resume_hint)
    return 130 if control.reason == interrupt.REASON else 1  # Ctrl-C: as every command ends on it
