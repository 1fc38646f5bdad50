"""`station diagnose`: where the gap between the twin and a recording lies, which unmodelled
effect causes it, and how far it shrinks once that effect is added; and `--self-check`, the same
diagnosis run on simulated sessions with known effects withheld from the twin.

The command fills a request and prints; the jobs are station/services/diagnosis_jobs.py (which the
terminal UI uses too), their twins station/services/twins.py, the self-check's sessions
procedures/synthetic.py (made from the plant, drivers/plant).
"""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import sys
from pathlib import Path

from station.services.diagnosis_jobs import PHYSICS as VARIANT_PHYSICS, SELF_CHECK_CONTRIBUTION_UM

NAME = "diagnose"
HELP = "diagnose the gap between the twin and a recording (where, which effect, how far)"
DESCRIPTION = (
    "Measure the gap between a recording and the digital twin, break it down (direction, stroke "
    "region, pass/time, spectrum, temperature, load), name the unmodelled effects that explain it "
    "(backlash, thermal, load, drift, scale, cyclic, speed; backlash and thermal also as variants that change with "
    "temperature or position) with parameters and uncertainties, say what no candidate explains, and say how far "
    "the held-out gap shrinks with them. Without --twin the twin is a position-only error model fitted "
    "on the same recording. --self-check runs the diagnosis on simulated sessions with known effects "
    "withheld from the twin and prints how often it names them rightly."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", type=V.SESSION.argtype(), nargs="?", metavar="FILE.h5", help="session recording (station sweep / station import)")
    p.add_argument("--twin", type=V.TWIN.argtype(), metavar="TWIN",
                   help="MODEL.json (station fit), REFERENCE.h5 (a twin fitted on another recording), or "
                        "sim:CONFIG.toml / sim:default (the simulated plant's systematic error), or fleet:TYPE (the "
                        "legs of that type in the catalog: their mean error map, and how many sigma this leg lies "
                        "from them)")
    p.add_argument("--config", type=V.CONFIG.argtype(), metavar="C", help="station TOML whose catalog --twin fleet:TYPE reads (docs/catalog.md)")
    p.add_argument("--local", action="store_true", help="--twin fleet:TYPE: read the local catalog, not the shared one")
    p.add_argument("--json", type=V.OUT_FILE.argtype(), metavar="OUT", help="write the report (or the self-check results) as JSON")
    p.add_argument("--force", action="store_true", help="replace the output if it exists (default: refused)")
    p.add_argument("--threshold-um", type=V.THRESHOLD_UM.argtype(), default=0.1,
                   help="name an effect only if it explains more than this on held-out passes, um (default 0.1)")
    p.add_argument("--alpha", type=V.ALPHA.argtype(), default=1e-3, help="significance level against pass scatter (default 0.001)")
    p.add_argument("--lead-mm", type=V.LEAD_MM.argtype(), default=5.0, help="screw lead marked in the spectrum, mm (default 5)")
    p.add_argument("--motor-turn-mm", type=V.MOTOR_TURN_MM.argtype(), default=None,
                   help="travel per motor turn, mm (lead / gear ratio): a periodic finding that may be its alias at "
                        "the plan's step is flagged, as the lead and its harmonics always are")
    p.add_argument("--effects", type=V.WORD_LIST.argtype(), help="candidate effects to try, comma separated (default all)")
    p.add_argument("--holdout", choices=["cycle", "pass"], default="cycle",
                   help="unit held out in cross-validation (default cycle: an upward and a downward pass)")
    p.add_argument("--self-check", action="store_true", help="check the diagnosis on simulated withheld effects")
    p.add_argument("--seeds", type=V.SEEDS.argtype(), default=20,
                   help="self-check: number of sessions (default 20; with --variants: per physics)")
    p.add_argument("--variants", type=V.WORD_LIST.argtype(), nargs="?", const=",".join(VARIANT_PHYSICS), metavar="PHYSICS",
                   help="self-check the effect variants instead: sessions with physics outside the plain library "
                        f"(comma separated, default all: {', '.join(VARIANT_PHYSICS)})")
    p.add_argument("--first-seed", type=V.SEED.argtype(), default=0, help="self-check: first seed (default 0)")
    p.add_argument("--magnitude-um", type=V.CONTRIBUTION_UM.argtype(), nargs=2, metavar=("MIN", "MAX"),
                   default=SELF_CHECK_CONTRIBUTION_UM,
                   help="self-check: RMS contribution of a withheld effect, drawn log-uniform in "
                        f"[MIN, MAX] um (default {SELF_CHECK_CONTRIBUTION_UM[0]:g} {SELF_CHECK_CONTRIBUTION_UM[1]:g})")


def _settings(args) -> dict:
    return {"threshold_um": args.threshold_um, "alpha": args.alpha, "lead_mm": args.lead_mm,
            "motor_turn_mm": args.motor_turn_mm, "effects": args.effects, "holdout": args.holdout}


def run(args) -> int:
    from station.services import diagnosis_jobs as jobs

    if args.self_check:
        check = jobs.prepare_self_check(
            jobs.SelfCheckRequest(session=args.file, seeds=args.seeds, first_seed=args.first_seed, variants=args.variants,
                                  magnitude_um=tuple(args.magnitude_um), json_out=args.json, force=args.force,
                                  **_settings(args)),
            progress=lambda line: print(line, file=sys.stderr, flush=True))
        for line in check.lines:
            print(line, file=sys.stderr, flush=True)
        outcome = check.run()
        for line in outcome.lines:
            print(line)
        return 0 if outcome.ok else 1
    job = jobs.prepare_diagnosis(jobs.DiagnoseRequest(Path(args.file) if args.file else None, twin=args.twin,
                                                      json_out=args.json, force=args.force, local=args.local,
                                                      **_settings(args)),
                                 say=print, config=args.config)
    for line in job.run().lines:
        print(line)
    return 0
