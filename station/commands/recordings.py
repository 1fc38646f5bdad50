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

from procedures.io.atomic import atomic_paths
from procedures.vocabulary import InputError
from station.services.samples import FILES, SAMPLES

NAME = "recordings"
HELP = "regenerate the sample sessions of recordings/ on the simulated rig (deterministic)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", type=V.OUT_DIR.argtype(), default="recordings", metavar="DIR", help="directory to write (default recordings)")
    p.add_argument("--only", type=V.WORD_LIST.argtype(), metavar="NAMES", help=f"comma-separated subset of {', '.join(SAMPLES)} "
                   "(verification needs calibration in the same run)")


def run(args) -> int:
    wanted = SAMPLES if not args.only else tuple(x.strip() for x in args.only.split(",") if x.strip())
    unknown = [w for w in wanted if w not in SAMPLES]
    if unknown:
        raise InputError(f"--only: unknown sample(s) {unknown}; choose from {', '.join(SAMPLES)}")
    if "verification" in wanted and "calibration" not in wanted:
        raise InputError("--only verification needs calibration too (the tables are fitted to it on the same rig)")
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    final = {name: out_dir / FILES[name] for name in wanted}
    # made under temporary names and renamed at the end: a failed run leaves the old samples
    with atomic_paths(final.values(), suffix=".h5", exists=False) as temps:  # the sweep creates them
        _make(wanted, {name: temps[path] for name, path in final.items()})
    for path in final.values():
        print(f"  {path}: {path.stat().st_size / 1e6:.2f} MB")
    return 0


def _make(wanted, targets: dict[str, Path]) -> None:
    from station.services.samples import make_calibration, make_fault, make_verification, open_sample_rig, sample_config

    cfg = sample_config()
    if "calibration" in wanted:
        with open_sample_rig() as rig:
            res = make_calibration(rig, targets["calibration"], cfg)
            print(f"{FILES['calibration']}: {res.outcome}, {res.points} points")
            if "verification" in wanted:
                for line in make_verification(rig, targets["calibration"], targets["verification"], cfg):
                    print(f"  {line}")
                print(f"{FILES['verification']}: written")
    if "fault" in wanted:
        with open_sample_rig() as rig:
            res = make_fault(rig, targets["fault"], cfg)
            print(f"{FILES['fault']}: {res.outcome}, {res.points} points ({res.reason})")
