"""`station diagnose` end to end: session files, the four kinds of twin, JSON output, bad input
as one clear line, and the self-check."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from drivers.plant.leg import default_leg_configs
from procedures.synthetic import synth_session
from procedures.fit import fit, save_model
from station.cli import main
from tests.tooling import write_points_session as write_session

TARGETS = np.linspace(-90.0, 90.0, 46)
POSITION_SOURCES = ("lead", "longwave", "wobble", "noise", "run_offset")




def leg1(*extra):
    return replace(default_leg_configs(0)[0], enabled=frozenset(POSITION_SOURCES + extra))


@pytest.fixture(scope="module")
def backlash_session(tmp_path_factory):
    path = tmp_path_factory.mktemp("diag") / "backlash.h5"
    return write_session(path, synth_session({1: leg1("backlash")}, TARGETS, cycles=4, seed=1))


def test_diagnose_a_session_prints_the_finding_and_writes_json(backlash_session, tmp_path, capsys):
    out = tmp_path / "diag.json"
    assert main(["diagnose", str(backlash_session), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "leg 1: backlash: reversal_um = " in text
    assert "where: the gap is mostly a direction-dependent offset" in text
    report = json.loads(out.read_text())
    assert report["recording"]["path"] == str(backlash_session)
    assert len(report["recording"]["sha256"]) == 64
    (f,) = report["findings"]
    assert f["effect"] == "backlash"
    assert f["parameters"]["reversal_um"] == pytest.approx(default_leg_configs(0)[0].reversal_um, rel=0.1)


def test_twin_sim_default_is_the_plant_without_direction_time_temperature_or_load(backlash_session, capsys):
    assert main(["diagnose", str(backlash_session), "--twin", "sim:default"]) == 0
    text = capsys.readouterr().out
    assert "twin: simulated plant (default)" in text
    assert "leg 1: backlash" in text


def test_twin_from_a_reference_recording(backlash_session, tmp_path, capsys):
    ref = write_session(tmp_path / "ref.h5", synth_session({1: leg1()}, TARGETS, cycles=3, seed=2))
    assert main(["diagnose", str(backlash_session), "--twin", str(ref), "--json", str(tmp_path / "r.json")]) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["twin"]["kind"] == "reference"
    assert [f["effect"] for f in report["findings"]] == ["backlash"]


def test_a_twin_without_the_leg_is_refused(tmp_path, capsys):
    ref = write_session(tmp_path / "ref1.h5", synth_session({1: leg1()}, TARGETS, cycles=2, seed=3))
    two = write_session(tmp_path / "leg2.h5", synth_session({2: leg1()}, TARGETS, cycles=2, seed=4))
    assert main(["diagnose", str(two), "--twin", str(ref)]) == 2
    err = capsys.readouterr().err
    assert "has no leg 2" in err and "Traceback" not in err


def test_twin_from_a_model_that_has_the_reversal_leaves_no_backlash(backlash_session, tmp_path, capsys):
    from procedures.io.recording.reader import read_session

    model_path = tmp_path / "model.json"
    save_model(fit(read_session(backlash_session).points), model_path)
    assert main(["diagnose", str(backlash_session), "--twin", str(model_path), "--json", str(tmp_path / "m.json")]) == 0
    report = json.loads((tmp_path / "m.json").read_text())
    assert report["twin"]["kind"] == "model"
    assert "backlash" not in [f["effect"] for f in report["findings"]]


def test_twin_sim_from_a_plant_toml(backlash_session, tmp_path, capsys):
    toml = tmp_path / "plant.toml"
    toml.write_text('seed = 0\n[all]\nreversal_um = 0.5\n[leg.1]\nlead_slope_um_per_m = 9.0\n')
    assert main(["diagnose", str(backlash_session), "--twin", f"sim:{toml}"]) == 0
    bad = tmp_path / "bad.toml"
    bad.write_text("[leg.1]\nlead_slope = 3\n")
    assert main(["diagnose", str(backlash_session), "--twin", f"sim:{bad}"]) == 2
    err = capsys.readouterr().err
    assert "lead_slope: not a plant parameter" in err and "Traceback" not in err


def test_bad_input_is_one_clear_line(tmp_path, capsys):
    csv = tmp_path / "x.csv"
    csv.write_text("leg,run,direction,target_mm,error_um\n")
    assert main(["diagnose", str(csv)]) == 2
    assert "station import" in capsys.readouterr().err
    assert main(["diagnose", str(tmp_path / "missing.h5")]) == 2
    err = capsys.readouterr().err
    assert "missing.h5" in err and "Traceback" not in err
    assert main(["diagnose"]) == 2
    assert "--self-check" in capsys.readouterr().err
    assert main(["diagnose", str(tmp_path / "x.h5"), "--twin", "nowhere.json"]) == 2


def test_self_check_prints_the_table_and_writes_json(tmp_path, capsys):
    out = tmp_path / "sc.json"
    assert main(["diagnose", "--self-check", "--seeds", "2", "--first-seed", "6", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "self-check: 2 sessions, 2 fully right" in text
    result = json.loads(out.read_text())
    assert result["summary"]["trials"] == 2
    assert {t["seed"] for t in result["trials"]} == {6, 7}


def test_self_check_magnitude_range_is_checked(capsys):
    from station.cli import main

    assert main(["diagnose", "--self-check", "--seeds", "1", "--magnitude-um", "1", "0.5"]) == 2
    assert "need 0 < MIN <= MAX" in capsys.readouterr().err


def test_self_check_of_the_variants_prints_a_row_per_physics_and_writes_json(tmp_path, capsys):
    out = tmp_path / "v.json"
    assert main(["diagnose", "--self-check", "--variants", "windup,clean", "--seeds", "1", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "variant self-check: 1 sessions per physics, 2 of 2 fully right" in text
    assert "windup_mm" in text and "named on clean legs: 0" in text
    data = json.loads(out.read_text())
    assert set(data["by_physics"]) == {"windup", "clean"}
    assert main(["diagnose", "--self-check", "--variants", "wobble", "--seeds", "1"]) == 2
    err = capsys.readouterr().err
    assert "unknown physics wobble" in err and "backlash_temperature" in err


def test_motor_turn_must_be_positive(backlash_session, capsys):
    assert main(["diagnose", str(backlash_session), "--motor-turn-mm", "0"]) == 2
    assert "argument --motor-turn-mm: '0' is outside >0 .. 100 mm" in capsys.readouterr().err
