"""`station iso230`: ISO 230-2 positioning accuracy of each leg in a session file."""

from __future__ import annotations

from station import values as V  # one parser per kind of value (issue 31)

import argparse
import json
from pathlib import Path

from procedures.io.atomic_outputs import write_text_atomic
from procedures.reporting.decision import decision_lines
from procedures.vocabulary import InputError
from procedures.io.outputs import check_output_file

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
    from procedures.io.recording.reader import read_session
    from procedures.reporting.iso230 import dumps, format_table
    from station.services.analysis import analyse_session
    from station.services.report_jobs import iso_lines, session_decisions

    if args.json:
        check_output_file(args.json, force=args.force, option="--json")
    session = read_session(Path(args.h5))
    if not len(session.points):
        raise InputError(f"{args.h5}: the session holds no points")
    analysis = analyse_session(session, args.raw, iso=True)
    if analysis.iso_error is not None:
        raise analysis.iso_error
    results, basis_lines, basis = analysis.iso, analysis.basis_lines, analysis.basis
    print(f"{args.h5} (sha256 {session.sha256[:16]}..., outcome {session.outcome})")
    for line in basis_lines:
        print(line)
    print(format_table(results), end="")
    tolerances = None
    if args.config:
        from station.services.config import load_config  # noqa: PLC0415 (only with --config)

        tolerances = {k: t.to_json() for k, t in load_config(args.config).tolerances.items()}
    # the report's values, each with its U (as station report), and their decisions
    iso = report = session_decisions(session, args.raw, tolerances)
    for line in iso_lines(iso):
        print(line)
    decisions = report["decisions"]
    print(f"Decisions ({decisions['rule']}):")
    for line in decision_lines(decisions["legs"]):
        print(f"  {line}")
    if args.json:
        out = Path(args.json)
        doc = json.loads(dumps(results, source={"path": str(args.h5), "sha256": session.sha256, "error_basis": basis}))
        doc["expanded_uncertainty_um"] = {  # U (k = 2) beside every value, as the ISO 230-2 report gives it
            leg: {name: v["U_um"] for name, v in entry["values"].items()} for leg, entry in iso["legs"].items()}
        for leg, entry in doc["legs"].items():
            entry["U_um"] = {name: v["U_um"] for name, v in report["legs"][leg]["values"].items()}
        doc["decisions"] = decisions
        write_text_atomic(out, json.dumps(doc, indent=2, allow_nan=False) + "\n")
        print(f"values written to {out}")
    return 0
