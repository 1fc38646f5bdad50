"""`station export`: an HDF5 session file -> the interchange CSV."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse

NAME = "export"
HELP = "write a session file's points as an interchange CSV"
DESCRIPTION = (
    "Write the points of an HDF5 session file as an interchange CSV (one row per point, in plan order). "
    "Optional columns with no measured value are left out; points without a measured error are skipped."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("h5", type=V.SESSION.argtype(), metavar="FILE.h5", help="session file to read")
    p.add_argument("--out", type=V.OUT_FILE.argtype(), required=True, metavar="FILE.csv", help="CSV file to write")
    p.add_argument("--force", action="store_true", help="replace --out if it exists")


def run(args) -> int:
    from station.services.csv_jobs import ExportRequest, prepare_export

    for line in prepare_export(ExportRequest(args.h5, args.out, force=args.force)).run().lines:
        print(line)
    return 0
