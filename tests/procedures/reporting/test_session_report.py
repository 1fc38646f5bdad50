"""`make_report`: the plots and the summary table, before and after compensation."""

from __future__ import annotations

import json

import numpy as np
import pytest

from drivers.plant.leg import PlantConfig
from procedures.synthetic import synth_session
from procedures.vocabulary import InputError
from procedures.fit import fit
from procedures.reporting.session_report import make_report

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def points():
    cfg = PlantConfig().only("backlash", "lead", "longwave", "wobble", "noise", "run_offset")
    return synth_session({1: cfg, 2: cfg}, np.linspace(-90, 90, 91), cycles=3, seed=3)


def test_report_files_and_summary(points, tmp_path):
    result = make_report(points, tmp_path / "rep", source_path="s.h5", source_sha256="c" * 64, lead_mm=5.0)
    names = sorted(p.name for p in result.files)
    assert names == ["errors.png", "histograms.png", "residuals.png", "spectrum.png", "summary.json", "summary.md"]
    for p in result.files:
        if p.suffix == ".png":
            assert p.read_bytes()[:8] == PNG and p.stat().st_size > 10_000
    summary = json.loads((tmp_path / "rep" / "summary.json").read_text())
    assert summary["model"]["fitted_to_this_session"] is True
    assert [r["leg"] for r in summary["legs"]] == [1, 2]
    for r in summary["legs"]:
        assert r["points"] == 91 * 6 and r["cycles"] == 3
        assert r["residual_range_um"] < 0.3 * r["range_before_um"]
        assert r["residual_rms_um"] < r["rms_before_um"]
        assert r["reversal_um"] == pytest.approx(1.0, abs=0.1)
        assert r["noise_floor_um"] > 0 and r["model_heldout_rms_um"] > 0
        iso = r["iso230_2"]  # procedures.reporting.iso230 before and after: the systematic part is gone
        assert iso["after"]["E"] < 0.2 * iso["before"]["E"] and iso["after"]["B"] < 0.3 * iso["before"]["B"]
        assert iso["before"]["B"] == pytest.approx(abs(r["reversal_um"]), abs=0.3)
    md = (tmp_path / "rep" / "summary.md").read_text()
    assert "| leg | points |" in md and "s.h5" in md and "ISO 230-2" in md
    assert md.count("\n| 1 |") == 2 and md.count("\n| 2 |") == 2  # summary and ISO tables


def test_report_with_a_model_from_another_recording(points, tmp_path):
    cfg = PlantConfig().only("backlash", "lead", "longwave", "wobble", "noise", "run_offset")
    other = synth_session({2: cfg}, np.linspace(-90, 90, 91), cycles=3, seed=99)
    model = fit(other, source={"path": "other.h5", "sha256": "d" * 64})
    result = make_report(points, tmp_path / "rep", model, source_path="s.h5", source_sha256="c" * 64)
    assert result.summary["model"]["fitted_to_this_session"] is False
    assert [r["leg"] for r in result.summary["legs"]] == [2]  # only the legs the model has
    row = result.summary["legs"][0]
    assert row["residual_range_um"] < 0.5 * row["range_before_um"]  # same plant: the model still helps


def test_report_refuses_a_model_without_common_legs(points, tmp_path):
    cfg = PlantConfig().only("noise", "lead")
    model = fit(synth_session({5: cfg}, np.linspace(-90, 90, 31), cycles=2, seed=1), lead_mm=None)
    with pytest.raises(InputError, match="no leg in common"):
        make_report(points, tmp_path / "rep", model)



def _warm(points):
    """The points with the leg's material at 25 .. 27 degC over the recording (5-7 K from 20 degC)."""
    warm = points.copy()
    warm["material_temp_c"] = 25.0 + 2.0 * np.arange(len(warm)) / len(warm)
    return warm


def test_report_works_on_the_error_normalised_to_20_degc_unless_raw(points, tmp_path):
    """Like `station fit`: the fit, figures and ISO values are of the normalised error by default,
    of the raw one with raw=True; the summary says which."""
    from procedures.reporting import iso230
    from procedures.fit.figures import range_um
    from procedures.metrology.thermal import normalise_session

    warm = _warm(points)
    norm = normalise_session(warm, None).points
    default = make_report(warm, tmp_path / "n").summary
    raw = make_report(warm, tmp_path / "r", raw=True).summary
    assert default["error_basis"]["basis"] == "normalised" and raw["error_basis"]["basis"] == "raw"
    assert default["error_basis"]["lines"][0].startswith("error: normalised to 20 degC")
    assert raw["error_basis"]["lines"] == ["error: raw, not normalised to 20 degC (--raw)"]
    for d, r in zip(default["legs"], raw["legs"]):
        leg = d["leg"]
        assert d["range_before_um"] == pytest.approx(range_um(norm["error_um"][norm["leg"] == leg]), rel=1e-12)
        assert r["range_before_um"] == pytest.approx(range_um(warm["error_um"][warm["leg"] == leg]), rel=1e-12)
        # 5-7 K on steel over +-90 mm tilts the error by ~6-8 um: the two bases differ by far more than noise
        assert abs(d["range_before_um"] - r["range_before_um"]) > 5.0
        assert d["iso230_2"]["before"]["E"] == pytest.approx(iso230.evaluate_leg(norm, leg).values["E"], rel=1e-12)
        assert r["iso230_2"]["before"]["E"] == pytest.approx(iso230.evaluate_leg(warm, leg).values["E"], rel=1e-12)
    assert "Error basis: **raw**" in (tmp_path / "r" / "summary.md").read_text()


def test_report_with_a_model_uses_its_basis_and_refuses_raw_against_a_normalised_one(points, tmp_path):
    warm = _warm(points)
    model = fit(warm, source={"path": "cal.h5", "sha256": "e" * 64})  # fit() alone records no basis: raw
    s = make_report(warm, tmp_path / "a", model).summary
    assert s["error_basis"]["basis"] == "raw"
    assert s["error_basis"]["lines"] == [
        "error: raw, not normalised to 20 degC (the model records no error basis: fitted to the raw error)"]
    model.options["error_basis"] = {"normalised": True}  # as `station fit` records it
    s = make_report(warm, tmp_path / "b", model).summary
    assert s["error_basis"]["basis"] == "normalised"
    with pytest.raises(InputError, match=r"cal-model\.json was fitted to the error normalised to 20 degC.*--raw"):
        make_report(warm, tmp_path / "c", model, raw=True, model_name="cal-model.json")
    assert not (tmp_path / "c").exists()
