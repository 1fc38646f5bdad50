"""Re-correction of the air refractive index (procedures.metrology.recorrect, `station recorrect`):
the size and sign of a sensor-offset correction on a simulated session over the real protocols,
the dead path, the instrument's modes, refusals, and the original left untouched."""

from __future__ import annotations

import hashlib
import json
import logging
from pathlib import Path

import h5py
import numpy as np
import pytest

from procedures.vocabulary import InputError
from procedures.metrology.air import ciddor, edlen
from procedures.metrology.recorrect import RecorrectOptions, recorrect_points
from procedures.io.recording.columns import read_point_column
from procedures.io.recording.reader import read_session
from procedures.io.recording.schema import POINT_DTYPE
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


def _points(temps_c, measured_mm) -> np.ndarray:
    pts = np.zeros(len(temps_c), POINT_DTYPE)
    pts["index"] = np.arange(len(temps_c))
    pts["leg"], pts["run"], pts["direction"] = 1, 1, 1
    pts["target_mm"] = pts["commanded_mm"] = measured_mm
    pts["measured_mm"] = measured_mm
    pts["error_um"] = 0.0
    pts["air_temp_c"], pts["air_pressure_hpa"], pts["humidity_pct"] = temps_c, 1013.25, 50.0
    return pts


AUTO = {"mode": "AUTO", "equation": "CIDDOR", "wavelength_nm": 632.991, "co2_ppm": 450.0, "dead_path_mm": 0.0}


def test_dead_path_adds_back_what_warmer_air_took_from_it():
    pts = _points([20.0, 21.0], [0.0, 0.0])  # zeroed at 20 degC; 1 K warmer later, leg not moved
    r = recorrect_points(pts, AUTO, RecorrectOptions(equation="ciddor", dead_path_mm=1000.0))
    n0, n1 = ciddor(632.991, 20.0, 101325, 50), ciddor(632.991, 21.0, 101325, 50)
    assert r.points["error_um"][0] == 0.0
    assert r.points["error_um"][1] == pytest.approx(1000.0 * (n0 - n1) / n1 * 1000.0, rel=1e-9)
    assert 0.85 < r.points["error_um"][1] < 1.0  # about 0.93 um per metre of dead path per kelvin


def test_instrument_modes_manual_and_off():
    pts = _points([20.0, 20.0], [0.0, 100.0])
    manual = {**AUTO, "mode": "MANUAL", "air_temp_c": 22.0, "air_pressure_hpa": 1013.25, "humidity_pct": 50.0}
    r = recorrect_points(pts, manual, RecorrectOptions(equation="ciddor"))
    n_i, n = ciddor(632.991, 22.0, 101325, 50), ciddor(632.991, 20.0, 101325, 50)
    assert r.points["error_um"][1] == pytest.approx(100.0 * (n_i / n - 1) * 1000.0, rel=1e-9)
    off = {"mode": "OFF", "equation": "NONE", "wavelength_nm": 632.991, "co2_ppm": None, "dead_path_mm": 0.0}
    r = recorrect_points(pts, off, RecorrectOptions(equation="ciddor"))
    assert r.points["error_um"][1] == pytest.approx(100.0 * (1 / n - 1) * 1000.0, rel=1e-9)  # about -27 um
    # another vacuum wavelength scales the reading by lambda / lambda_i
    r = recorrect_points(pts, AUTO, RecorrectOptions(equation="ciddor", wavelength_nm=632.991 * (1 + 1e-6)))
    assert r.points["error_um"][1] == pytest.approx(0.1, rel=1e-4)  # (+ the index's dispersion over 0.6 pm)


def test_sessions_without_the_instruments_record_and_bad_options_are_refused(capsys):
    Path("in.csv").write_text("leg,run,direction,target_mm,error_um,air_temp_c\n1,1,1,0,0.5,20\n1,1,1,10,0.6,20\n")
    assert main(["import", "in.csv", "--out", "imp.h5"]) == 0
    capsys.readouterr()
    assert main(["recorrect", "imp.h5", "--out", "r.h5"]) == 2
    err = capsys.readouterr().err
    assert "imp.h5: cannot re-correct: the session does not record how the interferometer compensated" in err
    assert not Path("r.h5").exists()
    pts = _points([20.0], [1.0])
    for opts, name in ((RecorrectOptions(humidity_pct=101.0), "--humidity-pct"),
                       (RecorrectOptions(wavelength_nm=10600.0), "--wavelength-nm"),
                       (RecorrectOptions(pressure_pa=1013.25), "--pressure-pa"),
                       (RecorrectOptions(equation="lorentz"), "--equation")):
        with pytest.raises(InputError, match=name):
            recorrect_points(pts, AUTO, opts)
    pts["air_pressure_hpa"][0] = np.nan
    with pytest.raises(InputError, match="row 0, field air_pressure_hpa: not recorded"):
        recorrect_points(pts, AUTO, RecorrectOptions())
