"""`station import`: an interchange CSV from other laser software -> an HDF5 session file."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

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
    "the error, how directions and runs are told (docs/import.md; examples in docs/import-maps/). Identity, so "
    "the session is decided and certified like a recorded one: --serial, --part-number, --leg-type, --screw-lot, "
    "--station, --stage, --measured, or the map's [identity], or --config's [legs.N], [station] id and [metrology]."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("csv", type=V.CSV_IN.argtype(), metavar="FILE.csv", help="interchange CSV to read")
    p.add_argument("--out", type=V.OUT_FILE.argtype(), required=True, metavar="FILE.h5", help="session file to write")
    p.add_argument("--operator", type=V.NAME_OR_EMPTY.argtype(), default="", help="operator name stored in the session")
    p.add_argument("--force", action="store_true", help="replace --out if it exists")
    p.add_argument("--legs", type=V.LEGS.argtype(), default="1-6", help="legs the file holds, e.g. 1-6 or 1,3 (default 1-6); "
                   "a point of another leg is refused")
    p.add_argument("--map", type=V.TOML_FILE.argtype(), metavar="MAP.toml", help="mapping file for another software's layout (docs/import.md)")
    p.add_argument("--accept-implausible", action="store_true",
                   help="keep values that look like a unit slip (a degC value that looks like degF, an um value that "
                        "looks like nm): refused by default, naming line and field")
    p.add_argument("--profile", type=V.PROFILE.argtype(), metavar="PROFILE.toml",
                   help="drive profile whose soft limits bound target_mm (default: the built-in profile)")
    p.add_argument("--serial", type=V.SERIAL_OR_LEG_SERIAL.argtype(), action="append", metavar="[LEG=]SERIAL",
                   help="the leg's serial (LEG=SERIAL for each leg of a file of several; repeat)")
    p.add_argument("--part-number", type=V.NAME_TEXT.argtype(), metavar="PN", help="the legs' part number")
    p.add_argument("--leg-type", type=V.NAME_TEXT.argtype(), metavar="TYPE", help="the legs' type ([tolerances.TYPE] decides them)")
    p.add_argument("--screw-lot", type=V.NAME_TEXT.argtype(), metavar="LOT", help="the legs' screw lot")
    p.add_argument("--station", type=V.NAME_TEXT.argtype(), metavar="ID", help="the station (or lab) that measured")
    p.add_argument("--stage", choices=("calibration", "verification", "other"), metavar="STAGE", help="calibration (as found), verification (as left) or other")
    p.add_argument("--measured", type=V.DATE_TIME.argtype(), metavar="DATE", help="when the measurement was made, YYYY-MM-DD[THH:MM] UTC")
    p.add_argument("--config", type=V.CONFIG.argtype(), metavar="C", help="station TOML: [legs.N] identity, [station] id, [metrology] laser "
                   "and uncertainties, [tolerances]; recorded in the session")


def import_limits(legs: str = "1-6", profile: str | None = None) -> PointLimits:
    """The physical ranges of an import: the legs given, the drive profile's soft limits."""
    from procedures.acquisition.plans import parse_legs
    from procedures.io.ranges import PointLimits
    from station.services.wiring import drive_soft_limits

    return PointLimits(legs=parse_legs(legs), stroke_mm=drive_soft_limits(profile))


def _identity(args, mapping) -> dict:
    """import_csv's identity keywords: the identity given (options, map, --config), checked now,
    the legs' part once the file is read (station/services/import_identity.py)."""
    from station.services import import_identity  # noqa: PLC0415

    cfg = None
    if args.config:
        from station.services.config import load_config  # noqa: PLC0415

        cfg = load_config(args.config)
    options = {"serial": args.serial, "part_number": args.part_number, "leg_type": args.leg_type,
               "screw_lot": args.screw_lot, "station": args.station, "stage": args.stage, "measured": args.measured}
    ii = import_identity.given(options, mapping.identity if mapping else None, str(mapping.path) if mapping else "",
                               cfg)
    if not ii.any and cfg is None:
        return {}
    return {"identity": lambda legs: ii.identity_json(legs, args.operator, __version__),
            "station_config": cfg.to_dict() if cfg is not None else None, "stage": ii.stage,
            "started_utc": ii.started_utc}


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
                             accept_implausible=args.accept_implausible, warnings=warnings, **_identity(args, None))
    pts = session.points
    legs = ", ".join(str(leg) for leg in session.legs)
    runs = len({(int(r["leg"]), int(r["run"])) for r in pts[["leg", "run"]]})
    optional = session.plan.get("optional_columns") or []
    for line in warnings:
        print(line)
    print(f"imported {len(pts)} points (legs {legs}; {runs} runs) from {args.csv}")
    print(f"optional columns: {', '.join(optional) if optional else 'none (environment unknown)'}")
    if session.identity.recorded:
        who = ", ".join(f"leg {leg} {session.identity.leg(leg).serial or '(no serial)'}"
                        + (f" type {session.identity.leg(leg).leg_type}" if session.identity.leg(leg).leg_type else "")
                        for leg in session.legs)
        print(f"identity: {who}; station {session.identity.station.id or 'not stated'}; stage "
              f"{session.plan.get('stage') or 'not stated (other)'}; measured {session.attrs.get('started_utc')}")
    else:
        print("identity: none given (no serial, type or stage): the session cannot be decided or certified; give "
              "--serial, --leg-type, --stage (or the map's [identity], or --config)")
    print(f"session written: {args.out} (sha256 {session.sha256[:16]}...)")
    return 0


def _import_mapped(args, limits, warnings):
    """Convert through the map, then import the interchange CSV; its problems are reported in
    terms of the source file (its lines and column names)."""
    from procedures.io.csv_io import import_csv
    from procedures.vocabulary import InputError
    from procedures.io.import_map import convert, load_map, source_message

    mapping = load_map(args.map)
    ident = _identity(args, mapping)  # checked before the file is read
    converted = convert(args.csv, mapping)
    with tempfile.TemporaryDirectory(prefix="station-import-") as tmp_dir:
        tmp = Path(tmp_dir) / f"{Path(args.csv).stem}.mapped.csv"
        tmp.write_text(converted.csv_text, encoding="utf-8")
        try:
            session = import_csv(tmp, Path(args.out), operator=args.operator, software_version=__version__,
                                 overwrite=args.force, limits=limits,
                                 accept_implausible=args.accept_implausible, warnings=warnings, **ident)
        except InputError as exc:
            raise InputError(source_message(str(exc), tmp, Path(args.csv), converted)) from None
    print(f"map: {args.map} (" + ", ".join(f"{k} <- {v}" for k, v in converted.columns.items()) + ")")
    return session
