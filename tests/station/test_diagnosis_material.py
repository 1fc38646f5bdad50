"""Issue 35, item 3: against a reference compared normalised to 20 degC, a thermal finding is the
expansion beyond the assumed material; the report says so in words and figures. Legs whose error
does not follow their temperature (a sensor on a part that does not warm with the screw):
normalising them with steel's 11.5 ppm/K puts -11.5 ppm/K into them."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from drivers.plant.leg import default_leg_configs
from procedures.diagnosis.diagnosis_text import text_report
from procedures.io.recording.reader import read_session
from station.services.diagnosis_jobs import diagnose_session
from procedures.synthetic import synth_session
from station.services.twins import load_twin
from tests.tooling import write_points_session


def _pair(tmp_path, expansion_ppm_per_k: float):
    cfg = replace(default_leg_configs(4)[0], expansion_ppm_per_k=expansion_ppm_per_k, heating_k_per_m=0.0,
                  drift_um_per_h=0.0, ambient_swing_k=2.5, ambient_period_s=4000.0, tau_s=900.0)
    targets = np.linspace(-90, 90, 61)
    ref = write_points_session(tmp_path / "ref.h5", synth_session({1: cfg}, targets, 4, seed=11, dwell_s=2.0))
    here_path = write_points_session(tmp_path / "here.h5", synth_session({1: cfg}, targets, 5, seed=12, dwell_s=2.0))
    return read_session(here_path), here_path, ref


def test_a_leg_that_does_not_expand_like_steel_is_said_so(tmp_path):
    here, path, ref = _pair(tmp_path, 0.0)
    assert np.ptp(here.points["material_temp_c"]) > 1.0
    report, _ = diagnose_session(here, path, load_twin(str(ref)))
    assert report["twin"]["normalised_legs"] == [1]
    (th,) = [f for f in report["findings"] if f["effect"] == "thermal"]
    m = th["material"]
    assert m["assumed_ppm_per_k"] == 11.5
    assert abs(m["beyond_assumed_ppm_per_k"] + 11.5) < 1.0 and abs(m["measured_ppm_per_k"]) < 1.0
    assert m["measured_ppm_per_k"] == m["assumed_ppm_per_k"] + th["parameters"]["expansion_ppm_per_k"]
    assert "expansion beyond the assumed steel: assumed 11.5, measured" in m["note"]
    assert "does not expand like the assumed steel: check the material setting or where the sensor sits" in m["note"]
    assert "NOTE: compared normalised to 20 degC" in text_report(report)


def test_a_steel_leg_is_not_flagged(tmp_path):
    here, path, ref = _pair(tmp_path, 11.5)
    report, _ = diagnose_session(here, path, load_twin(str(ref)))
    for f in report["findings"]:  # a finding, if any, is a small remainder and said to be like steel
        if f["effect"] == "thermal":
            assert "expands like steel" in f["material"]["note"]
