"""The diagnosis of a recorded session as both front ends give it (`station diagnose` and the
terminal UI's Diagnosis page): procedures.diagnosis.diagnose on the raw error, with the material
temperature range that the normalisation to 20 degC of fit, iso230 and verify has to cover
(procedures.metrology.thermal.diagnosis_temperature_note) added as `material_temperature`.

One function, so the two front ends' JSON reports are the same report, not two copies of it."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from procedures.vocabulary import InputError
from station.services.job import JobOutcome, OfflineJob, config_or_load

if TYPE_CHECKING:  # annotations only: a request and its refusal load nothing of the diagnosis
    import numpy as np

    from procedures.diagnosis import DiagnosisSettings
    from procedures.diagnosis.twin import ExternalTwin
    from procedures.fit.model import LegErrorModel
    from procedures.io.recording.reader import Session
    from station.services.config import StationConfig

# The self-check's sessions (`station diagnose --self-check`) are made from the plant alone, with the
# other synthetic sessions (procedures/synthetic.py); the front ends take them from here.
from procedures.synthetic import PHYSICS, SELF_CHECK_CONTRIBUTION_UM, selfcheck_trial, variant_trial  # noqa: F401


def diagnose_session(session: Session, path: str | Path, twin: ExternalTwin | None = None,
                     settings: DiagnosisSettings | None = None) -> tuple[dict, list[str]]:
    """The diagnosis report of `session` (as procedures.io.recording.reader reads it, from `path`)
    against `twin` (None: the twin fitted on the recording), and the lines saying which error it
    used and the material temperature range per leg. The diagnosis works on the raw error_um on
    purpose: thermal expansion stays an effect it can find (docs/metrology.md)."""
    from procedures.diagnosis import DiagnosisSettings, diagnose
    from procedures.diagnosis.diagnose import finite_or_null
    from procedures.metrology.thermal import diagnosis_temperature_note

    settings = settings if settings is not None else DiagnosisSettings()
    points, twin, normalised_legs = on_common_basis(session, twin)
    comparison = getattr(twin, "comparison", None)
    compared = {}
    if comparison is not None:  # the fleet twin: how far this leg's features lie from its siblings' (made first:
        from procedures.diagnosis.fleet import error_map  # the diagnosis names a scale only where they support it)

        import numpy as np

        compared = {int(leg): comparison(int(leg), error_map(points, int(leg)), settings.lead_mm)
                    for leg in np.unique(points["leg"])}
    report = diagnose(points, twin, settings, recording={"path": str(path), "sha256": session.sha256}, source=str(path))
    if normalised_legs:
        report["twin"]["normalised_legs"] = normalised_legs
        thermal_beyond_material(report, session, normalised_legs)
    temp_lines, report["material_temperature"] = diagnosis_temperature_note(session.points, session.station_config)
    if normalised_legs:
        temp_lines[0] = temp_lines[0].replace(
            "raw (diagnosis does not normalise: thermal expansion stays a diagnosable effect)",
            f"leg(s) {', '.join(map(str, normalised_legs))} normalised to 20 degC (NDE) like the twin, as both carry "
            "the material temperature (a thermal finding there is expansion beyond the material's nominal), others raw")
    if comparison is not None:
        report["twin"]["fleet"] = twin.info  # type, basis, siblings per leg, files left out, duplicates
        for leg, rep in report["legs"].items():
            rep["fleet"] = finite_or_null(compared[int(leg)], report["notes"], f"legs.{leg}.fleet")
    return report, temp_lines


MATERIAL_LIKE = (0.5, 2.0)  # a leg expanding within these factors of its assumed material expands like it


def thermal_beyond_material(report: dict, session: Session, legs: list[int]) -> None:
    """On legs compared normalised to 20 degC, a thermal finding is the expansion beyond the
    assumed material's (issue 35): say so in words and figures (`material` on the finding: the
    assumed and the measured total expansion, ppm/K). Sign: measured = assumed + found."""
    from procedures.metrology.thermal import normalise_session

    materials = normalise_session(session.points, session.station_config).materials
    for f in report["findings"]:
        if f["effect"] != "thermal" or f["leg"] not in legs or f["leg"] not in materials:
            continue
        assumed = float(materials[f["leg"]].expansion_um_m_k)
        beyond = f["parameters"]["expansion_ppm_per_k"]
        total = assumed + beyond
        what = "steel" if abs(assumed - 11.5) < 1e-9 else "material"
        note = (f"compared normalised to 20 degC, so this is the expansion beyond the assumed {what}: assumed "
                f"{assumed:.3g}, measured {total:.3g} ppm/K ({beyond:+.3g} ppm/K beyond it)")
        lo, hi = MATERIAL_LIKE
        if not lo * assumed <= total <= hi * assumed:
            note += (f": does not expand like the assumed {what}: check the material setting or where the sensor sits "
                     "(a sensor away from the screw, or on a part that does not warm with it)")
        else:
            note += f": expands like {what}, {'more' if beyond > 0 else 'less'} than assumed"
        f["material"] = {"assumed_ppm_per_k": assumed, "measured_ppm_per_k": total, "beyond_assumed_ppm_per_k": beyond,
                         "note": note}


def on_common_basis(session: Session, twin: ExternalTwin | None) -> tuple[np.ndarray, ExternalTwin | None, list[int]]:
    """(points, twin, legs compared normalised): the session's error normalised to 20 degC on the
    legs where both it and the twin carry the material temperature (a reference recorded at
    another temperature then shows no scale from the temperature alone), raw elsewhere."""
    import numpy as np

    from procedures.diagnosis.twin import ExternalTwin
    from procedures.metrology.thermal import normalise_session

    if getattr(twin, "kind", None) == "fleet":  # built on one basis for the whole session (station/services/twins.py)
        if not twin.normalised:
            return session.points, twin, []
        n = normalise_session(session.points, session.station_config)
        return n.points, twin, list(n.normalised)
    alt = getattr(twin, "normalised_twin", None)
    if alt is None:
        return session.points, twin, []
    n = normalise_session(session.points, session.station_config)
    legs = [leg for leg in n.normalised if alt.legs is None or leg in alt.legs]
    if not legs:
        return session.points, twin, []
    points = session.points.copy()
    rows = np.isin(points["leg"], legs)
    points["error_um"][rows] = n.points["error_um"][rows]
    info = {k: ({**v, "basis": "normalised"} if isinstance(v, dict) and k.isdigit() and int(k) in legs else v)
            for k, v in twin.info.items()}
    combined = ExternalTwin(
        predict=lambda leg, x, d: (alt if leg in legs else twin).predict(leg, x, d), kind=twin.kind,
        description=f"{twin.description}; legs {', '.join(map(str, legs))} normalised to 20 degC on both sides",
        legs=twin.legs, info=info)
    return points, combined, legs


# -- the diagnosis job (issue 32 part 1, one shape for every job) ---------------------------------

@dataclass(kw_only=True)
class DiagnosisOptions:
    """What a diagnosis and its self-check are both asked (keywords of either request): `json_out`,
    where to write the report (replaced only with `force`), and the settings: `threshold_um`,
    `alpha`, `lead_mm`, `motor_turn_mm`, `effects` (comma separated; None: all), `holdout`
    ("cycle" or "pass"); None = the default."""

    json_out: Path | None = None
    force: bool = False
    threshold_um: float | None = None
    alpha: float | None = None
    lead_mm: float | None = None
    motor_turn_mm: float | None = None
    effects: str | None = None
    holdout: str | None = None

    def checked_settings(self) -> DiagnosisSettings:
        """The settings (InputError naming a bad one) and the output (refused when it exists
        without `force`), both checked before the (long) run."""
        from procedures.diagnosis import DiagnosisSettings
        from procedures.io.outputs import check_output_file

        kw = {k: getattr(self, k) for k in ("threshold_um", "alpha", "lead_mm", "holdout", "motor_turn_mm")
              if getattr(self, k) is not None or k == "motor_turn_mm"}
        effects = tuple(e.strip() for e in self.effects.split(",") if e.strip()) if self.effects else ()
        if effects:
            kw["effects"] = effects
        settings = DiagnosisSettings(**kw)
        if self.json_out:
            check_output_file(self.json_out, force=self.force, option="--json")
        return settings


@dataclass
class DiagnoseRequest(DiagnosisOptions):
    """Diagnose the recording `session` against a twin: `twin` as `station diagnose --twin` spells
    it (MODEL.json, REFERENCE.h5, sim:..., fleet:TYPE; None: the twin fitted on the recording), or
    `twin_model` (a fitted model and the file it names, as the UI's Results page holds it).
    `local`: fleet:TYPE reads the local catalog. The output and settings: DiagnosisOptions."""

    session: Path | None
    twin: str | None = None
    twin_model: tuple[LegErrorModel, str] | None = None
    local: bool = False


@dataclass
class Diagnosis:
    """A diagnosis for the front end to present: the JSON `report`, its `text` (as `station
    diagnose` prints it) and the lines on the error used and the material temperature."""

    path: Path
    report: dict
    text: str
    temp_lines: list[str]


@dataclass
class PreparedDiagnosis(OfflineJob):
    request: DiagnoseRequest
    session: Session
    twin: ExternalTwin | None  # None: the twin fitted on the recording
    settings: DiagnosisSettings

    def run(self, sinks=(), control=None) -> JobOutcome:
        from procedures.diagnosis import to_json
        from procedures.diagnosis.diagnosis_text import text_report

        r = self.request
        report, temp_lines = diagnose_session(self.session, r.session, self.twin, self.settings)
        text = text_report(report)
        lines = [text, "\n" + "\n".join(temp_lines)]
        outputs = []
        if r.json_out:
            Path(r.json_out).write_text(to_json(report))
            lines.append(f"\nreport written to {r.json_out}")
            outputs.append(Path(r.json_out))
        return JobOutcome("done", outputs=outputs, lines=lines,
                          data=Diagnosis(Path(r.session), report, text, list(temp_lines)))


def prepare_diagnosis(request: DiagnoseRequest, cfg: StationConfig | None = None, say: Callable[[str], None] | None = None,
                      config: Path | None = None) -> PreparedDiagnosis:
    """Every refusal before the (long) diagnosis: the settings, an output that exists, no file,
    a CSV not imported, an unreadable session or twin. `cfg`: the station config whose catalog a
    fleet twin reads (None: load `config`); `say(line)` is told which catalog it read."""
    r = request
    settings = r.checked_settings()
    if not r.session:
        raise InputError("name a session file (FILE.h5), or use --self-check")
    path = Path(r.session)
    if path.suffix.lower() == ".csv":
        raise InputError(f"{path}: a CSV must be imported first: `station import {path} --out FILE.h5`, "
                         "then `station diagnose FILE.h5`")
    from procedures.io.recording.reader import read_session

    session = read_session(path)
    twin = None
    if r.twin_model is not None:
        from procedures.diagnosis import twin_from_model

        twin = twin_from_model(*r.twin_model)
    elif r.twin:
        from station.services.twins import load_twin

        def engine():  # fleet:TYPE reads the station's catalog
            from station.catalog.store import catalog_of, reading_engine

            got, where = reading_engine(catalog_of(config_or_load(cfg, config)), r.local)
            if say is not None:
                say(where)
            return got

        twin = load_twin(r.twin, session=session, path=path, catalog=engine)
    return PreparedDiagnosis(r, session, twin, settings, lines=[f"diagnose {path}"])


# -- the self-check: the diagnosis on simulated sessions with known effects withheld ---------------

@dataclass
class SelfCheckRequest(DiagnosisOptions):
    """`seeds` sessions from `first_seed` (per physics with `variants`, comma separated, "" = all)
    with a withheld effect of RMS contribution in `magnitude_um` (MIN, MAX); the output and
    settings: DiagnosisOptions."""

    session: Path | None = None  # refused: the self-check makes its own sessions
    seeds: int = 20
    first_seed: int = 0
    variants: str | None = None
    magnitude_um: tuple[float, float] | None = None


@dataclass
class PreparedSelfCheck(OfflineJob):
    request: SelfCheckRequest
    settings: DiagnosisSettings
    physics: list[str]
    progress: Callable[[str], None] | None = None

    def run(self, sinks=(), control=None) -> JobOutcome:
        """Status "done" when every trial was fully right, "failed" otherwise; `data` the results."""
        r = self.request
        seeds = range(r.first_seed, r.first_seed + r.seeds)
        say = self.progress or (lambda line: None)
        if self.physics:
            lines, result = self._variants(seeds, say)
        else:
            from procedures.diagnosis.selfcheck import format_self_check, run_self_check

            def progress(t):
                say(f"  {'ok ' if t['ok'] else 'BAD'} seed {t['seed']:>4} ({t['twin']} twin): {t['label']}")

            lo, hi = r.magnitude_um or SELF_CHECK_CONTRIBUTION_UM
            result = run_self_check((selfcheck_trial(s, contribution_um=(lo, hi)) for s in seeds), self.settings,
                                    progress)
            lines = [format_self_check(result)]
        outputs = []
        if r.json_out:
            Path(r.json_out).write_text(json.dumps(result, indent=1, allow_nan=False, default=float))
            outputs.append(Path(r.json_out))
        ok = result["summary"]["trials_ok"] == result["summary"]["trials"]
        return JobOutcome("done" if ok else "failed", outputs=outputs, lines=lines, data=result)

    def _variants(self, seeds, say) -> tuple[list[str], dict]:
        """The variants' self-check: seeds sessions per physics (procedures/synthetic.py),
        parameters within 15 %, gap within 25 % of the oracle's."""
        from procedures.diagnosis.selfcheck import (VARIANT_GAP_TOLERANCE, VARIANT_PARAM_TOLERANCE, format_by_physics,
                                                    format_self_check, run_self_check, summarise_by_physics)

        def progress(t):
            if not t["ok"]:
                say(f"  BAD seed {t['seed']:>4} ({t['twin']} twin): {t['label']}")

        result = run_self_check((variant_trial(s, p) for p in self.physics for s in seeds), self.settings, progress,
                                VARIANT_PARAM_TOLERANCE, VARIANT_GAP_TOLERANCE)
        result["by_physics"] = summarise_by_physics(result["trials"])
        lines = [f"variant self-check: {len(seeds)} sessions per physics, {result['summary']['trials_ok']} of "
                 f"{result['summary']['trials']} fully right",
                 format_by_physics(result["by_physics"], VARIANT_PARAM_TOLERANCE, VARIANT_GAP_TOLERANCE),
                 "\n".join(line for line in format_self_check(result).splitlines() if line.startswith("  seed"))]
        return lines, result


def prepare_self_check(request: SelfCheckRequest, progress: Callable[[str], None] | None = None) -> PreparedSelfCheck:
    """Every refusal before the sessions are made (settings, output, physics, magnitudes);
    `lines`: the size estimate. `progress(line)` is told each trial (the variants: each bad one)."""
    from station.services.sizing import selfcheck_estimate

    r = request
    settings = r.checked_settings()
    if r.session:
        raise InputError("--self-check makes its own sessions; drop FILE.h5")
    physics = [p.strip() for p in r.variants.split(",") if p.strip()] if r.variants else []
    per = len(r.variants.split(",")) if r.variants else 1
    lines = [f"self-check: {selfcheck_estimate(r.seeds * per).describe()}"]
    if physics:
        unknown = sorted(set(physics) - set(PHYSICS))
        if unknown:
            raise InputError(f"--variants {r.variants}: unknown physics {', '.join(unknown)}; known: "
                             f"{', '.join(PHYSICS)}")
    elif r.magnitude_um is not None:
        lo, hi = r.magnitude_um
        if not 0 < lo <= hi:
            raise InputError(f"--magnitude-um {lo:g} {hi:g}: need 0 < MIN <= MAX (um)")
    return PreparedSelfCheck(r, settings, physics, progress, lines=lines)


def material_text(doc: dict | None) -> str | None:
    """One line on the material temperature over the legs from a report's `material_temperature`
    (procedures.metrology.thermal.diagnosis_temperature_note), None when the report has none. The
    diagnosis is on the raw error, which the other analyses normalise to the reference temperature."""
    if not doc:
        return None
    from procedures.io.ranges import legs_text

    ref = doc.get("reference_temp_c", 20.0)
    legs = doc.get("legs") or {}
    if not legs:
        return f"raw error; no material temperature recorded (nothing to normalise to {ref:g} °C)"
    lo = min(v["min_c"] for v in legs.values())
    hi = max(v["max_c"] for v in legs.values())
    far = max(v["max_from_reference_k"] for v in legs.values())
    return (f"raw error (not normalised to {ref:g} °C); material {lo:.2f}..{hi:.2f} °C on legs "
            f"{legs_text(int(k) for k in legs)}, up to {far:.2f} K from {ref:g} °C")
