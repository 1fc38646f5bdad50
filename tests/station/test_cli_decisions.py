"""Decisions through the command line: `station iso230 --config` and `station report` decide each
leg by ISO 14253-1 with the U of its budget, against the [tolerances] of its leg type."""

from __future__ import annotations

import json

import pytest

from station.cli import main
from tests.tooling import default_legs_points, write_identified_session


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    d = tmp_path_factory.mktemp("dec")
    return write_identified_session(d / "s.h5", default_legs_points(legs=(1,), cycles=3, step_mm=15.0))


def _config(tmp_path, e_um: float) -> str:
    p = tmp_path / "station.toml"
    p.write_text(f"[tolerances.HX300]\nE_um = {e_um}\nR_um = 1000\n")
    return str(p)


def test_iso230_decides_by_the_tolerance_of_the_leg_type(session, tmp_path, capsys):
    js = tmp_path / "v.json"
    assert main(["iso230", str(session), "--json", str(js)]) == 0  # no tolerance recorded: no decision
    assert "leg 1 (HX300), as-found: NO TOLERANCE STATED: no [tolerances.HX300]" in capsys.readouterr().out
    doc = json.loads(js.read_text())
    E, U = doc["legs"]["1"]["E"], doc["legs"]["1"]["U_um"]["E"]
    assert U > 0
    # limits placed around the value: each side of value +/- U decides as the rule says
    for limit, outcome in ((E + U + 0.01, "conforms"), (E, "cannot decide"), (E - U - 0.01, "does not conform")):
        assert main(["iso230", str(session), "--config", _config(tmp_path, round(limit, 6)),
                     "--json", str(js), "--force"]) == 0  # --force: the one overwrite rule
        out = capsys.readouterr().out
        d = json.loads(js.read_text())["decisions"]["legs"]["1"]
        assert d["values"]["E"]["outcome"] == outcome, d
        assert d["values"]["R"]["outcome"] == "conforms"
        assert f"  E: {outcome}" in out
        if outcome == "cannot decide":
            assert "U is dominated by" in d["values"]["E"]["reason"]


def test_bad_tolerance_refused_with_file_and_key(session, tmp_path, capsys):
    p = tmp_path / "bad.toml"
    p.write_text("[tolerances.HX300]\nE_um = 0\n")
    assert main(["iso230", str(session), "--config", str(p)]) == 2
    err = capsys.readouterr().err
    assert str(p) in err and "[tolerances.HX300] E_um = 0" in err and "Traceback" not in err


def test_report_carries_the_decisions(tmp_path, capsys):
    tol = {"HX300": {"as_found_um": {"E": 1000.0}, "as_left_um": {"E": 1000.0}, "source": "recorded"}}
    s = write_identified_session(tmp_path / "r.h5", default_legs_points(legs=(1,), cycles=3, step_mm=15.0),
                                 station_config={"tolerances": tol})
    assert main(["report", str(s), "--out", str(tmp_path / "rep")]) == 0
    assert "leg 1 (HX300), as-found: CONFORMS (recorded)" in capsys.readouterr().out
    iso = json.loads((tmp_path / "rep" / "iso230-2.json").read_text())
    assert iso["decisions"]["stage"] == "as_found"
    assert iso["decisions"]["legs"]["1"]["overall"] == "conforms"
    md = (tmp_path / "rep" / "iso230-2.md").read_text()
    assert "Leg 1: as-found decision: CONFORMS" in md
