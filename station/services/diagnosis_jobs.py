"""The diagnosis of a recorded session as both front ends give it (`station diagnose` and the
terminal UI's Diagnosis page): procedures.diagnosis.diagnose on the raw error, with the material
temperature range that the normalisation to 20 degC of fit, iso230 and verify has to cover
(procedures.metrology.thermal.diagnosis_temperature_note) added as `material_temperature`.

One function, so the two front ends' JSON reports are the same report, not two copies of it."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def diagnose_session(session: Any, path: str | Path, twin: Any = None, settings: Any = None
                     ) -> tuple[dict, list[str]]:
    """The diagnosis report of `session` (as procedures.recording.reader reads it, from `path`)
    against `twin` (None: the twin fitted on the recording), and the lines saying which error it
    used and the material temperature range per leg. The diagnosis works on the raw error_um on
    purpose: thermal expansion stays an effect it can find (docs/metrology.md)."""
    from procedures.diagnosis import DiagnosisSettings, diagnose
    from procedures.metrology.thermal import diagnosis_temperature_note

    report = diagnose(session.points, twin, settings if settings is not None else DiagnosisSettings(),
                      recording={"path": str(path), "sha256": session.sha256}, source=str(path))
    temp_lines, report["material_temperature"] = diagnosis_temperature_note(session.points, session.station_config)
    return report, temp_lines
