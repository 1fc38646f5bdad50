"""`station verify` through station.cli.main on the simulated rig: refusals before anything moves
(no table, not the expected table, a leg the calibration lacks), and a wrong table caught."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest

from procedures.compensation.audit import read_entries
from procedures.compensation.table import CompTable, LegTable, table_csv_text
from station.cli import main


@pytest.fixture(autouse=True)
def _in_tmp(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def station(capsys, *argv: str) -> tuple[int, str, str]:
    rc = main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


def _csv(path: str, leg: int, slope_um_per_mm: float) -> str:
    x = [-90.0 + 6.0 * i for i in range(31)]
    t = LegTable(leg, -90.0, 6.0, tuple(slope_um_per_mm * v for v in x), tuple(slope_um_per_mm * v + 0.5 for v in x))
    Path(path).write_text(table_csv_text(CompTable({leg: t})))
    return path


def _verify_entries():
    entries, _ = read_entries("runs/audit.jsonl")
    return [e for e in entries if e.action == "verify"]


def test_verify_refuses_a_leg_without_a_table(capsys):
    rc, out, err = station(capsys, "verify", "--leg", "2", "--sim", "--out", "v.h5", "--noise-seed", "1")
    assert rc == 2 and "leg 2: the drive's active table (bank 0) is empty; push a table first" in err
    assert not Path("v.h5").exists()
    assert [(e.leg, e.outcome) for e in _verify_entries()] == [(2, "refused")]


def test_verify_refuses_when_the_active_table_is_not_the_named_one(capsys):
    _csv("a.csv", 1, 0.01)
    _csv("b.csv", 1, 0.02)
    assert station(capsys, "push", "a.csv", "--leg", "1", "--sim", "--yes")[0] == 0
    rc, out, err = station(capsys, "verify", "--leg", "1", "--sim", "--table", "b.csv", "--out", "v.h5")
    assert rc == 2 and "is not the leg's rows of b.csv" in err and "push it first" in err
    assert not Path("v.h5").exists()


def test_verify_refuses_a_leg_the_calibration_does_not_have(capsys):
    assert station(capsys, "sweep", "--sim", "--legs", "1", "--step", "45", "--cycles", "2", "--out", "cal.h5")[0] == 0
    rc, out, err = station(capsys, "verify", "--leg", "1-2", "--sim", "--before", "cal.h5", "--out", "v.h5")
    assert rc == 2 and "cal.h5: no calibration points for leg(s) [2]" in err


def test_a_wrong_table_is_caught(capsys):
    # a 20 um/m slope the leg does not have: the verification sees it and exits 1
    _csv("wrong.csv", 3, 0.02)
    assert station(capsys, "push", "wrong.csv", "--leg", "3", "--sim", "--yes")[0] == 0
    rc, out, err = station(capsys, "verify", "--leg", "3", "--sim", "--cycles", "2", "--noise-seed", "5",
                           "--out", "v.h5", "--json", "v.json")
    assert rc == 1 and "leg(s) [3]: residual RMS above 1.1 x the noise floor" in err
    assert "[no calibration session given: after only]" in out and "-> ABOVE (limit 1.1)" in out
    assert "noise seed 5" in out
    figures = json.loads(Path("v.json").read_text())["legs"]["3"]
    assert figures["passed"] is False and figures["ratio"] > 2 and figures["before"] is None
    assert figures["after"]["n_points"] == 2 * 2 * 11  # the ISO 230-2 plan: 11 targets, 2 cycles
    (entry,) = _verify_entries()
    assert entry.outcome == "completed" and entry.details["passed"] is False and "above" in entry.message
