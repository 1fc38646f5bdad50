"""The verification report points out a leg that is warmer than it was at calibration."""

import numpy as np
import pytest

from drivers.plant.leg import PlantConfig
from procedures.synthetic import synth_session
from procedures.compensation.verify import format_report, verify


def _session(initial_temp_c: float) -> np.ndarray:
    cfg = PlantConfig(initial_temp_c=initial_temp_c, ambient_temp_c=initial_temp_c, heating_k_per_m=0.0)
    return synth_session({1: cfg}, np.linspace(-90, 90, 11), cycles=3, seed=1)


def test_a_warmer_verification_is_named_with_its_temperatures():
    before, after = _session(20.0), _session(20.8)
    report = verify(after, before)
    assert report[1].after.material_temp_c - report[1].before.material_temp_c == pytest.approx(0.8)
    text = format_report(report)
    assert "0.80 K warmer during verification (20.80 C) than during calibration (20.00 C)" in text


def test_no_note_when_the_temperatures_match():
    before, after = _session(20.0), _session(20.02)
    assert "warmer" not in format_report(verify(after, before))
