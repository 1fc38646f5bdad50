"""The ISO 230-2 test report of `station report` (procedures.reporting.iso230_report): its JSON figures
against an independent evaluation, and the PDF's text (pdftotext) holding what the standard's
report states, each value with its expanded uncertainty."""

from __future__ import annotations

import json
import os
import shutil
import subprocess

import numpy as np
import pytest

from drivers.plant.leg import PlantConfig
from procedures.reporting import iso230
from procedures.acquisition import plans
from procedures.metrology.thermal import normalise_points, Material
from procedures.metrology.uncertainty import UncertaintyInputs, leg_budget
from procedures.reporting.session_report import make_report
from procedures.synthetic import synth_session

PLAN = plans.iso230_plan(legs=(1, 2))
CONFIG = {
    "metrology": {"model": "Renishaw XL-80", "serial": "XL-12345", "calibration_date": "2026-03-14",
                  "laser_accuracy_ppm": 0.5, "wavelength_nm": 632.991, "air_temp_u_c": 0.1},
    "leg_materials": {"1": {"expansion_um_m_k": 11.5, "expansion_u_um_m_k": 1.0, "fixed_point_mm": -120.0},
                      "2": {"expansion_um_m_k": 23.0, "expansion_u_um_m_k": 2.0, "fixed_point_mm": 0.0}},
}
DEVICES = {"interferometer": "StationSim,LI-6,SIM-0001,1.0", "leg1": "LegServo s/n A1", "leg2": "LegServo s/n A2",
           "leg1_compensation": "table compensation off", "leg2_compensation": "bank B active, empty",
           "laser_air_compensation": json.dumps({"equation": "edlen", "wavelength_nm": 632.991})}
ATTRS = {"session_id": "abc123", "operator": "jdoe", "rig": "sim", "started_utc": "2026-11-24T08:00:00+00:00",
         "ended_utc": "2026-11-24T09:00:00+00:00", "outcome": "completed"}


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    pts = synth_session({1: PlantConfig(), 2: PlantConfig()}, PLAN.targets_mm, cycles=5, seed=2)
    out = tmp_path_factory.mktemp("rep")
    meta = {"plan": PLAN.to_dict(), "devices": DEVICES, "station_config": CONFIG, "attrs": ATTRS}
    result = make_report(pts, out, source_path="cal.h5", source_sha256="d" * 64, session_meta=meta)
    return pts, out, result


def test_json_figures_are_the_normalised_iso_values_with_their_U(report):
    pts, out, result = report
    d = json.loads((out / "iso230-2.json").read_text())
    assert d == result.iso230
    mats = {int(k): Material(**v) for k, v in CONFIG["leg_materials"].items()}
    norm = normalise_points(pts, mats, 20.0).points
    # the normalisation moved the values (the legs warm up during the test)
    assert not np.allclose(norm["error_um"], pts["error_um"])
    assert d["error_basis"]["basis"] == "normalised"
    expected = iso230.evaluate(norm)
    for leg in (1, 2):
        entry = d["legs"][str(leg)]
        budget = leg_budget(expected[leg], norm, UncertaintyInputs.from_record(CONFIG, leg))
        for name in ("E", "E_up", "E_down", "M", "A", "A_up", "A_down", "B", "B_mean", "R", "R_up", "R_down"):
            assert entry["values"][name]["value_um"] == pytest.approx(expected[leg].values[name], abs=1e-9)
            assert entry["values"][name]["U_um"] == pytest.approx(budget.U(name), rel=1e-9)
            assert entry["values"][name]["U_um"] > 0
        lp = pts[pts["leg"] == leg]
        assert entry["environment"]["material_temp_c"] == pytest.approx(
            [lp["material_temp_c"].min(), lp["material_temp_c"].max()])
        assert entry["environment"]["pressure_hpa"] == pytest.approx(
            [lp["air_pressure_hpa"].min(), lp["air_pressure_hpa"].max()])
        assert entry["material"]["expansion_um_m_k"] == CONFIG["leg_materials"][str(leg)]["expansion_um_m_k"]
        assert entry["compensation"] == DEVICES[f"leg{leg}_compensation"]
        assert len(entry["targets"]) == 2 * len(PLAN.targets_mm)
        assert all(t["U_um"] > 0 for t in entry["targets"])
    # leg 2's aluminium-like coefficient and its larger u weigh more in E's budget than leg 1's steel
    def alpha_term(leg):
        return next(c["u_um"] for c in d["legs"][str(leg)]["budget"]["values"]["E"]["contributions"]
                    if c["source"] == "material temperature")
    assert alpha_term(2) > alpha_term(1)
    tp = d["test_parameters"]
    assert tp["targets_mm"] == pytest.approx(list(PLAN.targets_mm))
    assert (tp["cycles"], tp["dwell_s"], tp["overrun_mm"]) == (PLAN.cycles, PLAN.dwell_s, PLAN.overrun_mm)
    ins = d["identification"]["instrument"]
    assert (ins["model"], ins["serial"], ins["calibration_date"]) == ("Renishaw XL-80", "XL-12345", "2026-03-14")


def test_pdf_states_what_the_standard_asks(report):
    pts, out, result = report
    pdf = out / "iso230-2.pdf"
    assert pdf.read_bytes().startswith(b"%PDF")
    png = out / "iso230-2.png"
    assert png.read_bytes().startswith(b"\x89PNG")
    if shutil.which("pdftotext") is None:
        if os.environ.get("CI") == "true":
            pytest.fail("pdftotext (poppler-utils) is needed on CI to read the report's PDF")
        pytest.skip("pdftotext not installed (apt install poppler-utils): the PDF's text is not checked here")
    text = subprocess.run(["pdftotext", "-layout", str(pdf), "-"], capture_output=True, text=True, check=True).stdout
    for phrase in ("ISO 230-2 test report", "Renishaw XL-80", "XL-12345", "2026-03-14", "Environment",
                   "Expansion coefficient and NDE", "normalised to 20 degC", "Test parameters", "Cycles: 5",
                   "overrun 2 mm", "Compensation state", "table compensation off", "bank B active, empty",
                   "U (k = 2)", "LegServo s/n A2", "+/-2s bands", "equation edlen"):
        assert phrase in text, phrase
    d = result.iso230
    for leg in ("1", "2"):
        for name in ("E", "A", "B", "M", "R"):
            v = d["legs"][leg]["values"][name]
            assert f"{v['value_um']:.3f}" in text and f"{v['U_um']:.3f}" in text, (leg, name)
        lo, hi = d["legs"][leg]["environment"]["material_temp_c"]
        assert f"{lo:.2f} .. {hi:.2f}" in text
    md = (out / "iso230-2.md").read_text()
    assert "| E |" in md and "Renishaw XL-80" in md


def test_a_session_without_metrology_says_so(tmp_path):
    pts = synth_session({1: PlantConfig()}, PLAN.targets_mm, cycles=3, seed=1)
    pts["material_temp_c"] = np.nan  # no material sensor
    meta = {"plan": plans.iso230_plan(cycles=3).to_dict(), "devices": {}, "station_config": {}, "attrs": {}}
    result = make_report(pts, tmp_path / "r", session_meta=meta)
    d = result.iso230
    assert d["error_basis"]["basis"] == "raw" and "NOT normalised" in d["error_basis"]["statement"]
    assert d["identification"]["instrument"]["calibration_date"] == "not stated"
    assert d["legs"]["1"]["environment"]["material_temp_c"] is None
    assert d["legs"]["1"]["values"]["E"]["U_um"] > 0
    json.dumps(d, allow_nan=False)
