"""The diagnosis on simulated sessions: it names the effect present in the plant and withheld
from the twin, with its parameters, and nothing where there is nothing."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from drivers.plant.leg import PlantConfig
from procedures.synthetic import synth_session
from procedures.diagnosis import DiagnosisSettings, diagnose, to_json
from procedures.vocabulary import InputError, SchemaError
from procedures.diagnosis.twin import plant_twin

BASE = PlantConfig(noise_um=0.03, run_offset_um=0.04).only("lead", "longwave", "wobble", "noise", "run_offset")
TARGETS = np.linspace(-90.0, 90.0, 61)


def named(report: dict, leg: int) -> dict:
    return {f["effect"]: f for f in report["findings"] if f["leg"] == leg}


def with_source(cfg: PlantConfig, *sources: str, **kw) -> PlantConfig:
    return replace(cfg, enabled=cfg.enabled | set(sources), **kw)


def test_backlash_is_named_on_its_leg_only_with_the_reversal():
    cfgs = {1: with_source(BASE, "backlash", reversal_um=1.5), 2: BASE}
    report = diagnose(synth_session(cfgs, TARGETS, cycles=5, seed=3))
    assert set(named(report, 1)) == {"backlash"}
    assert named(report, 2) == {}
    f = named(report, 1)["backlash"]
    assert f["parameters"]["reversal_um"] == pytest.approx(1.5, rel=0.1)
    assert 0 < f["uncertainty"]["reversal_um"] < 0.1
    assert f["heldout_rms_after_um"] < 0.3 * f["heldout_rms_before_um"]
    assert report["legs"]["1"]["dominant"].startswith("the gap is mostly a direction-dependent offset")
    assert [(f["leg"], f["effect"]) for f in report["findings"]] == [(1, "backlash")]
    assert report["legs"]["2"]["combined"]["effects"] == []
    # the clean leg's gap is at the plant's noise (white 0.03 um + pass offsets 0.04 um); with no
    # effect named, the repeat scatter after effects is the noise floor (of station fit)
    assert report["legs"]["2"]["noise_floor_um"] == pytest.approx(0.05, rel=0.35)
    assert report["legs"]["2"]["repeat_scatter_after_effects_um"] == pytest.approx(
        report["legs"]["2"]["noise_floor_um"], rel=0.05)


def test_drift_with_a_changing_temperature_is_named_drift_not_thermal():
    # the material temperature swings (ambient cycling) but the plant has no thermal error
    cfg = with_source(BASE, "drift", drift_um_per_h=2.0, ambient_swing_k=1.2, ambient_period_s=1500.0,
                      initial_temp_c=20.5)
    points = synth_session({1: cfg}, TARGETS, cycles=5, seed=4, dwell_s=4.0)
    assert np.ptp(points["material_temp_c"]) > 0.3
    report = diagnose(points)
    assert set(named(report, 1)) == {"drift"}
    assert named(report, 1)["drift"]["parameters"]["drift_um_per_h"] == pytest.approx(2.0, rel=0.1)
    thermal = next(c for c in report["legs"]["1"]["candidates"] if c["effect"] == "thermal")
    assert thermal["status"] != "named"


def test_thermal_against_the_plant_twin_gives_the_expansion_coefficient():
    cfg = with_source(BASE, "thermal", expansion_ppm_per_k=11.5, bearing_mm=-150.0, ambient_swing_k=1.5,
                      ambient_period_s=1500.0, initial_temp_c=21.0)
    points = synth_session({2: cfg}, TARGETS, cycles=5, seed=5, dwell_s=4.0)
    report = diagnose(points, plant_twin({2: BASE}, "plant without thermal"))
    f = named(report, 2)
    assert set(f) == {"thermal"}
    p = f["thermal"]["parameters"]
    assert p["expansion_ppm_per_k"] == pytest.approx(11.5, rel=0.1)
    assert p["bearing_mm"] == pytest.approx(-150.0, abs=25.0)


def test_load_compliance_from_passes_at_different_loads():
    loads = tuple(float(v) for v in np.random.default_rng(1).uniform(0, 800, 12))
    cfg = with_source(BASE, "load", load_per_pass_n=loads, bearing_compliance_um_per_kn=2.0,
                      screw_compliance_um_per_kn_per_m=15.0, bearing_mm=-150.0)
    report = diagnose(synth_session({1: cfg}, TARGETS, cycles=5, seed=6))
    f = named(report, 1)
    assert set(f) == {"load"}
    assert f["load"]["parameters"]["compliance_um_per_kn"] == pytest.approx(cfg.compliance_um_per_kn, rel=0.1)


def test_cyclic_and_scale_against_an_external_twin():
    cfg = with_source(BASE, "scale", scale_ppm=6.0, longwave=BASE.longwave + ((17.0, 0.5, 1.0),))
    report = diagnose(synth_session({1: cfg}, TARGETS, cycles=4, seed=7), plant_twin({1: BASE}, "plant"))
    f = named(report, 1)
    assert set(f) == {"scale", "cyclic"}
    assert f["scale"]["parameters"]["scale_ppm"] == pytest.approx(6.0, rel=0.1)
    assert f["cyclic"]["parameters"]["wavelength_mm"] == pytest.approx(17.0, rel=0.05)
    assert f["cyclic"]["parameters"]["amplitude_um"] == pytest.approx(0.5, rel=0.1)


def test_a_twin_fitted_on_the_recording_cannot_test_scale_or_cyclic_and_says_so():
    report = diagnose(synth_session({1: BASE}, TARGETS, cycles=3, seed=8))
    cands = {c["effect"]: c for c in report["legs"]["1"]["candidates"]}
    for name in ("scale", "cyclic"):
        assert cands[name]["status"] == "not applicable"
        assert "--twin" in cands[name]["reason"]
    assert cands["load"]["status"] == "not applicable"  # load constant at 0 N
    assert report["findings"] == []


def test_the_report_is_strict_json_with_units_in_the_keys():
    cfgs = {1: with_source(BASE, "backlash", reversal_um=1.0)}
    report = diagnose(synth_session(cfgs, TARGETS, cycles=3, seed=9), settings=DiagnosisSettings(lead_mm=5.0))
    text = to_json(report)  # raises on NaN/Infinity
    back = json.loads(text)
    assert back["format"] == "station-diagnosis"
    f = back["findings"][0]
    for key in ("leg", "effect", "parameters", "uncertainty", "heldout_rms_before_um", "heldout_rms_after_um"):
        assert key in f
    leg = back["legs"]["1"]
    for key in ("gap", "by_direction", "by_region", "by_pass", "spectrum", "by_condition", "dominant",
                "noise_floor_um", "repeat_scatter_after_effects_um", "within_pass_scatter_after_effects_um",
                "pass_offset_scatter_after_effects_um", "combined", "candidates", "cannot_conclude"):
        assert key in leg
    assert leg["spectrum"]["lead_mm"] == 5.0
    assert len(leg["by_region"]) == 4


def test_one_cycle_is_described_but_nothing_is_tested():
    points = synth_session({1: with_source(BASE, "backlash")}, TARGETS, cycles=1, seed=10)
    report = diagnose(points)
    leg = report["legs"]["1"]
    assert report["findings"] == []
    assert any("only 1 cycle" in t for t in leg["cannot_conclude"])
    assert all(c["status"] == "not applicable" for c in leg["candidates"])
    to_json(report)


def test_missing_conditions_are_not_measured_not_zero():
    points = synth_session({1: BASE}, TARGETS, cycles=3, seed=11)
    for name in ("time_s", "material_temp_c", "load_n"):
        points[name] = np.nan
    report = diagnose(points)
    leg = report["legs"]["1"]
    cands = {c["effect"]: c for c in leg["candidates"]}
    assert "no material temperature" in cands["thermal"]["reason"]
    assert "no axial load" in cands["load"]["reason"]
    assert cands["drift"]["status"] != "not applicable"  # tested against pass order
    assert leg["by_condition"]["material_temp"] is None
    assert leg["pass_trend"]["note"].startswith("no time recorded")
    to_json(report)


def test_bad_input_is_refused_with_the_row_named():
    points = synth_session({1: BASE}, TARGETS, cycles=2, seed=12)
    points["direction"][7] = 0
    with pytest.raises(SchemaError, match="row 7"):
        diagnose(points)
    no_error = np.zeros(3, dtype=[("leg", "i2"), ("run", "i4"), ("direction", "i1"), ("target_mm", "f8")])
    with pytest.raises(SchemaError, match="error_um"):
        diagnose(no_error)
    with pytest.raises(InputError, match="threshold"):
        DiagnosisSettings(threshold_um=-1)
    with pytest.raises(InputError, match="unknown effect"):
        DiagnosisSettings(effects=("backlash", "gremlins"))


def test_gap_by_target_is_the_mean_gap_per_target_and_direction():
    cfg = PlantConfig().only("lead", "backlash", "noise")
    pts = synth_session({1: cfg}, np.linspace(-90, 90, 13), cycles=4, seed=3)
    report = diagnose(pts)
    bt = report["legs"]["1"]["by_target"]
    assert bt["position_mm"] == pytest.approx(list(np.linspace(-90, 90, 13)))
    up, down = np.array(bt["gap_up_um"]), np.array(bt["gap_down_um"])
    # the twin has no direction term: the gap's direction split is the reversal
    assert np.mean(down - up) == pytest.approx(cfg.reversal_um, abs=0.05)
