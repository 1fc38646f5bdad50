"""End to end on the simulated rig, through the command line and the real protocols (Modbus TCP,
serial pty), at time scale 0: sweep, fit, table, push every swept leg, verify.

Acceptance (issue 4): the verified residual RMS is within 10 % of the plant's own noise floor on
every leg. Definitions (docs/compensation.md):

- verified residual RMS: RMS of the verification sweep's errors (measured minus commanded, table
  active) about their mean. The mean is the session's zero reference (the interferometer reads
  displacement from where it was zeroed, and with a table active the zero point itself is
  corrected), not a leg error, and no table can change it.
- the plant's own noise floor: the scatter no static table can remove, measured as the pooled
  pass-to-pass standard deviation over (target, direction) cells of the verification sweep
  itself (n - 1 per cell): measurement noise, pass-to-pass offsets, and the thermal and drift
  changes from pass to pass within the session. Measured on the same passes as the residual, so
  the ratio does not depend on how this session's ten or so pass offsets happened to fall
  (across plant and noise seeds it stays within 0.90-0.97 while the floor itself moves by up to
  25 % from session to session). Guarded, so a table cannot hide its own scatter in the floor:
  the within-pass scatter must match the calibration's within 20 %, the floor the calibration's
  within 35 %, and the floor must be at least the plant's white noise and pass offsets combined.

The verification runs with new measurement noise (another noise seed, same plant): with the
calibration's noise it would only replay the fit's own residuals.
"""

from __future__ import annotations

import json
import logging
import math

import numpy as np
import pytest

from drivers.plant.leg import default_leg_configs
from procedures.compensation.audit import read_entries
from procedures.metrology.thermal import error_basis
from procedures.io.recording.reader import read_session
from station.cli import main

LEGS = (1, 2, 3)
ACCEPT = 1.1


@pytest.fixture(autouse=True)
def _in_tmp(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def station(capsys, *argv: str) -> str:
    rc = main(list(argv))
    out, err = capsys.readouterr()
    assert rc == 0, f"station {' '.join(argv)} -> {rc}\n{out}\n{err}"
    return out


def floor_um(points: np.ndarray, leg: int) -> float:
    """Pooled pass-to-pass standard deviation over (target, direction) cells, um."""
    p = points[points["leg"] == leg]
    cells: dict[tuple[float, int], list[float]] = {}
    for t, d, e in zip(p["target_mm"], p["direction"], p["error_um"]):
        cells.setdefault((round(float(t), 6), int(d)), []).append(float(e))
    ss = sum(float(np.sum((np.array(v) - np.mean(v)) ** 2)) for v in cells.values() if len(v) > 1)
    dof = sum(len(v) - 1 for v in cells.values() if len(v) > 1)
    return math.sqrt(ss / dof)


def rms_about_mean_um(points: np.ndarray, leg: int) -> float:
    e = points[points["leg"] == leg]["error_um"]
    return float(np.sqrt(np.mean((e - e.mean()) ** 2)))


def test_sweep_fit_push_verify_reaches_the_noise_floor_on_every_leg(capsys):
    # calibration: uniform 6 mm targets (not a multiple of the 5 mm lead), 5 cycles, default plant
    # (backlash, lead, long-wave, wobble, heating, drift, noise, pass offsets), seed 0
    station(capsys, "sweep", "--sim", "--legs", "1-3", "--step", "6", "--out", "cal.h5")
    station(capsys, "fit", "cal.h5", "--out", "model.json")
    out = station(capsys, "table", "model.json", "--out", "table.csv")
    assert "leg 3: 31 points, -90 .. 90 mm step 6 mm" in out
    for leg in LEGS:
        out = station(capsys, "push", "table.csv", "--leg", str(leg), "--sim", "--yes")
        assert f"pushed: leg {leg} bank 1 active" in out
    main(["verify", "--leg", "1-3", "--sim", "--before", "cal.h5", "--table", "table.csv", "--out", "ver.h5",
          "--noise-seed", "1", "--json", "ver.json"])
    report, err = capsys.readouterr()

    # the figures are on the error normalised to 20 degC, as verify judges by default (its
    # report says so); the normalisation itself is tested in tests/procedures/metrology
    cal, ver = (error_basis(read_session(name))[0] for name in ("cal.h5", "ver.h5"))
    assert "error: normalised to 20 degC material temperature" in report
    figures = json.loads(open("ver.json").read())["legs"]
    plant = default_leg_configs(0)[0]
    white_and_offsets = math.hypot(plant.noise_um, plant.run_offset_um)
    for leg in LEGS:
        rms = rms_about_mean_um(ver, leg)
        floor = floor_um(ver, leg)
        floor_cal = floor_um(cal, leg)
        ratio = rms / floor
        f = figures[str(leg)]
        print(f"leg {leg}: verified residual RMS {rms:.4f} um, noise floor {floor:.4f} um (calibration "
              f"{floor_cal:.4f} um), ratio {ratio:.3f}; before {rms_about_mean_um(cal, leg):.4f} um")
        # the acceptance
        assert ratio <= ACCEPT, f"leg {leg}: residual RMS {rms:.4f} um is {ratio:.3f} x the noise floor {floor:.4f} um"
        # the floor is the plant's, not something the table added, and not below its noise
        within, within_cal = f["after"]["within_pass_um"], f["before"]["within_pass_um"]
        assert abs(within / within_cal - 1.0) <= 0.2, f"leg {leg}: within-pass {within:.4f} vs {within_cal:.4f} um"
        assert abs(floor / floor_cal - 1.0) <= 0.35, f"leg {leg}: floor {floor:.4f} vs calibration {floor_cal:.4f} um"
        # ... nor far below the plant's noise and pass offsets: the pass offsets are drawn once per
        # pass (five per direction here), so their sample spread has few degrees of freedom: for
        # 8 of them chi-square's 5th percentile gives sqrt(2.73 / 8) = 0.58 of the true spread,
        # hence 0.6 (the seeds are fixed: measured 0.71 on leg 1). The raw error's floor also held
        # the passes' thermal drift, which the normalisation removes.
        assert floor >= 0.6 * white_and_offsets
        # the criterion can fail: the uncompensated calibration is far above its floor
        assert rms_about_mean_um(cal, leg) / floor_cal > 2.0
        # the systematic deviation (ISO 230-2 E) is what the table removed
        assert f["after"]["iso230"]["E"] < 0.25 * f["before"]["iso230"]["E"]
        # the command reports the same figures
        assert f["after"]["rms_um"] == pytest.approx(rms, rel=1e-9)
        assert f["after"]["noise_floor_um"] == pytest.approx(floor, rel=1e-9)
        assert f["ratio"] == pytest.approx(ratio, rel=1e-9) and f["passed"] is True
        assert f"Leg {leg}: compensated error" in report
    assert report.count("-> PASS (limit 1.1)") == len(LEGS)
    entries, problems = read_entries("runs/audit.jsonl")
    assert problems == []
    assert sorted(e.leg for e in entries if e.action == "push" and e.outcome == "ok") == list(LEGS)
    verified = [e for e in entries if e.action == "verify"]
    assert [(e.leg, e.outcome) for e in verified] == [(leg, "completed") for leg in LEGS]
    assert all(e.details["session"] == "ver.h5" and e.table_sha256 for e in verified)
