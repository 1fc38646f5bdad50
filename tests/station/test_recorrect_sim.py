"""`station recorrect` end to end on the simulated rig (real Modbus TCP and pty): a sweep whose
interferometer compensated with an air temperature sensor reading 1 K high, re-corrected with
--air-temp-offset-c -1, gives the readings of the same sweep with a good sensor."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from procedures.metrology.air import edlen
from procedures.acquisition.plans import SweepPlan
from procedures.io.recording.reader import read_session
from station.cli import main
from station.services.config import StationConfig
from station.services.jobs import run_sweep
from station.services.wiring import open_rig

PLAN = SweepPlan("test", (-90.0, -45.0, 0.0, 45.0, 90.0), cycles=2, legs=(1,), dwell_s=1.0)


@pytest.fixture(autouse=True)
def _quiet():
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def _sweep(out, sensor_offset_c: float) -> None:
    with open_rig(StationConfig(), legs=(1,), time_scale=0.0) as rig:
        # the instrument's Edlen compensation, done with the faulty sensor's temperature
        rig.sim.laser_server.set_air_sensor_offset(sensor_offset_c, index=lambda t, p, h: edlen(632.991, t, p, h))
        assert run_sweep(rig, PLAN, out, StationConfig()).outcome == "completed"


def test_a_wrong_air_sensor_is_undone_by_recorrect(tmp_path, capsys):
    good, bad, fixed = tmp_path / "good.h5", tmp_path / "bad.h5", tmp_path / "fixed.h5"
    _sweep(good, 0.0)
    _sweep(bad, 1.0)
    g, b = read_session(good).points, read_session(bad).points
    assert np.allclose(b["air_temp_c"] - g["air_temp_c"], 1.0)
    wrong_um = b["error_um"] - g["error_um"]
    # the instrument divided by too small an index: +0.93 ppm, 0.084 um at +90 mm
    at_end = np.argmax(g["target_mm"])
    assert 0.075 < wrong_um[at_end] < 0.095
    assert main(["recorrect", str(bad), "--out", str(fixed), "--equation", "edlen", "--air-temp-offset-c", "-1"]) == 0
    f = read_session(fixed).points
    left_um = f["error_um"] - g["error_um"]
    with capsys.disabled():
        print(f"\nwrong sensor: error off by up to {np.max(np.abs(wrong_um)):.4f} um; after recorrect "
              f"{np.max(np.abs(left_um)):.6f} um")
    assert np.max(np.abs(left_um)) < 0.002 * np.max(np.abs(wrong_um))
    assert np.allclose(f["air_temp_c"], g["air_temp_c"], atol=1e-9)
