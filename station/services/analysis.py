"""The analysis of a recorded session, composed once for every front end: the error on the
chosen basis (procedures.metrology.thermal.error_basis: normalised to 20 degC unless raw), then
the fitted leg-error model tagged with that basis, and the ISO 230-2 values with their expanded
uncertainty U (k = 2) from the one evaluation of a session (procedures.reporting.evaluation).
`station fit`, `station iso230` and the terminal UI's Results page call it."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from procedures.metrology.thermal import error_basis
from procedures.reporting import evaluation

if TYPE_CHECKING:
    import numpy as np

    from procedures.fit.model import LegErrorModel
    from procedures.io.recording.reader import Session
    from procedures.reporting.iso230 import LegIso230
    from procedures.reporting.session_report import ReportResult
    from station.services.config import StationConfig


@dataclass
class SessionAnalysis:
    """What `analyse_session` found. `iso_error` / `uncertainty_error`: why the ISO 230-2 values
    or their U could not be had (the rest stands without them)."""

    session: Session
    points: np.ndarray  # session.points with error_um on the chosen basis
    basis_lines: tuple[str, ...]  # what error_basis says, as the commands print it
    basis: dict  # the same as JSON (a model carries it as options["error_basis"])
    raw: bool = False
    model: LegErrorModel | None = None  # when a fit was asked for
    iso: dict[int, LegIso230] | None = None  # procedures.reporting.iso230.evaluate's result, when asked for
    iso_u: dict[int, dict[str, float | None]] | None = None  # leg -> value name -> U (k = 2), um
    evaluation: dict | None = None  # procedures.reporting.evaluation.evaluate_session's, with `uncertainty`
    iso_error: Exception | None = None
    uncertainty_error: Exception | None = None
    fit_options: dict = field(default_factory=dict)


def analyse_session(session: Session, raw: bool = False, *, fit_method: str | None = None, fit_options: dict | None = None,
                    iso: bool = False, uncertainty: bool = False) -> SessionAnalysis:
    """Analyse `session` (procedures.io.recording.reader.Session) on the raw error (`raw`) or the
    error normalised to 20 degC. With `fit_method` ("default", "paper"), fit a model (keyword
    arguments of procedures.fit.fit in `fit_options`) naming the recording and tagged with the
    error basis (`station table` says which error its table holds); fitting errors are raised.
    With `iso`, evaluate ISO 230-2, and with `uncertainty` also its U per value; their errors
    are kept in the result (`iso_error`, `uncertainty_error`)."""
    points, basis_lines, basis = error_basis(session, raw)
    out = SessionAnalysis(session, points, tuple(basis_lines), basis, raw, fit_options=dict(fit_options or {}))
    if fit_method is not None:
        from procedures.fit import fit

        out.model = fit(points, fit_method, source={"path": str(session.path), "sha256": session.sha256},
                        **out.fit_options)
        out.model.options["error_basis"] = basis
    if iso:
        from procedures.reporting import iso230

        try:
            out.iso = iso230.evaluate(points)
        except Exception as exc:
            out.iso_error = exc
        if out.iso and uncertainty:
            try:
                out.evaluation = evaluation.evaluate_session(session, raw)
                out.iso_u = iso_uncertainty(out.evaluation)
            except Exception as exc:  # the values stand without their U
                out.uncertainty_error = exc
    return out


def iso_uncertainty(ev: dict) -> dict[int, dict[str, float | None]]:
    """U (k = 2, um) of every ISO 230-2 value per leg from the one evaluation of the session
    (procedures.reporting.evaluation: what the report and the certificate state)."""
    return {int(leg): {name: v["U_um"] for name, v in evaluation.leg_values(ev, leg).items()} for leg in ev["legs"]}


def save_session_model(model: LegErrorModel, out: str | Path, session: Session, cfg: StationConfig) -> Path:
    """Write `model` (fitted to `session`) as JSON with the session's identity, and index it in
    the catalog of station config `cfg` (a catalog that cannot be written never fails the save:
    `station catalog sync` indexes the file later). Both front ends save models through this."""
    from procedures.fit import save_model
    from procedures.io.recording.identity import model_identity
    from station.catalog.writer import catalog_for, register

    path = save_model(model, out, str(session.path), session.sha256, identity=model_identity(session.identity, model.legs))
    register(catalog_for(cfg), path, "model")
    return Path(path)


@dataclass
class FileAnalysis:
    """What the terminal UI's Results page shows of a recording file: `analysis` (the fit and ISO
    230-2 values with U, as `station fit` and `station iso230` give them), the ISO 14253-1
    `decisions` against the session's recorded [tolerances] (None when it states none for its
    legs' types) and their one-line `decision_summary`, and `decisions_error` (why they could not
    be had; the rest stands without them)."""

    analysis: SessionAnalysis
    decisions: dict | None = None
    decision_summary: str = ""
    decisions_error: Exception | None = None


def analyse_file(path: str | Path, method: str, raw: bool = False) -> FileAnalysis:
    """Read the recording `path` and analyse it on the chosen error basis with a `method` fit,
    ISO 230-2 with U, and the tolerance decisions; reading and fitting errors are raised."""
    from procedures.io.recording.reader import read_session

    a = analyse_session(read_session(path), raw, fit_method=method, iso=True, uncertainty=True)
    out = FileAnalysis(a)
    try:  # ISO 14253-1 against the recorded [tolerances] of the legs' types (docs/decisions.md)
        from procedures.reporting.decision import decision_summary
        from station.services.report_jobs import decisions_if_stated

        out.decisions = decisions_if_stated(a.session, raw, evaluated=a.evaluation)  # evaluated once
        if out.decisions:
            out.decision_summary = decision_summary(out.decisions["legs"])
    except Exception as exc:
        out.decisions_error = exc
    return out


def normalised_basis_text(basis: dict) -> str:
    """The error basis of a normalised analysis in one line (`basis`: error_basis' JSON): the
    reference temperature and legs, the material temperature and correction ranges over them,
    and the legs left raw with why."""
    from procedures.io.ranges import legs_text

    ref = basis.get("reference_temp_c", 20.0)
    legs = [str(k) for k in basis.get("normalised_legs", [])]
    temps = [v for k, v in basis.get("material_temp_range_c", {}).items() if k in legs]
    corr = [v for k, v in basis.get("correction_range_um", {}).items() if k in legs]
    text = f"error: normalised to {ref:g} degC material temperature, legs {legs_text(int(k) for k in legs)}"
    if temps and corr:
        text += (f": material {min(t[0] for t in temps):.2f}..{max(t[1] for t in temps):.2f} °C, "
                 f"correction {min(c[0] for c in corr):+.3f}..{max(c[1] for c in corr):+.3f} µm")
    raw_legs = basis.get("raw_legs") or {}
    if raw_legs:
        text += "; raw on " + "; ".join(f"leg {k} ({v})" for k, v in sorted(raw_legs.items()))
    return text
