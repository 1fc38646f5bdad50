"""`station verify` decides each leg as left: the verification's ISO 230-2 values with U against
the as-left limits of its leg type (simulated rig, real Modbus and pty)."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest

from procedures.compensation.table import CompTable, LegTable, table_csv_text
from procedures.io.recording.reader import read_session
from station.services.report_jobs import session_decisions
from station.cli import main


@pytest.fixture(autouse=True)
def _in_tmp(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def test_verify_prints_and_writes_the_as_left_decisions(capsys):
    x = [-90.0 + 6.0 * i for i in range(31)]
    Path("t.csv").write_text(table_csv_text(CompTable({3: LegTable(3, -90.0, 6.0, tuple(0.0 for _ in x),
                                                                   tuple(0.0 for _ in x))})))
    Path("station.toml").write_text(
        '[drive]\nurl = "sim"\n[interferometer]\nport = "sim"\n[legs.3]\nserial = "HX-0042"\nleg_type = "HX300"\n'
        # as found nothing could fail; as left E is held to 0.001 um: no leg is proven to conform
        "[tolerances.HX300]\nE_um = 1000\nR_um = 1000\n[tolerances.HX300.as_left]\nE_um = 0.001\n")
    # the leg as found, before any table: what a certificate is issued from
    assert main(["sweep", "--config", "station.toml", "--legs", "3", "--step", "15", "--cycles", "2",
                 "--time-scale", "0", "--out", "c.h5"]) == 0
    assert main(["push", "t.csv", "--leg", "3", "--config", "station.toml", "--yes"]) == 0
    capsys.readouterr()
    main(["verify", "--leg", "3", "--config", "station.toml", "--cycles", "2", "--noise-seed", "5",
          "--out", "v.h5", "--json", "v.json"])
    out = capsys.readouterr().out
    assert "As-left decisions (ISO 14253-1" in out
    assert "leg 3 (HX300), as-left: DOES NOT CONFORM" in out
    d = json.loads(Path("v.json").read_text())["decisions"]
    assert d["stage"] == "as_left"
    leg = d["legs"]["3"]
    assert leg["values"]["E"]["limit_um"] == 0.001 and leg["values"]["E"]["outcome"] == "does not conform"
    assert leg["values"]["R"]["limit_um"] == 1000 and leg["values"]["R"]["outcome"] == "conforms"
    # decided on the points as measured, not read back: the same decisions as the recording's
    recorded = session_decisions(read_session("v.h5"), stage="as_left")["decisions"]
    assert d == json.loads(json.dumps(recorded)) and leg["values"]["E"]["value_um"] > 0
    # a certificate of the verified leg checks that the table active as left is the table given
    assert main(["certificate", "c.h5", "--as-left", "v.h5", "--table", "t.csv", "--config", "station.toml"]) == 0
    (cert,) = Path("runs/certificates").glob("*_r1.json")
    table = json.loads(cert.read_text())["compensation_table"]
    assert table["matches_as_left"] is True and table["active_as_left_sha256"] == table["leg_rows_sha256"]
    x2 = [1.0 for _ in x]
    Path("other.csv").write_text(table_csv_text(CompTable({3: LegTable(3, -90.0, 6.0, tuple(x2), tuple(x2))})))
    capsys.readouterr()
    assert main(["certificate", "c.h5", "--as-left", "v.h5", "--table", "other.csv", "--config", "station.toml"]) == 0
    assert "the table active in the as-left session is NOT the --table given" in capsys.readouterr().out
