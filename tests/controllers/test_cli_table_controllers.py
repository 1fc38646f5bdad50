"""`station table --format siemens840d|heidenhain|twincat|ecmc` through station.cli.main: the
files read back through each controller's rule give -e(x) of the model's table."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.plant.leg import PlantConfig
from procedures.compensation import controllers
from procedures.fit import load_model
from procedures.compensation.table import make_table
from station.cli import main
from procedures.synthetic import synth_session
from tests.tooling import write_points_session as write_session

CFG = PlantConfig(reversal_um=2.0).only("backlash", "lead", "longwave", "wobble", "noise")


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    pts = synth_session({1: CFG, 2: CFG}, np.linspace(-90, 90, 121), cycles=3, seed=21)
    session = write_session(tmp_path_factory.mktemp("s") / "s.h5", pts)
    out = tmp_path_factory.mktemp("m") / "model.json"
    assert main(["fit", str(session), "--out", str(out)]) == 0
    return out


@pytest.mark.parametrize("fmt, names, tolerance_mm", [
    ("siemens840d", ["leg1.ini", "leg2.ini"], 1e-6),
    ("heidenhain", ["leg1.COM", "leg2.COM"], 1e-4),
    ("twincat", ["achskw1.lis", "achskw2.lis"], 1e-4),
])
def test_table_writes_each_controller_format(model_file, tmp_path, capsys, fmt, names, tolerance_mm):
    out = tmp_path / fmt
    assert main(["table", str(model_file), "--out", str(out), "--format", fmt]) == 0
    printed = capsys.readouterr().out
    assert sorted(p.name for p in out.iterdir()) == names
    assert controllers.HINTS[fmt] in printed
    table = make_table(load_model(model_file), spec=controllers.module(fmt).LIMITS)
    x = np.linspace(-92, 92, 301)
    for leg, name in zip((1, 2), names):
        comp = controllers.module(fmt).load(out / name)
        t = table.legs[leg]
        shift = controllers.module(fmt).reference_shift_mm(t, 0.0) if fmt == "siemens840d" else 0.0
        for d in (1, -1):
            expected = -(np.asarray(t.correction_um(x, d)) / 1000.0 - shift)
            assert np.max(np.abs(comp.applied_mm(x, d) - expected)) <= tolerance_mm / 2 + 1e-12


def test_table_ecmc_one_direction_and_siemens_enc_comp(model_file, tmp_path, capsys):
    assert main(["table", str(model_file), "--out", str(tmp_path / "e.lut"), "--format", "ecmc",
                 "--ecmc-direction", "fwd", "--legs", "2"]) == 0
    assert (tmp_path / "e_leg2.lut").exists() and not (tmp_path / "e_leg1.lut").exists()
    assert main(["table", str(model_file), "--out", str(tmp_path / "s"), "--format", "siemens840d",
                 "--siemens-mode", "enc_comp", "--reference-mm", "10"]) == 0
    text = (tmp_path / "s" / "leg1.ini").read_text()
    assert "$AA_ENC_COMP_STEP[0,AX1]=" in text and "reference point 10 mm" in text
    comp = controllers.module("siemens840d").load(tmp_path / "s" / "leg1.ini")
    assert float(comp.value_mm(10.0, 1)) == pytest.approx(
        float(comp.value_mm(10.0, -1)))  # one table: the same both ways


def test_a_table_too_long_for_heidenhain_is_refused_and_nothing_written(model_file, tmp_path, capsys):
    out = tmp_path / "hh"
    assert main(["table", str(model_file), "--out", str(out), "--format", "heidenhain", "--step", "0.5"]) == 2
    err = capsys.readouterr().err
    assert "256" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not out.exists() or list(out.iterdir()) == []
