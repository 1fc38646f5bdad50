"""A session's report and its CSV export, for both front ends: `station report` / `station
export` and the terminal UI's Results page call these, so they write the same files and say the
same about them. The export itself is procedures.io.csv_io.export_csv. Moved here from
station/commands/report.py and export_csv.py (the UI never imports a command module)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from procedures.reporting import evaluation
from procedures.io.csv_io import ExportSummary
from procedures.reporting.decision import NO_TOLERANCE, decision_lines
from procedures.vocabulary import InputError
from procedures.reporting.session_report import ReportResult, make_report
from station.catalog.writer import register
from station.services.job import JobOutcome


def session_report(session, out_dir: str | os.PathLike, model=None, *, lead_mm: float | str | None = "auto",
                   raw: bool = False, model_name: str = "", catalog=None) -> ReportResult:
    """`station report`: the report files of `session` (procedures.io.recording.reader.Session)
    into `out_dir`, before and after `model` (None: the default model fitted to the session), on
    the error basis of `station fit`: normalised to 20 degC unless `raw`; with a model, the
    model's own basis (a normalised model with `raw` is refused; `model_name` names it)."""
    if session.points.size == 0:
        raise InputError(f"{session.path}: the session has no points; record a sweep first")
    meta = {"plan": session.plan, "devices": session.devices, "station_config": session.station_config,
            "attrs": session.attrs,
            "identity": session.identity.to_json() if session.identity.recorded else {},
            # decided at the session's stage, as the catalog and the certificate decide it
            "stage": evaluation.decision_stage(session.stage)}
    result = make_report(session.points, out_dir, model, source_path=str(session.path),
                         source_sha256=session.sha256, lead_mm=lead_mm, session_meta=meta, raw=raw,
                         model_name=model_name)
    register(catalog, out_dir, "report")  # `catalog` (station.catalog.store.Catalog): None = not indexed
    return result


def report_lines(result: ReportResult, model=None) -> list[str]:
    """What `station report` prints about `result` (`model`: the one given, None when fitted)."""
    lines = [f"warning: {w}" for w in (result.iso230 or {}).get("warnings", [])]
    lines += list((result.summary.get("error_basis") or {}).get("lines") or [])
    if model is not None and not result.summary["model"]["fitted_to_this_session"]:
        lines.append(f"note: the model was fitted to {model.source.get('path') or 'another recording'}, "
                     "not to this session: the residual figures are a true test of it")
    for row in result.summary["legs"]:
        rr = row["residual_range_reduction_pct"]
        lines.append(f"leg {row['leg']}: range before {row['range_before_um']:.3f} um, residual range {row['residual_range_um']:.3f} um"
                     + (f" (residual range reduction {rr:.1f} %)" if rr is not None else "")
                     + f"; RMS before {row['rms_before_um']:.3f} um, residual RMS {row['residual_rms_um']:.3f} um")
    lines.append(f"residual = error minus model on this session's points: {result.summary['residuals']}; "
                 "figures: docs/figures.md")
    lines += iso_lines(result.iso230)
    decided = ((result.iso230 or {}).get("decisions") or {}).get("legs") or {}
    if any(d["overall"] != NO_TOLERANCE for d in decided.values()):
        lines += decision_lines(decided)
    lines += [f"wrote {path}" for path in result.files]
    return lines


def session_iso230(session, raw: bool = False) -> dict:
    """The ISO 230-2 values of `session` with the expanded uncertainty U (k = 2) of each, on the
    basis of `station fit` (normalised to 20 degC unless `raw`): the content of the report's
    iso230-2.json (procedures.reporting.iso230_report.build), for the commands that print ISO values."""
    return session_decisions(session, raw)


def iso_lines(iso: dict | None) -> list[str]:
    """One line per leg: the ISO 230-2 values with their expanded uncertainty (k = 2)."""
    if not iso:
        return []
    lines = [f"ISO 230-2 ({iso['error_basis']['basis']} error), U with k = 2 (docs/uncertainty.md):"]
    for leg, entry in iso["legs"].items():
        cells = []
        for name in ("E", "M", "A", "B", "R"):
            v = entry["values"][name]
            cells.append(f"{name} {v['value_um']:.3f} +/- {v['U_um']:.3f}" if v["value_um"] is not None
                         and v["U_um"] is not None else f"{name} n/a")
        lines.append(f"  leg {leg}: " + ", ".join(cells) + " um")
    return lines


def export_lines(summary: ExportSummary) -> list[str]:
    """What `station export` prints about what `export_csv` wrote."""
    lines = [f"exported {summary.rows} points to {summary.path} (columns: {', '.join(summary.columns)})"]
    if summary.skipped_no_error:
        lines.append(f"left out {summary.skipped_no_error} points without a measured error")
    return lines


def session_decisions(session, raw: bool = False, tolerances: dict | None = None, stage: str | None = None) -> dict:
    """The one evaluation of `session` (procedures.reporting.evaluation.evaluate_session: the ISO
    230-2 report's values with U, budget, per-target U and decisions): `tolerances` {type:
    Tolerance.to_json()}, None = the session's recorded ones (a --config's are the caller's to
    load); `stage` "as_found" / "as_left" (None: the session's own stage)."""
    return evaluation.evaluate_session(session, raw, tolerances, stage)


def decisions_if_stated(session, raw: bool = False, stage: str | None = None,
                        evaluated: dict | None = None) -> dict | None:
    """session_decisions' "decisions" when the session's recorded [tolerances] hold a type of one
    of its legs, else None without computing anything (the screens call this on every session).
    `evaluated`: the session's evaluation already made on the same basis (analyse_session's
    `evaluation`), reused when it was decided at `stage`, so a screen evaluates a session once."""
    from procedures.reporting.decision import tolerances_from_json  # noqa: PLC0415

    tol = tolerances_from_json((session.station_config or {}).get("tolerances"))
    if not any(session.identity.leg(leg).leg_type in tol for leg in session.legs):
        return None
    if evaluated is not None and evaluated["decisions"]["stage"] == (stage or evaluation.decision_stage(session.stage)):
        return evaluated["decisions"]
    return session_decisions(session, raw, stage=stage)["decisions"]



# -- the report and the ISO 230-2 jobs (issue 32 part 1, one shape for every job) --------------------

@dataclass
class ReportRequest:
    """`station report`: the report files of `session` into the folder `out` (replaced only with
    `force`), before and after the model in `model` (None: the default model fitted to the
    session), the screw lead `lead_mm` (a float, "auto" or None), on the raw error with `raw`;
    `config`: the station TOML whose catalog indexes the files (None: the built-in config)."""

    session: Path
    out: Path
    force: bool = False
    model: Path | None = None
    lead_mm: float | str | None = "auto"
    raw: bool = False
    config: Path | None = None


@dataclass
class PreparedReport:
    """A report that passed the output check; `run` reads, fits if asked and writes the files. The
    outcome's `lines` are what `station report` prints, its `data` the ReportResult."""

    request: ReportRequest
    needs_rig: bool = False
    question: str | None = None
    lines: list[str] = field(default_factory=list)
    # what a page has read already (prepare_session_report): the Session, the model on show, the config
    session: Any = None
    model: Any = None
    cfg: Any = None

    def run(self, sinks=(), control=None) -> JobOutcome:
        from procedures.fit import load_model
        from procedures.io.recording.reader import read_session
        from station.catalog.writer import catalog_for
        from station.services.config import load_config

        r = self.request
        session = self.session if self.session is not None else read_session(r.session)
        model = self.model if self.model is not None else (load_model(r.model) if r.model else None)
        cfg = self.cfg if self.cfg is not None else load_config(r.config)
        result = session_report(session, r.out, model, lead_mm=r.lead_mm, raw=r.raw, model_name=r.model or "",
                                catalog=catalog_for(cfg))
        return JobOutcome("done", outputs=[Path(f) for f in result.files], lines=report_lines(result, model),
                          data=result)


def prepare_report(request: ReportRequest) -> PreparedReport:
    """The output check before reading and fitting (procedures/io/outputs.py): an existing --out
    without `force` is refused (InputError, nothing written)."""
    from procedures.io.outputs import check_output_folder

    check_output_folder(request.out, force=request.force)
    return PreparedReport(request)


def prepare_session_report(session, model, out: Path, cfg) -> PreparedReport:
    """The report `station report SESSION --out OUT --model MODEL.json` writes, of the `session`
    (procedures.io.recording.reader.Session) already read with the `model` on show, indexed in
    the catalog of station config `cfg` (the UI's Results page, `r`; the page keeps an existing
    folder that holds a report, so nothing is refused here). The outcome's "note:" lines are what
    the page says beside the files."""
    return PreparedReport(ReportRequest(Path(session.path), Path(out)), session=session, model=model, cfg=cfg)
