"""Re-correction of the air refractive index (procedures.metrology.recorrect): the dead path, the
instrument's modes and the refusals of bad options (the size and sign of a sensor-offset
correction on a simulated session, through `station recorrect`: tests/station/test_cli_recorrect.py)."""

from __future__ import annotations

import numpy as np
import pytest

from procedures.vocabulary import InputError
from procedures.metrology.air import ciddor
from procedures.metrology.recorrect import RecorrectOptions, recorrect_points
from procedures.io.recording.schema import POINT_DTYPE


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


def test_bad_options_and_points_without_a_reading_are_refused():
    """(A session without the instrument's record: tests/station/test_cli_recorrect.py.)"""
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
