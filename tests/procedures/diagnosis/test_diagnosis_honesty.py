"""What the diagnosis says about what its library does not hold (issue 25): passes explained by
temperature are not outliers; periodic findings that may be aliases; a reference twin recorded
at another temperature; structure that no candidate explains."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from drivers.plant.leg import default_leg_configs
from procedures.diagnosis import DiagnosisSettings, diagnose
from procedures.diagnosis.diagnosis_text import text_report
from procedures.synthetic import synth_session

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


def _gearbox_session(step_mm=1.25):
    from procedures.diagnosis.twin import plant_twin

    base = _leg()
    real = replace(base, longwave=base.longwave + ((1.5625, 0.5, 0.3),))  # a gearbox term: 5 mm lead / 3.2
    pts = synth_session({1: real}, np.arange(-90, 90.001, step_mm), 5, seed=5, dwell_s=4.0)
    return pts, plant_twin({1: base}, "the plant without the gearbox term")


def test_a_gearbox_term_sampled_coarsely_is_flagged_as_a_possible_alias():
    from procedures.diagnosis.aliasing import alias_of

    assert abs(alias_of(1.5625, 1.25) - 6.25) < 1e-9 and abs(alias_of(5 / 3, 1.25) - 5.0) < 1e-9
    pts, twin = _gearbox_session()
    f = diagnose(pts, twin)["findings"][0]
    assert f["effect"] == "cyclic" and abs(f["parameters"]["wavelength_mm"] - 6.25) < 0.05
    w = f["sampling"]
    assert w["step_mm"] == 1.25 and 0.5 < w["step_to_tell_apart_mm"] <= 0.78  # below half of 1.5625 mm
    assert any(abs(p - 1.5625) < 0.01 for p in w["aliasing_periods_mm"])
    # told the motor turn, it names it
    rep = diagnose(pts, twin, DiagnosisSettings(motor_turn_mm=1.5625))
    w = rep["findings"][0]["sampling"]
    assert w["may_be_alias_of"][0]["period_mm"] == 1.5625 and "motor turn" in w["note"]
    assert "may be an alias" in text_report(rep)


def test_the_same_term_sampled_finely_is_found_at_its_own_wavelength_without_a_warning():
    pts, twin = _gearbox_session(0.5)
    f = diagnose(pts, twin, DiagnosisSettings(motor_turn_mm=1.5625))["findings"][0]
    assert abs(f["parameters"]["wavelength_mm"] - 1.5625) < 0.01
    assert "sampling" not in f


def test_a_reference_recorded_3_k_warmer_ties_the_scale_to_the_temperature_difference():
    from procedures.diagnosis.reference_twin import twin_from_recording

    cfg = _leg(add={"thermal"}, heating_k_per_m=0.0)
    targets = np.linspace(-90, 90, 91)
    ref = synth_session({1: replace(cfg, initial_temp_c=23.0, ambient_temp_c=23.0)}, targets, 5, seed=6, dwell_s=4.0)
    pts = synth_session({1: replace(cfg, initial_temp_c=20.0, ambient_temp_c=20.0)}, targets, 5, seed=5, dwell_s=4.0)
    rep = diagnose(pts, twin_from_recording(ref, "ref.h5"))
    (f,) = [f for f in rep["findings"] if f["effect"] == "scale"]
    td = f["temperature_difference"]
    assert abs(td["difference_k"] + 3.0) < 0.05
    expected = -cfg.expansion_ppm_per_k * 3.0
    assert abs(f["parameters"]["scale_ppm"] - expected) < 0.05 * abs(expected)
    assert abs(td["scale_ppm_per_k"] - cfg.expansion_ppm_per_k) < 0.05 * cfg.expansion_ppm_per_k
    assert "3.00 K warmer" in td["note"] and "most likely the temperature difference" in td["note"]
    assert "3.00 K warmer" in text_report(rep)


def _clean_session():
    from procedures.diagnosis.twin import plant_twin

    base = _leg()
    pts = synth_session({1: base}, np.linspace(-90, 90, 91), 5, seed=5, dwell_s=4.0)
    return pts, plant_twin({1: base}, "the plant")


def test_structure_outside_the_library_is_described_not_mapped_silently():
    pts, twin = _clean_session()
    assert diagnose(pts, twin)["legs"]["1"]["unexplained"] is None
    x, d = pts["target_mm"], pts["direction"]
    bump = pts.copy()
    bump["error_um"] += 0.8 * np.exp(-(((x + 40) / 6) ** 2))  # a local bump at -40 mm
    u = diagnose(bump, twin)["legs"]["1"]["unexplained"]
    assert u["shape"] == "local bump" and u["kind"] == "direction-independent"
    assert u["from_mm"] <= -40 <= u["to_mm"] and u["to_mm"] - u["from_mm"] <= 20
    assert 0.6 < u["peak_um"] < 1.0 and "outside the library" in u["note"]
    end = pts.copy()
    end["error_um"] += np.exp(-(90 - x) / 4) * (d > 0)  # upward passes only, at the top end
    u = diagnose(end, twin)["legs"]["1"]["unexplained"]
    assert u["shape"] == "end of stroke" and u["kind"] == "direction-dependent" and u["peak_at_mm"] == 90
    rep = diagnose(end, twin)
    assert "UNEXPLAINED" in text_report(rep)


def test_a_narrow_worn_patch_is_a_direction_dependent_bump_against_the_fitted_twin():
    pts, _ = _clean_session()
    x, d = pts["target_mm"], pts["direction"]
    pts["error_um"] += -0.5 * d * 0.8 * np.exp(-(((x - 20) / 8) ** 2))  # a reversal 0.8 um larger near 20 mm
    u = diagnose(pts)["legs"]["1"]["unexplained"]
    assert u["kind"] == "direction-dependent" and u["shape"] == "local bump"
    assert u["from_mm"] <= 20 <= u["to_mm"] and abs(u["peak_um"] - 0.8) < 0.15
