"""`station table`: a compensation table from a model, for the drive (CSV) or LinuxCNC."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import sys

from procedures.vocabulary import InputError
from station.services.table_job import TABLE_FORMATS

NAME = "table"
HELP = "make a compensation table (CSV for the drives, or LinuxCNC COMP_FILEs) from a model"
DESCRIPTION = (
    "Resample a leg-error model on a fixed step over each leg's recorded stroke. The CSV has the "
    "columns leg,position_mm,error_fwd_um,error_rev_um: the predicted error (measured minus "
    "commanded) approaching in the + / - direction, which the drive subtracts. The table's point "
    "count and correction range are checked against the drive profile's limits. "
    "--format linuxcnc writes one COMP_FILE per joint (leg N -> joint N-1); siemens840d, heidenhain, "
    "twincat and ecmc one file per leg for those controllers. See docs/tables.md and docs/controllers.md."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", type=V.MODEL.argtype(), metavar="MODEL.json", help="model written by `station fit`")
    p.add_argument("--out", type=V.OUT_PATH.argtype(), required=True, metavar="TABLE.csv|DIR",
                   help="CSV file; for --format linuxcnc a directory (joint0.comp, ...) or NAME.comp (NAME_joint0.comp, ...)")
    p.add_argument("--step", type=V.STEP_MM.argtype(), metavar="MM", help="table step, mm (default: the recording's spacing, "
                   "coarsened to fit the point limit)")
    p.add_argument("--format", choices=list(TABLE_FORMATS), default="csv",
                   help="output format (default csv; controllers: docs/controllers.md)")
    p.add_argument("--siemens-mode", choices=["cec", "enc_comp"], default="cec",
                   help="siemens840d: direction-dependent CEC tables (default) or one $AA_ENC_COMP table (mean of both directions)")
    p.add_argument("--reference-mm", type=V.POSITION_MM.argtype(), default=0.0, metavar="MM",
                   help="siemens840d: the axis reference point, where the table is made zero (default 0, mid-stroke)")
    p.add_argument("--axis-name", type=V.AXIS_NAME.argtype(), default="X", help="heidenhain: the axis column's name, as in CfgAxes/axisList (default X)")
    p.add_argument("--ecmc-direction", choices=["mean", "fwd", "rev"], default="mean",
                   help="ecmc: one table for both directions: their mean (default) or one direction's error")
    p.add_argument("--comp-type", type=V.BANK_TYPE.argtype(), choices=[0, 1], default=0,
                   help="LinuxCNC COMP_FILE_TYPE: 0 = nominal, actual moving +, actual moving - (default); "
                   "1 = nominal, forward trim, reverse trim")
    p.add_argument("--profile", type=V.PROFILE.argtype(), metavar="PROFILE.toml", help="drive profile whose table limits apply (default: built-in)")
    p.add_argument("--legs", type=V.LEGS.argtype(), help="only these legs, e.g. 1-3 (default: all in the model)")
    p.add_argument("--config", type=V.CONFIG.argtype(), metavar="C", help="station TOML whose catalog indexes the file written "
                   "(default: the built-in config: <runs>/catalog.sqlite; docs/catalog.md)")
    p.add_argument("--force", action="store_true", help="replace the output file(s) if they exist (default: refused)")
    p.add_argument("--accept-implausible", action="store_true",
                   help="write a table whose corrections span more than the recorded error did, or whose model made a "
                        "leg worse on held-out data (refused by default; asked at a terminal)")


def run(args) -> int:
    from station.services.table_job import TableRequest, prepare_table

    job = prepare_table(TableRequest(
        args.model, args.out, format=args.format, step_mm=args.step, profile=args.profile, legs=args.legs,
        config=args.config, force=args.force, accept_implausible=args.accept_implausible, comp_type=args.comp_type,
        siemens_mode=args.siemens_mode, reference_mm=args.reference_mm, axis_name=args.axis_name,
        ecmc_direction=args.ecmc_direction))
    for line in job.lines:
        print(line)
    if job.question:  # the plausibility checks refused it: at a terminal, ask (as the UI's "Make anyway")
        if not (hasattr(sys.stdin, "isatty") and sys.stdin.isatty()):
            raise job.refusal  # --accept-implausible says yes on the command line
        print(f"refused: {job.refusal}")
        sys.stdout.write(f"{job.question} [y/N] ")
        sys.stdout.flush()
        if sys.stdin.readline().strip().lower() not in ("y", "yes"):
            raise InputError("not confirmed; nothing was written")
    for line in job.run().lines:
        print(line)
    return 0
