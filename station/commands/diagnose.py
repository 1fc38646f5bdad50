"""`station diagnose`: where the gap between the twin and a recording lies, which unmodelled
effect causes it, and how far it shrinks once that effect is added; and `--self-check`, the same
diagnosis run on simulated sessions with known effects withheld from the twin.

The command reads files and prints; its twins come from station/services/twins.py (which the
terminal UI uses too; the simulated plant's own systematic error for `--twin sim:...` is made a
twin there, so procedures never import the simulator), the self-check's sessions from
station/services/selfcheck.py.
"""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from procedures.vocabulary import InputError
from procedures.io.outputs import check_output_file
from station.services.diagnosis_jobs import PHYSICS as VARIANT_PHYSICS, SELF_CHECK_CONTRIBUTION_UM

if TYPE_CHECKING:
    from procedures.diagnosis import DiagnosisSettings

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


def _settings(args) -> DiagnosisSettings:
    from procedures.diagnosis import DiagnosisSettings

    effects = None
    if args.effects:
        effects = tuple(e.strip() for e in args.effects.split(",") if e.strip())
    kw = {"threshold_um": args.threshold_um, "alpha": args.alpha, "lead_mm": args.lead_mm, "holdout": args.holdout,
          "motor_turn_mm": args.motor_turn_mm}
    if effects:
        kw["effects"] = effects
    return DiagnosisSettings(**kw)


def run(args) -> int:
    from procedures.diagnosis import to_json
    from procedures.diagnosis.text_report import text_report
    from station.services.twins import load_twin

    settings = _settings(args)
    if args.json:  # before the (long) diagnosis or self-check
        check_output_file(args.json, force=args.force, option="--json")
    if args.self_check:
        if args.file:
            raise InputError("--self-check makes its own sessions; drop FILE.h5")
        from station.services.sizing import selfcheck_estimate

        per = len(args.variants.split(",")) if args.variants else 1
        print(f"self-check: {selfcheck_estimate(args.seeds * per).describe()}", file=sys.stderr, flush=True)
        return _self_check(args, settings)
    if not args.file:
        raise InputError("name a session file (FILE.h5), or use --self-check")
    path = Path(args.file)
    if path.suffix.lower() == ".csv":
        raise InputError(f"{path}: a CSV must be imported first: `station import {path} --out FILE.h5`, "
                         "then `station diagnose FILE.h5`")
    from procedures.io.recording.reader import read_session

    session = read_session(path)
    twin = load_twin(args.twin, session=session, path=path, catalog=lambda: _catalog_engine(args)) if args.twin else None
    from station.services.diagnosis_jobs import diagnose_session

    report, temp_lines = diagnose_session(session, path, twin, settings)  # the same as the UI's Diagnosis page
    print(text_report(report))
    print("\n" + "\n".join(temp_lines))
    if args.json:
        Path(args.json).write_text(to_json(report))
        print(f"\nreport written to {args.json}")
    return 0


def _catalog_engine(args):
    from station.catalog.store import catalog_of, reading_engine
    from station.services.config import load_config

    engine, where = reading_engine(catalog_of(load_config(args.config)), args.local)
    print(where)
    return engine


# -- self-check -----------------------------------------------------------------------------------
def _self_check(args, settings: DiagnosisSettings) -> int:
    from procedures.diagnosis.selfcheck import format_self_check, run_self_check
    from station.services.diagnosis_jobs import selfcheck_trial

    seeds = range(args.first_seed, args.first_seed + args.seeds)
    if args.variants:
        return _variant_check(args, settings, seeds)

    def progress(r):
        mark = "ok " if r["ok"] else "BAD"
        print(f"  {mark} seed {r['seed']:>4} ({r['twin']} twin): {r['label']}", file=sys.stderr, flush=True)

    lo, hi = args.magnitude_um
    if not 0 < lo <= hi:
        raise InputError(f"--magnitude-um {lo:g} {hi:g}: need 0 < MIN <= MAX (um)")
    result = run_self_check((selfcheck_trial(s, contribution_um=(lo, hi)) for s in seeds), settings, progress)
    print(format_self_check(result))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1, allow_nan=False, default=float))
    return 0 if result["summary"]["trials_ok"] == result["summary"]["trials"] else 1


def _variant_check(args, settings: DiagnosisSettings, seeds) -> int:
    """The variants' self-check: --seeds sessions per physics (station/services/selfcheck_variants.py),
    parameters within 15 %, gap within 25 % of the oracle's."""
    from procedures.diagnosis.selfcheck import (VARIANT_GAP_TOLERANCE, VARIANT_PARAM_TOLERANCE, format_by_physics,
                                                format_self_check, run_self_check, summarise_by_physics)
    from station.services.diagnosis_jobs import variant_trial

    physics = [p.strip() for p in args.variants.split(",") if p.strip()]
    unknown = sorted(set(physics) - set(VARIANT_PHYSICS))
    if unknown:
        raise InputError(f"--variants {args.variants}: unknown physics {', '.join(unknown)}; known: "
                         f"{', '.join(VARIANT_PHYSICS)}")

    def progress(r):
        if not r["ok"]:
            print(f"  BAD seed {r['seed']:>4} ({r['twin']} twin): {r['label']}", file=sys.stderr, flush=True)

    result = run_self_check((variant_trial(s, p) for p in physics for s in seeds), settings, progress,
                            VARIANT_PARAM_TOLERANCE, VARIANT_GAP_TOLERANCE)
    result["by_physics"] = summarise_by_physics(result["trials"])
    print(f"variant self-check: {len(seeds)} sessions per physics, {result['summary']['trials_ok']} of "
          f"{result['summary']['trials']} fully right")
    print(format_by_physics(result["by_physics"], VARIANT_PARAM_TOLERANCE, VARIANT_GAP_TOLERANCE))
    bad = [line for line in format_self_check(result).splitlines() if line.startswith("  seed")]
    print("\n".join(bad))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1, allow_nan=False, default=float))
    return 0 if result["summary"]["trials_ok"] == result["summary"]["trials"] else 1
