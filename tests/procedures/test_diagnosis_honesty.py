"""What the diagnosis says about what its library does not hold (issue 25): passes explained by
temperature are not outliers; periodic findings that may be aliases; a reference twin recorded
at another temperature; structure that no candidate explains."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from drivers.sim.plant import default_leg_configs
from procedures.diagnosis import DiagnosisSettings, diagnose
from procedures.diagnosis.text_report import text_report
from station.synth import synth_session

BASE = frozenset({"lead", "longwave", "wobble", "noise", "run_offset"})


def _leg(seed=3, **kw):
    return replace(default_leg_configs(seed, 1)[0], enabled=BASE | set(kw.pop("add", ())), **kw)


def test_a_cold_first_pass_is_explained_by_temperature_not_an_outlier():
    # warm-up: the leg starts 2 K below the hall and reaches it within the first passes
    cfg = _leg(add={"thermal", "backlash"}, initial_temp_c=18.0, ambient_temp_c=20.5, tau_s=400.0)
    pts = synth_session({1: cfg}, np.linspace(-90, 90, 91), 5, seed=5, dwell_s=4.0)
    leg = diagnose(pts)["legs"]["1"]
    assert leg["outlier_passes"] == []
    assert not any("dominates the pass scatter" in c for c in leg["cannot_conclude"])
    # without the thermal candidate the cold passes stand out, but temperature explains them
    rep = diagnose(pts, settings=DiagnosisSettings(effects=("backlash",)))
    leg = rep["legs"]["1"]
    assert leg["outlier_passes"] == []
    runs = [p["run"] for p in leg["passes_explained_by_temperature"]]
    assert 1 in runs
    first = leg["passes_explained_by_temperature"][0]
    assert first["offset_um"] < -1 and first["temp_c"] < 19.5
    assert "explained by its material temperature" in text_report(rep)


def test_a_pass_off_for_no_recorded_reason_stays_an_outlier():
    cfg = _leg(add={"thermal"})
    pts = synth_session({1: cfg}, np.linspace(-90, 90, 91), 5, seed=5, dwell_s=4.0)
    pts["error_um"][pts["run"] == 4] += 3.0  # a bumped reflector: no temperature change explains it
    leg = diagnose(pts)["legs"]["1"]
    assert [p["run"] for p in leg["outlier_passes"]] == [4]
