"""Diagnosis of the gap between the digital twin and a recorded leg: where it lies, which
unmodelled effect causes it, and how far it shrinks once that effect is added (docs/diagnosis.md)."""

from procedures.diagnosis.diagnose import DiagnosisSettings, diagnose, to_json
from procedures.diagnosis.effects import EFFECTS
from procedures.diagnosis.twin import ExternalTwin, Twin, twin_from_model, twin_from_recording

__all__ = ["DiagnosisSettings", "diagnose", "to_json", "EFFECTS", "ExternalTwin", "Twin",
           "twin_from_model", "twin_from_recording"]
