"""`station import`, `station export`, `station iso230` through station.cli.main."""

from __future__ import annotations

import csv
import json

import pytest

from procedures.reporting.iso230 import VALUE_NAMES
from procedures.io.recording.reader import read_session
from station.cli import main


def test_import_export_iso230_round_trip(shared_data, tmp_path, capsys):
    src = shared_data / "examples" / "two-legs-backlash-thermal.csv"
    h5, back, js = tmp_path / "s.h5", tmp_path / "back.csv", tmp_path / "iso.json"
    assert main(["import", str(src), "--out", str(h5), "--operator", "kim"]) == 0
    out = capsys.readouterr().out
    n_rows = sum(1 for _ in open(src)) - 1
    assert f"imported {n_rows} points (legs 1, 2" in out and "air_temp_c" in out
    assert read_session(h5).attrs["operator"] == "kim"

    assert main(["export", str(h5), "--out", str(back)]) == 0
    assert f"exported {n_rows} points" in capsys.readouterr().out
    with open(src, newline="") as a, open(back, newline="") as b:
        assert [list(map(float, r)) for r in list(csv.reader(a))[1:]] == \
               [list(map(float, r)) for r in list(csv.reader(b))[1:]]

    assert main(["iso230", str(h5), "--json", str(js)]) == 0
    out = capsys.readouterr().out
    assert "Leg 1: ISO 230-2" in out and "Leg 2: ISO 230-2" in out and "repeatability" in out
    assert "nan" not in out.lower()
    data = json.loads(js.read_text())
    assert sorted(data["legs"]) == ["1", "2"] and data["source"]["sha256"] == read_session(h5).sha256
    for leg in data["legs"].values():
        assert set(VALUE_NAMES) <= set(leg)
        # four cycles: all computable (the notes say ISO asks for five)
        assert all(isinstance(leg[n], float) for n in VALUE_NAMES)
        assert any("asks for 5 approaches" in n for n in leg["notes"])


def test_iso230_prints_reasons_for_a_messy_file(shared_data, tmp_path, capsys):
    h5 = tmp_path / "r.h5"
    assert main(["import", str(shared_data / "real" / "ecmccomgui_report_3.csv"), "--out", str(h5)]) == 0
    capsys.readouterr()
    assert main(["iso230", str(h5)]) == 0
    out = capsys.readouterr().out
    assert "not computed (E, M, A, B, B_mean, R): backward targets differ from forward targets by 0.2 mm" in out
    assert "nan" not in out.lower()


def test_bad_csv_exits_2_with_one_line_naming_the_row_and_writes_nothing(tmp_path, capsys):
    src = tmp_path / "bad.csv"
    src.write_text("leg,run,direction,target_mm,error_um\n1,1,1,0,0.1\n1,1,-1,5,0.2\n")
    out = tmp_path / "s.h5"
    assert main(["import", str(src), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert err.startswith("station import: error: ") and "line 3, field direction: run 1 of leg 1 mixes" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.csv"]


def test_existing_outputs_need_force(shared_data, tmp_path, capsys):
    src = shared_data / "real" / "ecmccomgui_report_7.csv"
    h5, back = tmp_path / "s.h5", tmp_path / "b.csv"
    assert main(["import", str(src), "--out", str(h5)]) == 0
    assert main(["import", str(src), "--out", str(h5)]) == 2
    assert "exists; add --force to replace it" in capsys.readouterr().err
    assert main(["import", str(src), "--out", str(h5), "--force"]) == 0
    back.write_text("keep me")
    assert main(["export", str(h5), "--out", str(back)]) == 2
    assert back.read_text() == "keep me"
    assert main(["export", str(h5), "--out", str(back), "--force"]) == 0


@pytest.mark.parametrize("command", ["export", "iso230"])
def test_commands_refuse_a_file_that_is_not_a_session(tmp_path, capsys, command):
    not_h5 = tmp_path / "x.h5"
    not_h5.write_text("leg,run\n")
    argv = [command, str(not_h5)] + (["--out", str(tmp_path / "o.csv")] if command == "export" else [])
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "not an HDF5 file" in err and "Traceback" not in err
    assert not (tmp_path / "o.csv").exists()
