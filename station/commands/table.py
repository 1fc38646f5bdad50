"""`station table`: a compensation table from a model, for the drive (CSV) or LinuxCNC."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import sys
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from procedures.compensation import controllers
from procedures.vocabulary import InputError
from procedures.io.outputs import check_output_file

if TYPE_CHECKING:
    from procedures.io.plausibility import ImplausibleError

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
    p.add_argument("--format", choices=["csv", "linuxcnc", *controllers.FORMATS], default="csv",
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


def _soft_limits(args) -> tuple[float, float] | None:
    """The soft limits of the drive profile's (--profile, default the built-in one), when it states them."""
    from station.services.wiring import drive_soft_limits

    try:
        return drive_soft_limits(args.profile)
    except Exception:  # noqa: BLE001 (a bad profile is refused by drive_table_spec with its own message)
        return None


def _ask_anyway(exc: ImplausibleError) -> bool:
    """At a terminal, ask before making a table the checks refused (as the UI's "Make anyway"); False
    without one (the refusal stands: --accept-implausible says yes on the command line)."""
    if not (hasattr(sys.stdin, "isatty") and sys.stdin.isatty()):
        return False
    print(f"refused: {exc}")
    sys.stdout.write("Make the table anyway? [y/N] ")
    sys.stdout.flush()
    if sys.stdin.readline().strip().lower() in ("y", "yes"):
        return True
    raise InputError("not confirmed; nothing was written")


def output_paths(fmt: str, out: str, legs) -> list[Path]:
    """The files `--format fmt --out out` writes for `legs`, known before the table is made."""
    from procedures.compensation.controllers.linuxcnc import linuxcnc_paths

    if fmt == "csv":
        return [Path(out)]
    if fmt == "linuxcnc":
        return list(linuxcnc_paths(out, legs).values())
    from procedures.compensation.controllers.common import leg_paths

    module = controllers.module(fmt)
    return list(leg_paths(out, legs, module.SUFFIX, stem=getattr(module, "STEM", "leg{leg}")).values())


def run(args) -> int:
    from procedures.acquisition.plans import parse_legs
    from procedures.compensation.controllers.linuxcnc import LINUXCNC_LIMITS, write_linuxcnc_comp
    from procedures.fit import load_model
    from procedures.fit.model_io import unverified_model_line
    from procedures.io.plausibility import ImplausibleError
    from station.services.config import load_config
    from station.services.table_jobs import make_checked_table, write_table
    from station.services.wiring import drive_table_spec

    model = load_model(args.model)
    unverified = unverified_model_line(args.model, model)
    if unverified:
        print(unverified)
    legs = parse_legs(args.legs) if args.legs else None
    if legs is not None:
        missing = [x for x in legs if x not in model.legs]
        if missing:
            raise InputError(f"{args.model}: the model has no leg(s) {missing} (it has {list(model.legs)})")
    for path in output_paths(args.format, args.out, legs or list(model.legs)):  # before anything is made
        check_output_file(path, force=args.force, make_parents=args.format != "csv")
    if args.format in controllers.FORMATS:
        fmt = controllers.module(args.format)
        limits = fmt.LIMITS
    elif args.format == "linuxcnc":
        drive = drive_table_spec(args.profile) if args.profile else None
        limits = LINUXCNC_LIMITS if drive is None else replace(
            LINUXCNC_LIMITS, max_points=min(drive.max_points, LINUXCNC_LIMITS.max_points),
            max_correction_um=drive.max_correction_um)
    else:
        limits = drive_table_spec(args.profile)
        if limits is None:  # a drive without a table: the CSV is for the station's own table (target station)
            from station.services.wiring import station_store_table_spec

            limits = station_store_table_spec("[compensation] tables_path")
            print(f"note: the drive of {args.profile} holds no compensation table; the table is checked for the "
                  "station's table store (compensation target station, docs/compensation.md); for the "
                  "controller use --format linuxcnc")
    # the unit-slip and held-out checks are the service's, as on the UI's Compensation page; a drive table ends
    # within the drive's soft limits (the profile's), where the push will check it
    soft = _soft_limits(args) if args.format == "csv" else None
    try:
        table, warnings = make_checked_table(model, args.step, limits, legs=legs, accept_implausible=args.accept_implausible,
                                             soft_limits_mm=soft)
    except ImplausibleError as exc:
        if not _ask_anyway(exc):
            raise
        table, warnings = make_checked_table(model, args.step, limits, legs=legs, accept_implausible=True,
                                             soft_limits_mm=soft)
    if args.format == "csv":
        written = [write_table(table, args.out, load_config(args.config), limits)]
    elif args.format in controllers.FORMATS:
        options = {"siemens840d": {"mode": args.siemens_mode, "reference_mm": args.reference_mm},
                   "heidenhain": {"axis": args.axis_name}, "ecmc": {"direction": args.ecmc_direction}}
        written = fmt.write(table, args.out, spec=limits, **options.get(args.format, {}))
    else:
        written = write_linuxcnc_comp(table, args.out, args.comp_type, limits)
    print(f"model: {args.model} ({model.method}; from {model.source.get('path') or 'unknown recording'})")
    for line in warnings:
        print(line)
    basis = model.options.get("error_basis")
    if isinstance(basis, dict):  # what `station fit` fitted (docs/metrology.md)
        ref = basis.get("reference_temp_c", 20.0)
        print("error: normalised to " + f"{ref:g} degC material temperature (the table holds the leg's error at {ref:g} degC)"
              if basis.get("normalised") else "error: RAW, not normalised to 20 degC (the table holds the error at the "
              "calibration's temperatures)")
    else:
        print("error: not stated by the model (fitted before normalisation to 20 degC existed: raw)")
    for leg, t in table.legs.items():
        worst = max(float(np.max(np.abs(t.error_fwd_um))), float(np.max(np.abs(t.error_rev_um))))
        print(f"leg {leg}: {t.point_count} points, {t.start_mm:g} .. {t.end_mm:g} mm step {t.step_mm:g} mm, "
              f"largest correction {worst:.3f} um (limit {limits.max_correction_um:g} um)")
    for path in written:
        print(f"wrote {path}")
    if args.format == "linuxcnc":
        print(f"LinuxCNC: [JOINT_n] COMP_FILE = <file>  COMP_FILE_TYPE = {args.comp_type}  (machine units mm)")
    elif args.format in controllers.FORMATS:
        print(controllers.HINTS[args.format])
    else:
        print(f"next: station push {written[0]} --leg N --sim")
    return 0
