"""`station iso230`: ISO 230-2 positioning accuracy of each leg in a session file."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
from pathlib import Path

NAME = "iso230"
HELP = "ISO 230-2 values (E, M, A, B, R; up, down, both) of each leg in a session file"
DESCRIPTION = (
    "Evaluate a session file by ISO 230-2: per leg the systematic deviation E, accuracy A, repeatability R "
    "(per direction and bidirectional), range of mean bidirectional deviation M and reversal B, in micrometres. "
    "Values that cannot be computed are shown as '-' with the reason. Each leg with a leg type and "
    "[tolerances.TYPE] (the --config's, else those the session recorded) is decided by ISO 14253-1 with the "
    "expanded uncertainty U of each value: conforms / does not conform / cannot decide (docs/decisions.md)."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("h5", type=V.SESSION.argtype(), metavar="FILE.h5", help="session file (import a CSV first with `station import`)")
    p.add_argument("--json", type=V.OUT_FILE.argtype(), metavar="OUT", help="also write the values as JSON to OUT")
    p.add_argument("--force", action="store_true", help="replace the output if it exists (default: refused)")
    p.add_argument("--raw", action="store_true",
                   help="evaluate the raw error (default: normalised to 20 degC material temperature, docs/metrology.md)")
    p.add_argument("--config", type=V.CONFIG.argtype(), metavar="C", help="station TOML whose [tolerances.TYPE] decide (default: the "
                   "tolerances the session's config recorded)")


def run(args) -> int:
    from station.services.iso230_job import Iso230Request, prepare_iso230

    job = prepare_iso230(Iso230Request(Path(args.h5), Path(args.json) if args.json else None, args.force, args.raw,
                                       args.config))
    for line in job.run().lines:
        print(line)
    return 0
