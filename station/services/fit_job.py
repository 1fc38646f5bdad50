"""The fit job (issue 32 part 1, one shape for every job): `station fit` fills a `FitRequest`,
`prepare_fit` makes every refusal before anything is fitted or written, and `PreparedFit.run`
fits the model on the session's error basis (station.services.analysis), saves it with the
recording's identity, indexes it in the catalog and says what the front end should note."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from procedures.vocabulary import InputError
from procedures.fit.paper import DEFAULT_N_PARAMS  # the paper's number of cosine terms (help text, default)
from station.services.job import JobOutcome, OfflineJob, config_or_load

if TYPE_CHECKING:
    from procedures.fit.model import LegErrorModel
    from procedures.io.recording.reader import Session
    from station.services.config import StationConfig

__all__ = ["DEFAULT_N_PARAMS", "FitRequest", "FitResult", "PreparedFit", "prepare_fit"]


@dataclass
class FitRequest:
    """What a front end asks: fit `session` and write the model to `out` (replaced only with
    `force`). `method`: "default" or "paper"; `params`: cosine terms of the paper method (None:
    DEFAULT_N_PARAMS); `lead_mm`: a float, "auto" or None (no once-per-revolution terms); `legs`:
    the leg text ("1-3", "2,5"; None: all); `config`: the station TOML whose catalog indexes the
    file (None: the built-in config); `raw`: fit the raw error instead of the one at 20 degC."""

    session: Path
    out: Path
    force: bool = False
    method: str = "default"
    params: int | None = None
    lead_mm: float | str | None = "auto"
    legs: str | None = None
    config: Path | None = None
    raw: bool = False


@dataclass
class FitResult:
    """A fit for the front end to present. `model`: procedures.fit.LegErrorModel (per leg its
    `stats` and `describe()`); `notes`: what to say before the figures (the session's outcome,
    legs recorded with a compensation table active); `probes`: leg -> the line about its reversal
    probes (only the legs that had them)."""

    session_path: Path
    model: LegErrorModel
    path: Path
    method: str
    params: int
    basis_lines: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    probes: dict[int, str] = field(default_factory=dict)


@dataclass
class PreparedFit(OfflineJob):
    """A fit that passed every check (prepare_fit); `run` fits, writes and indexes the model."""

    request: FitRequest
    session: Session
    out: Path
    params: int
    legs: list[int] | None
    cfg: StationConfig

    def run(self, sinks=(), control=None) -> JobOutcome:
        from procedures.acquisition.probe_rule import recorded_stop
        from procedures.vocabulary import Outcome
        from procedures.fit.reversal_probes import ProbeReversal
        from procedures.io.recording.stage import active_tables
        from station.services.analysis import analyse_session, save_session_model

        r, session = self.request, self.session
        analysis = analyse_session(session, r.raw, fit_method=r.method,
                                   fit_options={"legs": self.legs, "n_params": self.params, "lead_mm": r.lead_mm})
        model = analysis.model
        if r.params is not None:  # the paper method keeps at most the terms the targets give: more is refused, not ignored
            for leg, f in model.legs.items():
                most = (int(getattr(f, "n_samples", 0)) + 1) // 2 - 1
                if r.params > most:
                    raise InputError(f"--params {r.params}: leg {leg} has {f.n_samples} targets per pass, which give "
                                     f"at most {most} cosine terms; give --params 1..{most}; nothing was written")
        save_session_model(model, self.out, session, self.cfg)
        notes = []
        if session.outcome != Outcome.COMPLETED:
            notes.append(f"note: the session's outcome is '{session.outcome}': the model uses the "
                         f"{session.points.size} points recorded")
        for leg, state in sorted(active_tables(session.devices).items()):  # the table state as a structure
            notes.append(f"warning: leg {leg} was recorded with a compensation table active ({state}): this model "
                         "describes the compensated leg, and a table made from it replaces the active one instead "
                         "of adding to it")
        probes = {}
        for leg, f in model.legs.items():
            p = getattr(f, "selection", {}).get("reversal_probes")
            if p:
                why = recorded_stop(session.plan, p["pairs"], p["stderr_um"])
                probes[leg] = ProbeReversal(**p).describe() + (f"; probes stopped: {why}" if why else "")
        result = FitResult(Path(session.path), model, self.out, r.method, self.params, list(analysis.basis_lines),
                           notes, probes)
        return JobOutcome("done", outputs=[self.out], lines=result.basis_lines + notes, data=result)


def prepare_fit(request: FitRequest, cfg: StationConfig | None = None) -> PreparedFit:
    """Every refusal of a fit before it runs (InputError): --params without the paper method, an
    output that exists (without force), an empty session, a bad leg list. `cfg`: the station
    config (None: load `request.config`)."""
    from procedures.acquisition.plans import parse_legs
    from procedures.io.outputs import check_output_file
    from procedures.io.recording.reader import read_session

    r = request
    if r.params is not None and r.method != "paper":  # never silently ignored
        raise InputError(f"--params {r.params}: the number of cosine terms applies to --method paper only "
                         "(the default method sizes itself by cross-validation); drop --params or add --method paper")
    out = check_output_file(r.out, force=r.force)  # before the fit (procedures/io/outputs.py)
    session = read_session(r.session)
    if session.points.size == 0:
        raise InputError(f"{session.path}: the session has no points; record a sweep first")
    legs = parse_legs(r.legs) if r.legs else None
    cfg = config_or_load(cfg, r.config)
    params = DEFAULT_N_PARAMS if r.params is None else r.params
    return PreparedFit(r, session, Path(out), params, legs, cfg, lines=[f"fit {session.path} ({r.method}) -> {out}"])
