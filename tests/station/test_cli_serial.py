"""Leg serials on the command line: `station sweep --serial 3=HX-0042` / `--serials FILE` /
[legs.N] serial recorded in the session (schema 1.1) with the station, operator, instrument and
each drive's identity read over Modbus; carried by `fit` and `table`; `station push` refusing a
table made for another serial, naming both, with the simulated drive's table memory unchanged."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest

from procedures.compensation.audit import read_entries
from procedures.io.recording.reader import read_identity
from procedures.compensation.table import read_table_csv
from station.cli import main

SWEEP = ("sweep", "--cycles", "1", "--n-targets", "5")  # the simulated rig unless --config


@pytest.fixture(autouse=True)
def _in_tmp(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def station(capsys, *argv: str) -> tuple[int, str, str]:
    rc = main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


def _config(path: str, legs: str = "", metrology: str = "") -> str:
    Path(path).write_text(f'[station]\nid = "bench-b"\noperator = "ana"\n[drive]\nurl = "sim"\n'
                          f'[interferometer]\nport = "sim"\n[metrology]\n{metrology}\n{legs}')
    return path


def test_serials_from_options_file_and_config_are_recorded(capsys):
    Path("serials.csv").write_text("leg,serial,part_number,leg_type,screw_lot\n1,HX-0001,P-1,HX300,L9\n2,HX-0002,,,\n")
    cfg = _config("c.toml", '[legs.2]\nserial = "HX-CFG"\nleg_type = "HX300"\n[legs.3]\nscrew_lot = "L3"\n',
                  'model = "XL-80"\nserial = "L123"\ncalibration_date = "2026-01-10"\ncalibration_due = "2999-01-10"')
    rc, out, err = station(capsys, *SWEEP, "--config", cfg, "--legs", "1-3", "--out", "s.h5",
                           "--serials", "serials.csv", "--serial", "3=HX-0042")
    assert rc == 0, err
    ident = read_identity("s.h5")
    assert ident.station.id == "bench-b" and ident.operator == "ana" and ident.software_version
    # the file overrides the config field by field; --serial overrides both
    assert (ident.leg(1).serial, ident.leg(1).part_number, ident.leg(1).screw_lot) == ("HX-0001", "P-1", "L9")
    assert (ident.leg(2).serial, ident.leg(2).leg_type) == ("HX-0002", "HX300")
    assert (ident.leg(3).serial, ident.leg(3).screw_lot) == ("HX-0042", "L3")
    for leg in (1, 2, 3):  # the simulated drive answers Read Device Identification
        drive = ident.leg(leg).drive
        assert drive.source == "modbus-device-id" and drive.vendor == "StationSim" and drive.serial == f"SIM-000{leg}"
    assert ident.instrument.model == "XL-80" and ident.instrument.traceable and ident.warnings == ()
    # a list typed by hand (no integrity record) is read whole and said to be unverified, once
    warnings = [line for line in (out + err).splitlines() if "warning:" in line]
    assert len(warnings) == 1 and warnings[0].startswith("warning: serials.csv has no integrity record") \
        and "unverified" in warnings[0], warnings


def test_laser_past_due_or_without_due_date_is_warned_and_recorded(capsys):
    cfg = _config("c.toml", metrology='calibration_due = "2020-01-31"')
    rc, _, out = station(capsys, *SWEEP, "--config", cfg, "--out", "a.h5")  # progress goes to stderr
    assert rc == 0
    assert "warning: the laser: calibration was due 2020-01-31" in out and "not traceable" in out
    ident = read_identity("a.h5")
    assert not ident.instrument.traceable and "2020-01-31" in ident.warnings[0]
    rc, _, out = station(capsys, *SWEEP, "--out", "b.h5")
    assert "warning: the laser: calibration due date not stated: result not traceable" in out
    assert read_identity("b.h5").warnings == ("the laser: calibration due date not stated: result not traceable",)


@pytest.mark.parametrize("content, where", [
    ("leg,serial\n1,HX-1\n7,HX-7\n", "serials.csv: row 3, field leg: leg '7' is not a leg number 1..6"),
    ("leg,serial\n1,HX 1\n", "serials.csv: row 2, field serial: serial 'HX 1' is not a serial number"),
    ("leg,serial\n1,HX-1\n1,HX-2\n", "serials.csv: row 3, field leg: leg 1 is listed twice"),
    ("leg,serial,colour\n1,HX-1,red\n", "serials.csv: row 1 (header)"),
    ("leg,serial\n1,HX-1,extra\n", "serials.csv: row 2: 3 fields, the header has 2"),
])
def test_a_bad_serials_file_is_refused_before_anything_moves(capsys, content, where):
    Path("serials.csv").write_text(content)
    rc, out, err = station(capsys, *SWEEP, "--out", "s.h5", "--serials", "serials.csv")
    assert rc == 2 and where in err and err.count("\n") == 1, err
    assert not Path("s.h5").exists() and "rig:" not in out


@pytest.mark.parametrize("arg, reason", [("3", "write LEG=SERIAL"), ("9=HX-1", "not a leg number"),
                                         ("2=", "not a serial number")])
def test_a_bad_serial_option_is_refused(capsys, arg, reason):
    rc, _, err = station(capsys, *SWEEP, "--out", "s.h5", "--serial", arg)
    assert rc == 2 and reason in err and not Path("s.h5").exists()


def test_config_refuses_a_serial_that_is_not_text(capsys):
    Path("c.toml").write_text('[drive]\nurl = "sim"\n[interferometer]\nport = "sim"\n[legs.2]\nserial = 42\n')
    rc, _, err = station(capsys, *SWEEP, "--config", "c.toml", "--out", "s.h5")
    assert rc == 2 and "c.toml: [legs.2] serial: expected text" in err


def test_table_for_another_serial_is_refused_by_push_naming_both(capsys):
    rc, _, err = station(capsys, "sweep", "--legs", "1", "--out", "cal.h5", "--serial", "1=HX-0042")  # 5 cycles: fit needs them
    assert rc == 0, err
    assert station(capsys, "fit", "cal.h5", "--out", "m.json")[0] == 0
    assert json.loads(Path("m.json").read_text())["identity"]["legs"]["1"]["serial"] == "HX-0042"
    assert station(capsys, "table", "m.json", "--out", "t.csv")[0] == 0
    assert dict(read_table_csv("t.csv").serials) == {1: "HX-0042"}
    nv = Path("runs/sim-drive-nv.json")
    before = nv.read_bytes() if nv.exists() else None
    cfg = _config("wrong.toml", '[legs.1]\nserial = "HX-0077"\n')
    rc, out, err = station(capsys, "push", "t.csv", "--leg", "1", "--config", cfg, "--yes")
    assert rc == 2 and "HX-0042" in err and "HX-0077" in err and "Nothing was written" in err
    assert (nv.read_bytes() if nv.exists() else None) == before
    (entry,) = read_entries("runs/audit.jsonl")[0]
    assert (entry.outcome, entry.leg_serial, entry.station_id) == ("refused", "HX-0077", "bench-b")
    # the right leg takes it, and the audit entry names its serial
    rc, out, err = station(capsys, "push", "t.csv", "--leg", "1", "--config", _config("right.toml",
                           '[legs.1]\nserial = "HX-0042"\n'), "--yes")
    assert rc == 0, err
    assert "serial:   leg serial HX-0042, the table was made for it" in out
    assert read_entries("runs/audit.jsonl")[0][-1].leg_serial == "HX-0042"


def test_serials_are_refused_on_a_resume(capsys):
    rc, _, err = station(capsys, "sweep", "--resume", "any.h5", "--serial", "1=HX-1")
    assert rc == 2 and "a resumed session keeps the identity it was created with" in err
