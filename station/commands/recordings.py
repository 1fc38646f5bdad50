"""`station recordings`: make the sample sessions of recordings/ on the simulated rig.

Deterministic: the simulated rig runs on its virtual clock with fixed seeds, so the points of a
regenerated file are the same as those of the committed one (only session ids and UTC times
differ). `make recordings` runs `station recordings --out recordings`, which replaces the files (they
are made under temporary names first, so a failed run leaves the old ones); recordings/README.md
lists them. What each sample is and how it is made: station/services/samples.py.
"""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
from pathlib import Path

from station.services.samples import SAMPLES

NAME = "recordings"
HELP = "regenerate the sample sessions of recordings/ on the simulated rig (deterministic)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", type=V.OUT_DIR.argtype(), default="recordings", metavar="DIR", help="directory to write (default recordings)")
    p.add_argument("--only", type=V.WORD_LIST.argtype(), metavar="NAMES", help=f"comma-separated subset of {', '.join(SAMPLES)} "
                   "(verification needs calibration in the same run)")


def run(args) -> int:
    from station.services.samples_job import SamplesRequest, prepare_samples

    only = tuple(x.strip() for x in args.only.split(",") if x.strip()) if args.only else None
    job = prepare_samples(SamplesRequest(Path(args.out), only), say=print)
    for line in job.run().lines:
        print(line)
    return 0
