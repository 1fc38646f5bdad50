"""`station report` end to end on the simulated rig (real Modbus TCP server and pty): the sweep
records the instrument, the drives, their compensation state and the air compensation; the ISO
230-2 test report states them, with every value's expanded uncertainty."""

from __future__ import annotations

import json

import pytest

from procedures.reporting import iso230
from procedures.metrology.thermal import normalise_session
from procedures.io.recording.reader import read_session
from station.cli import main

pytestmark = pytest.mark.timeout(180)


def test_sweep_then_report_states_what_iso_230_2_asks(tmp_path, capsys):
    session = tmp_path / "cal.h5"
    assert main(["sweep", "--sim", "--legs", "1", "--out", str(session)]) == 0
    out = tmp_path / "rep"
    assert main(["report", str(session), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "ISO 230-2 (normalised error), U with k = 2" in text
    d = json.loads((out / "iso230-2.json").read_text())
    s = read_session(session)
    # the values are those of the normalised error, each with a positive U
    iso = iso230.evaluate(normalise_session(s.points, s.station_config).points)[1]
    leg = d["legs"]["1"]
    for name, v in leg["values"].items():
        assert v["value_um"] == pytest.approx(iso.values[name], abs=1e-9)
        assert v["U_um"] > 0, name
        assert f"{name} {v['value_um']:.3f} +/- {v['U_um']:.3f}" in text or name not in "EMABR"
    ident = d["identification"]
    assert ident["instrument"]["reported_identity"] == s.devices["interferometer"]
    assert ident["legs"]["1"] == s.devices["leg1"]
    assert leg["compensation"] == s.devices["leg1_compensation"]
    assert "equation" in ident["air_compensation"], s.devices  # the simulated laser reports its compensation
    assert d["test_parameters"]["targets_mm"] == pytest.approx(s.plan["targets_mm"])
    assert d["test_parameters"]["cycles"] == s.plan["cycles"]
    assert (out / "iso230-2.pdf").read_bytes().startswith(b"%PDF")
