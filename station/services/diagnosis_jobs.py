"""The diagnosis of a recorded session as both front ends give it (`station diagnose` and the
terminal UI's Diagnosis page): procedures.diagnosis.diagnose on the raw error, with the material
temperature range that the normalisation to 20 degC of fit, iso230 and verify has to cover
(procedures.metrology.thermal.diagnosis_temperature_note) added as `material_temperature`.

One function, so the two front ends' JSON reports are the same report, not two copies of it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

# The self-check's sessions (`station diagnose --self-check`) are made from the plant alone, with the
# other synthetic sessions (procedures/synthetic.py); the front ends take them from here.
from procedures.synthetic import PHYSICS, SELF_CHECK_CONTRIBUTION_UM, selfcheck_trial, variant_trial  # noqa: F401


def diagnose_session(session: Any, path: str | Path, twin: Any = None, settings: Any = None
                     ) -> tuple[dict, list[str]]:
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


def thermal_beyond_material(report: dict, session: Any, legs: list[int]) -> None:
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


def on_common_basis(session: Any, twin: Any) -> tuple[Any, Any, list[int]]:
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
