"""`station import`: an interchange CSV from other laser software -> an HDF5 session file."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse

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


def run(args) -> int:
    from station.services.csv_jobs import ImportRequest, prepare_import

    job = prepare_import(ImportRequest(
        args.csv, args.out, operator=args.operator, force=args.force, legs=args.legs, map=args.map,
        accept_implausible=args.accept_implausible, profile=args.profile, serial=args.serial,
        part_number=args.part_number, leg_type=args.leg_type, screw_lot=args.screw_lot, station=args.station,
        stage=args.stage, measured=args.measured, config=args.config))
    for line in job.run().lines:
        print(line)
    return 0
