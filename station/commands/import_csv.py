"""`station import`: an interchange CSV from other laser software -> an HDF5 session file."""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from procedures.io.outputs import check_output_file
from station import __version__

if TYPE_CHECKING:
    from procedures.io.ranges import PointLimits

NAME = "import"
HELP = "convert an interchange CSV (leg, run, direction, target_mm, error_um, ...), or another layout through --map, to a session file"
# A plain string, so `station import --help` shows it without loading the CSV reader (h5py);
# tests/station/test_cli_startup.py holds it to REQUIRED_COLUMNS, OPTIONAL_COLUMNS and MAX_ERROR_UM.
DESCRIPTION = (
    "Convert measurements in the interchange CSV format to an HDF5 session file. Required columns: "
    "leg, run, direction, target_mm, error_um; optional: time_s, material_temp_c, air_temp_c, air_pressure_hpa, "
    "humidity_pct, load_n, speed_mm_s (a missing optional column "
    "means 'not measured'). The whole file is checked first; on any problem nothing is written. "
    "Values are checked against physical ranges: legs (--legs), targets within the drive profile's soft "
    "limits, |error_um| <= 1000 um, temperatures, pressure, humidity and load a workshop sees. "
    "Other laser software's CSV: --map MAP.toml says which columns hold what, their units, the sign of "
    "the error, how directions and runs are told (docs/import.md; examples in docs/import-maps/)."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("csv", metavar="FILE.csv", help="interchange CSV to read")
    p.add_argument("--out", required=True, metavar="FILE.h5", help="session file to write")
    p.add_argument("--operator", default="", help="operator name stored in the session")
    p.add_argument("--force", action="store_true", help="replace --out if it exists")
    p.add_argument("--legs", default="1-6", help="legs the file holds, e.g. 1-6 or 1,3 (default 1-6); "
                   "a point of another leg is refused")
    p.add_argument("--map", metavar="MAP.toml", help="mapping file for another software's layout (docs/import.md)")
    p.add_argument("--accept-implausible", action="store_true",
                   help="keep values that look like a unit slip (a degC value that looks like degF, an um value that "
                        "looks like nm): refused by default, naming line and field")
    p.add_argument("--profile", metavar="PROFILE.toml",
                   help="drive profile whose soft limits bound target_mm (default: the built-in profile)")


def import_limits(legs: str = "1-6", profile: str | None = None) -> PointLimits:
    """The physical ranges of an import: the legs given, the drive profile's soft limits."""
    from procedures.acquisition.plans import parse_legs
    from procedures.io.ranges import PointLimits
    from station.services.wiring import drive_soft_limits

    return PointLimits(legs=parse_legs(legs), stroke_mm=drive_soft_limits(profile))


def run(args) -> int:
    from procedures.io.csv_io import import_csv

    check_output_file(args.out, force=args.force, suffixes=(".h5",))
    limits = import_limits(args.legs, args.profile)
    warnings: list[str] = []
    if args.map:
        session = _import_mapped(args, limits, warnings)
    else:
        session = import_csv(Path(args.csv), Path(args.out), operator=args.operator, software_version=__version__,
                             overwrite=args.force, limits=limits,
                             accept_implausible=args.accept_implausible, warnings=warnings)
    pts = session.points
    legs = ", ".join(str(leg) for leg in session.legs)
    runs = len({(int(r["leg"]), int(r["run"])) for r in pts[["leg", "run"]]})
    optional = session.plan.get("optional_columns") or []
    for line in warnings:
        print(line)
    print(f"imported {len(pts)} points (legs {legs}; {runs} runs) from {args.csv}")
    print(f"optional columns: {', '.join(optional) if optional else 'none (environment unknown)'}")
    print(f"session written: {args.out} (sha256 {session.sha256[:16]}...)")
    return 0


def _import_mapped(args, limits, warnings):
    """Convert through the map, then import the interchange CSV; its problems are reported in
    terms of the source file (its lines and column names)."""
    from procedures.io.csv_io import import_csv
    from procedures.engine.errors import InputError
    from procedures.io.import_map import convert, load_map, source_message

    mapping = load_map(args.map)
    converted = convert(args.csv, mapping)
    with tempfile.TemporaryDirectory(prefix="station-import-") as tmp_dir:
        tmp = Path(tmp_dir) / f"{Path(args.csv).stem}.mapped.csv"
        tmp.write_text(converted.csv_text, encoding="utf-8")
        try:
            session = import_csv(tmp, Path(args.out), operator=args.operator, software_version=__version__,
                                 overwrite=args.force, limits=limits,
                             accept_implausible=args.accept_implausible, warnings=warnings)
        except InputError as exc:
            raise InputError(source_message(str(exc), tmp, Path(args.csv), converted)) from None
    print(f"map: {args.map} (" + ", ".join(f"{k} <- {v}" for k, v in converted.columns.items()) + ")")
    return session
