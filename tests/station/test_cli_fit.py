"""`station fit`, `station table`, `station report` through station.cli.main."""

from __future__ import annotations

import json

import numpy as np
import pytest

from drivers.plant.leg import PlantConfig
from procedures.synthetic import synth_session
from procedures.acquisition.plans import irregular_targets
from procedures.io.recording.reader import file_sha256
from procedures.compensation.table import read_table_csv
from station.cli import main
from tests.tooling import write_points_session as write_session




CFG = PlantConfig().only("backlash", "lead", "longwave", "wobble", "noise", "run_offset")


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    pts = synth_session({1: CFG, 2: CFG}, np.linspace(-90, 90, 121), cycles=3, seed=21)
    return write_session(tmp_path_factory.mktemp("s") / "s.h5", pts)


@pytest.fixture(scope="module")
def model_file(session, tmp_path_factory):
    out = tmp_path_factory.mktemp("m") / "model.json"
    assert main(["fit", str(session), "--out", str(out)]) == 0
    return out


def test_fit_prints_per_leg_figures_and_names_the_recording(session, model_file, capsys):
    out = model_file.with_name("again.json")
    assert main(["fit", str(session), "--out", str(out), "--lead-mm", "5"]) == 0
    text = capsys.readouterr().out
    assert "held-out RMS" in text and "noise floor" in text and "ratio" in text and "reduction" in text
    lines = [line for line in text.splitlines() if line.strip().startswith(("1 ", "2 "))]
    assert len(lines) == 2 and all("lead harmonic" in line and "%" in line for line in lines)
    doc = json.loads(out.read_text())
    assert doc["source"] == {"path": str(session), "sha256": file_sha256(session)}
    assert doc["method"] == "default" and set(doc["legs"]) == {"1", "2"}


def test_fit_paper_method_with_params(session, tmp_path, capsys):
    out = tmp_path / "paper.json"
    assert main(["fit", str(session), "--out", str(out), "--method", "paper", "--params", "30", "--legs", "2"]) == 0
    assert "30 of 60 cosines" in capsys.readouterr().out
    doc = json.loads(out.read_text())
    assert doc["method"] == "paper" and list(doc["legs"]) == ["2"] and len(doc["legs"]["2"]["model"]["k"]) == 30


def test_fit_paper_refuses_irregular_targets(tmp_path, capsys):
    pts = synth_session({1: CFG}, irregular_targets(-90, 90, 21, seed=1), cycles=2, seed=1)
    f = write_session(tmp_path / "iso.h5", pts)
    out = tmp_path / "m.json"
    assert main(["fit", str(f), "--out", str(out), "--method", "paper"]) == 2
    err = capsys.readouterr().err
    assert "uniformly spaced" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_table_csv_and_linuxcnc(model_file, tmp_path, capsys):
    csv = tmp_path / "t.csv"
    assert main(["table", str(model_file), "--out", str(csv)]) == 0
    t = read_table_csv(csv, expected_legs=2)
    assert t.legs[1].point_count == 121 and t.legs[1].step_mm == pytest.approx(1.5)
    assert main(["table", str(model_file), "--out", str(tmp_path / "t2.csv"), "--step", "2.5"]) == 0
    assert read_table_csv(tmp_path / "t2.csv").legs[2].point_count == 73
    lc = tmp_path / "lc"
    assert main(["table", str(model_file), "--out", str(lc), "--format", "linuxcnc", "--comp-type", "1"]) == 0
    assert sorted(p.name for p in lc.iterdir()) == ["joint0.comp", "joint1.comp"]
    assert "COMP_FILE_TYPE = 1" in capsys.readouterr().out


def test_table_refuses_a_too_fine_step_and_writes_nothing(model_file, tmp_path, capsys):
    csv = tmp_path / "t.csv"
    assert main(["table", str(model_file), "--out", str(csv), "--step", "0.1"]) == 2
    err = capsys.readouterr().err
    assert "more than the drive holds (512)" in err and "Traceback" not in err
    assert not csv.exists()


def test_table_refuses_a_corrupt_model(model_file, tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text(model_file.read_text()[:300])
    csv = tmp_path / "t.csv"
    assert main(["table", str(bad), "--out", str(csv)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "not valid JSON" in err and "Traceback" not in err
    assert not csv.exists()


def test_report(session, model_file, tmp_path, capsys):
    out = tmp_path / "rep"
    assert main(["report", str(session), "--out", str(out), "--model", str(model_file)]) == 0
    assert {"errors.png", "residuals.png", "histograms.png", "spectrum.png", "summary.md", "summary.json"} <= {
        p.name for p in out.iterdir()}
    text = capsys.readouterr().out
    assert "leg 1: range" in text and "leg 2: range" in text


def test_table_with_a_missing_profile_is_one_clear_line(model_file, tmp_path, capsys):
    csv = tmp_path / "t.csv"
    assert main(["table", str(model_file), "--out", str(csv), "--profile", str(tmp_path / "nope.toml")]) == 2
    err = capsys.readouterr().err
    assert "nope.toml" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not csv.exists()


def test_fit_of_a_csv_file_says_what_to_do(tmp_path, capsys):
    f = tmp_path / "x.csv"
    f.write_text("leg,run,direction,target_mm,error_um\n1,1,1,0.0,0.1\n")
    assert main(["fit", str(f), "--out", str(tmp_path / "m.json")]) == 2
    assert "station import" in capsys.readouterr().err


def test_fit_warns_of_a_table_recorded_only_as_the_structured_state(tmp_path, capsys):
    # a session whose devices carry the table state only as JSON (legN_compensation_table, no prose):
    # fit reads it through procedures.io.recording.stage.active_tables, not by parsing text
    from procedures.io.recording.writer import SessionWriter

    pts = synth_session({1: CFG, 2: CFG}, np.linspace(-90, 90, 61), cycles=2, seed=5)
    state = json.dumps({"enabled": True, "bank": 1, "points": 37, "sha256": "ab" * 32, "start_mm": -90.0,
                        "spacing_mm": 5.0, "target": "drive"})  # as procedures.compensation.applied_table records
    off = json.dumps({"enabled": False, "bank": 0, "points": 0, "sha256": ""})
    path = tmp_path / "tabled.h5"
    with SessionWriter.create(path, session_id="t", operator="test", rig="sim", plan={"kind": "test"},
                              station_config={}, devices={"leg2_compensation_table": state,
                                                          "leg1_compensation_table": off},
                              software_version="test") as w:
        w.append_points(pts)
        w.finish("completed")
    assert main(["fit", str(path), "--out", str(tmp_path / "m.json")]) == 0
    out = capsys.readouterr().out
    assert ("warning: leg 2 was recorded with a compensation table active (bank 1 active, 37 points from "
            "-90.000 mm every 5 mm)") in out
    assert "warning: leg 1" not in out
