"""`station recorrect` (procedures.metrology.recorrect on a session file): a sensor offset corrected
with the right size and sign in a new file that says what was done, the original unchanged; a
session that does not record how the interferometer compensated is refused, nothing written."""

from __future__ import annotations

import hashlib
import json
import logging
from pathlib import Path

import h5py
import numpy as np
import pytest

from procedures.io.recording.columns import read_point_column
from procedures.io.recording.reader import read_session
from procedures.metrology.air import edlen
from station.cli import main


@pytest.fixture(autouse=True)
def _in_tmp(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def _sha(path: str) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def test_a_sensor_offset_is_corrected_with_the_right_size_and_sign(capsys):
    assert main(["sweep", "--sim", "--legs", "1-2", "--step", "45", "--cycles", "1", "--out", "s.h5"]) == 0
    before = _sha("s.h5")
    src = read_session("s.h5")
    rec = json.loads(src.devices["laser_air_compensation"])
    assert rec["mode"] == "AUTO" and rec["equation"] == "EDLEN" and rec["wavelength_nm"] == 632.991
    # the air sensor read 1 K high: the air was cooler, denser, its index higher by ~0.93 ppm; the
    # instrument divided by too small an index, so every displacement read too long
    assert main(["recorrect", "s.h5", "--out", "r.h5", "--equation", "edlen", "--air-temp-offset-c", "-1"]) == 0
    out = capsys.readouterr().out
    assert "written: r.h5 (the original s.h5 is unchanged" in out
    assert _sha("s.h5") == before
    new = read_session("r.h5")
    p = src.points
    n_i = edlen(632.991, p["air_temp_c"], p["air_pressure_hpa"] * 100, p["humidity_pct"])
    n = edlen(632.991, p["air_temp_c"] - 1.0, p["air_pressure_hpa"] * 100, p["humidity_pct"])
    expected = p["measured_mm"] * (n_i / n - 1.0) * 1000.0
    change = new.points["error_um"] - p["error_um"]
    assert np.max(np.abs(change - expected)) < 1e-9
    far = np.argmax(p["measured_mm"])
    assert change[far] < 0 and abs(change[far]) == pytest.approx(0.93e-6 * p["measured_mm"][far] * 1000, rel=0.05)
    assert np.allclose(new.points["air_temp_c"], p["air_temp_c"] - 1.0)
    # the new file says what was done
    with h5py.File("r.h5", "r") as f:
        what = json.loads(f["meta"].attrs["recorrection"])
    assert what["source"] == {"path": "s.h5", "sha256": before}
    assert what["equation"] == "edlen" and what["air_temp_offset_c"] == -1.0 and what["instrument"] == rec
    assert json.loads(new.devices["laser_air_compensation_original"]) == rec
    assert json.loads(new.devices["laser_air_compensation"])["mode"] == "STATION"
    assert np.all(read_point_column("r.h5", "co2_ppm") == 450.0)
    # re-correcting the new file back gives the original readings
    assert main(["recorrect", "r.h5", "--out", "back.h5", "--equation", "edlen", "--air-temp-offset-c", "+1"]) == 0
    assert np.max(np.abs(read_session("back.h5").points["error_um"] - p["error_um"])) < 1e-9


def test_a_session_without_the_instruments_record_is_refused(capsys):
    Path("in.csv").write_text("leg,run,direction,target_mm,error_um,air_temp_c\n1,1,1,0,0.5,20\n1,1,1,10,0.6,20\n")
    assert main(["import", "in.csv", "--out", "imp.h5"]) == 0
    capsys.readouterr()
    assert main(["recorrect", "imp.h5", "--out", "r.h5"]) == 2
    err = capsys.readouterr().err
    assert "imp.h5: cannot re-correct: the session does not record how the interferometer compensated" in err
    assert not Path("r.h5").exists()
