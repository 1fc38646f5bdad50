"""A calibration sweep runs end to end on the simulated rig serving each real-drive profile:
`station sweep --config C` with `[drive] profile = "<path>"`, through the real Modbus client
(the profile's request lengths, frame gap, word order, scaling and set-point latch), recorded to
a session that names the profile, with errors of the size the simulated legs have."""

from __future__ import annotations


import numpy as np
import pytest

from drivers.modbus.profile import DEFAULT_PROFILE, DriveProfile
from procedures.io.recording.reader import read_session
from station.cli import main

REAL = sorted(p for p in DEFAULT_PROFILE.parent.glob("*.toml") if p.name != DEFAULT_PROFILE.name)


@pytest.mark.parametrize("path", REAL, ids=[p.stem for p in REAL])
def test_sweep_on_a_real_drive_profile(tmp_path, path, capsys):
    prof = DriveProfile.load(path)
    assert prof.table is None and prof.table_note  # the real drives hold no table, and say why
    cfg = tmp_path / "station.toml"
    cfg.write_text(f'[drive]\nurl = "sim"\nprofile = "{path}"\n[interferometer]\nport = "sim"\n')
    out = tmp_path / "run.h5"
    rc = main(["sweep", "--config", str(cfg), "--legs", "1-2", "--cycles", "1", "--n-targets", "5",
               "--dwell", "0", "--averaging", "0", "--out", str(out)])
    text = capsys.readouterr()
    assert rc == 0, text.out + text.err
    s = read_session(out)
    assert s.outcome == "completed"
    pts = s.points[s.points["index"] >= 0]
    assert sorted(set(pts["leg"].tolist())) == [1, 2]
    assert len(pts) == 2 * 2 * 5  # 2 legs, up and down, 5 targets
    # the legs' modelled errors are tens of um; a scaling or word-order slip would be mm
    assert np.all(np.abs(pts["error_um"]) < 200.0), pts["error_um"]
    assert np.all(np.isfinite(pts["error_um"]))
    assert str((s.station_config.get("drive") or {}).get("profile")) == str(path)
