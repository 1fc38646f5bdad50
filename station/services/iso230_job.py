"""The ISO 230-2 job (issue 32 part 1, one shape for every job): `station iso230` fills an
`Iso230Request`; `prepare_iso230` makes every refusal before the evaluation (a --json output that
exists, an empty session) and `PreparedIso230.run` evaluates the session (station.services.analysis
for the ISO 230-2 table, the one evaluation of station.services.report_jobs for U and decisions)
and writes the JSON if asked."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from procedures.vocabulary import InputError
from station.services.job import JobOutcome


@dataclass
class Iso230Request:
    """`station iso230`: the ISO 230-2 values of each leg of `session` with their U and decisions,
    on the raw error with `raw`; `json_out`: also write them as JSON there (replaced only with
    `force`); `config`: the station TOML whose [tolerances.TYPE] decide (None: the tolerances the
    session recorded)."""

    session: Path
    json_out: Path | None = None
    force: bool = False
    raw: bool = False
    config: Path | None = None


@dataclass
class PreparedIso230:
    """An evaluation that passed every check (the session read and not empty); `run` evaluates
    and writes the JSON if asked. The outcome's `lines` are what `station iso230` prints."""

    request: Iso230Request
    session: Any  # procedures.io.recording.reader.Session
    needs_rig: bool = False
    question: str | None = None
    lines: list[str] = field(default_factory=list)

    def run(self, sinks=(), control=None) -> JobOutcome:
        from procedures.io.atomic_outputs import write_text_atomic
        from procedures.reporting.decision import decision_lines
        from procedures.reporting.iso230 import dumps, format_table
        from station.services.analysis import analyse_session
        from station.services.report_jobs import iso_lines, session_decisions

        r, session = self.request, self.session
        analysis = analyse_session(session, r.raw, iso=True)
        if analysis.iso_error is not None:
            raise analysis.iso_error
        results, basis = analysis.iso, analysis.basis
        lines = [f"{r.session} (sha256 {session.sha256[:16]}..., outcome {session.outcome})"]
        lines += list(analysis.basis_lines)
        lines += format_table(results).splitlines()
        tolerances = None
        if r.config:
            from station.services.config import load_config  # noqa: PLC0415 (only with --config)

            tolerances = {k: t.to_json() for k, t in load_config(r.config).tolerances.items()}
        # the report's values, each with its U (as station report), and their decisions
        iso = session_decisions(session, r.raw, tolerances)
        lines += iso_lines(iso)
        decisions = iso["decisions"]
        lines.append(f"Decisions ({decisions['rule']}):")
        lines += [f"  {line}" for line in decision_lines(decisions["legs"])]
        outputs = []
        if r.json_out:
            out = Path(r.json_out)
            doc = json.loads(dumps(results, source={"path": str(r.session), "sha256": session.sha256,
                                                    "error_basis": basis}))
            doc["expanded_uncertainty_um"] = {  # U (k = 2) beside every value, as the ISO 230-2 report gives it
                leg: {name: v["U_um"] for name, v in entry["values"].items()} for leg, entry in iso["legs"].items()}
            for leg, entry in doc["legs"].items():
                entry["U_um"] = {name: v["U_um"] for name, v in iso["legs"][leg]["values"].items()}
            doc["decisions"] = decisions
            write_text_atomic(out, json.dumps(doc, indent=2, allow_nan=False) + "\n")
            lines.append(f"values written to {out}")
            outputs.append(out)
        return JobOutcome("done", outputs=outputs, lines=lines, data=iso)


def prepare_iso230(request: Iso230Request) -> PreparedIso230:
    """Every refusal before the evaluation (InputError): a --json output that exists without
    `force` (checked before reading), a session without points."""
    from procedures.io.outputs import check_output_file
    from procedures.io.recording.reader import read_session

    if request.json_out:
        check_output_file(request.json_out, force=request.force, option="--json")
    session = read_session(Path(request.session))
    if not len(session.points):
        raise InputError(f"{request.session}: the session holds no points")
    return PreparedIso230(request, session)
