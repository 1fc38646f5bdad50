"""`station compare`: do stations agree? Sessions of one reference leg from several stations,
per target and direction E_n with both stations' U; a station flagged beyond chance."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
from pathlib import Path

NAME = "compare"
HELP = "station comparison: sessions of one reference leg from several stations, E_n per target, bias flagged"
DESCRIPTION = (
    "Compare sessions of the same reference leg (same serial; refused otherwise, naming both) and of the same "
    "stage (an as-found calibration with calibrations, an as-left verification with verifications) measured by "
    "different stations: per target and direction the mean deviation of each station against the mean of the "
    "others, E_n = d / sqrt(U^2 + U_ref^2) with each side's expanded U of that mean (the uncertainty budget), and "
    "a station flagged when |E_n| > 1 at more targets than chance allows (binomial at 5 %). Sessions started "
    "further apart than [catalog] compare_window_days of --config (default 90) are refused, as the web's /compare "
    "does not compare them: their difference is the leg's drift, not a station's bias. Writes compare.md, "
    "compare.json and compare.png into --out. docs/decisions.md."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("sessions", type=V.SESSION.argtype(), nargs="+", metavar="FILE.h5", help="two or more sessions of the reference leg")
    p.add_argument("--serial", type=V.SERIAL.argtype(), help="the reference leg's serial (default: the one serial every session holds)")
    p.add_argument("--out", type=V.OUT_DIR.argtype(), required=True, metavar="DIR", help="folder for compare.md/.json/.png (created; its parent must exist)")
    p.add_argument("--force", action="store_true", help="replace compare.md/.json/.png in an existing --out (default: refused)")
    p.add_argument("--raw", action="store_true", help="compare the raw error (default: normalised to 20 degC)")
    p.add_argument("--config", type=V.CONFIG.argtype(), metavar="C",
                   help="station TOML whose [catalog] compare_window_days bounds how far apart the sessions may be "
                        "(the web's /compare uses the same; default 90 days)")


def run(args) -> int:
    from station.services.compare_job import CompareRequest, flagged, prepare_compare

    job = prepare_compare(CompareRequest([Path(p) for p in args.sessions], Path(args.out), args.serial,
                                         args.force, args.raw, args.config))
    outcome = job.run()
    for line in outcome.lines:
        print(line)
    return 1 if flagged(outcome) else 0
