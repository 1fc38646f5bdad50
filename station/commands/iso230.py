"""`station iso230`: ISO 230-2 positioning accuracy of each leg in a session file."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from procedures.errors import InputError
from procedures.iso230 import dumps, format_table
from procedures.recording.reader import read_session
from station.services.analysis import analyse_session

NAME = "iso230"
HELP = "ISO 230-2 values (E, M, A, B, R; up, down, both) of each leg in a session file"
DESCRIPTION = (
    "Evaluate a session file by ISO 230-2: per leg the systematic deviation E, accuracy A, repeatability R "
    "(per direction and bidirectional), range of mean bidirectional deviation M and reversal B, in micrometres. "
    "Values that cannot be computed are shown as '-' with the reason."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("h5", metavar="FILE.h5", help="session file (import a CSV first with `station import`)")
    p.add_argument("--json", metavar="OUT", help="also write the values as JSON to OUT")
    p.add_argument("--raw", action="store_true",
                   help="evaluate the raw error (default: normalised to 20 degC material temperature, docs/metrology.md)")


def run(args) -> int:
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
    if args.json:
        out = Path(args.json)
        text = dumps(results, source={"path": str(args.h5), "sha256": session.sha256, "error_basis": basis})
        tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
        try:
            tmp.write_text(text + "\n")
            os.replace(tmp, out)
        finally:
            tmp.unlink(missing_ok=True)
        print(f"values written to {out}")
    return 0
