"""Acceptance (issue 14, item 2): station-side compensation on the simulated rig whose drive
profile declares NO table ([table] kind = "none"), target `station`, through the command line,
the real Modbus TCP server on 127.0.0.1 and the real pty:

- push -> verify gives a verified residual RMS within 1.1 x the noise floor (figures printed);
- rollback restores the previous state (the store's active bank and table, the audit entries);
- a SIGKILL during a sweep leaves the session file stating which table was applied;
- target `drive` on that drive is refused naming `station` and `controller`, nothing written;
  target `controller` is refused by push naming the export.
"""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import h5py
import pytest

from procedures.compensation.applied_table import recorded_tables
from procedures.compensation.audit import read_entries
from procedures.io.recording.reader import read_session
from station.cli import main

REPO = Path(__file__).resolve().parents[2]
ACCEPT = 1.1


def no_table_profile(path: Path) -> Path:
    """The built-in profile with its [table] replaced by `kind = "none"` (a drive without a table)."""
    src = (REPO / "drivers/modbus/profiles/default.toml").read_text()
    head = src[: src.index("\n[table]")]
    path.write_text(head + '\n[table]\nkind = "none"\nnote = "test drive: no compensation table over Modbus"\n')
    return path


def config(path: Path, profile: Path, target: str = "station", legs: str = "") -> Path:
    path.write_text(f"""[station]
recordings_dir = "runs"
[drive]
url = "sim"
profile = "{profile}"
[interferometer]
port = "sim"
[compensation]
target = "{target}"
{legs}
""")
    return path


@pytest.fixture(autouse=True)
def _in_tmp(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def station(capsys, *argv: str, rc: int = 0) -> tuple[str, str]:
    got = main(list(argv))
    out, err = capsys.readouterr()
    assert got == rc, f"station {' '.join(argv)} -> {got}\n{out}\n{err}"
    return out, err


def _store(tmp_path: Path) -> dict:
    return json.loads((tmp_path / "runs" / "station-tables.json").read_text())


def test_station_target_push_verify_rollback_and_kill(capsys, tmp_path):
    profile = no_table_profile(tmp_path / "notable.toml")
    cfg = str(config(tmp_path / "station.toml", profile))
    # calibration on the drive without a table (the store is empty: nothing is applied)
    station(capsys, "sweep", "--config", cfg, "--legs", "1", "--step", "6", "--time-scale", "0", "--out", "cal.h5")
    station(capsys, "fit", "cal.h5", "--out", "model.json")
    out, _ = station(capsys, "table", "model.json", "--out", "table.csv", "--profile", str(profile))
    assert "holds no compensation table; the table is checked for the station's table store" in out

    out, _ = station(capsys, "push", "table.csv", "--leg", "1", "--config", cfg, "--yes")
    assert "compensation target of leg 1: station (runs/station-tables.json)" in out
    assert "target:   station" in out
    pushed_sha = out.split("table sha256 ")[-1].split(";")[0]
    leg1 = _store(tmp_path)["legs"]["1"]
    assert leg1["active_bank"] == 1 and leg1["banks"][1]["sha256"] == pushed_sha and leg1["enabled"] is True
    assert leg1["banks"][0]["error_fwd_um"] == []  # the previous (empty) table, kept for the rollback

    out, _ = station(capsys, "verify", "--leg", "1", "--config", cfg, "--before", "cal.h5", "--table", "table.csv",
                     "--noise-seed", "1", "--time-scale", "0", "--out", "ver.h5", "--json", "ver.json")
    figures = json.loads(Path("ver.json").read_text())["legs"]["1"]
    ratio = figures["ratio"]
    rms, floor = figures["after"]["rms_um"], figures["after"]["noise_floor_um"]
    before_rms = figures["before"]["rms_um"]
    with capsys.disabled():
        print(f"\nstation-side compensation, leg 1 (drive without a table): residual RMS {before_rms:.3f} -> {rms:.3f} um, "
              f"noise floor {floor:.3f} um, ratio {ratio:.3f} (limit {ACCEPT})")
    assert ratio <= ACCEPT, out
    assert rms < 0.5 * before_rms  # the table did the work: not a floor that grew
    ver = read_session("ver.h5")
    applied = recorded_tables(ver.devices)[1]
    assert applied["target"] == "station" and applied["sha256"] == pushed_sha and applied["bank"] == 1

    # a SIGKILL in the middle of a sweep: the file, opened as it was left, says which table was applied
    killed = tmp_path / "killed.h5"
    proc = subprocess.Popen(
        # 2020 points at time scale 0: the 90 % after the first progress line outlast the test's
        # reaction to it on a loaded machine (210 points took a fraction of a second in all)
        [sys.executable, "-m", "station.cli", "sweep", "--config", cfg, "--legs", "1", "--cycles", "10",
         "--n-targets", "101", "--time-scale", "0", "--out", str(killed), "--yes"],  # leg 1 compensated: confirmed
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)})
    progressed = threading.Event()

    def watch():
        for line in proc.stderr:
            if "/2020 points (" in line:
                progressed.set()

    threading.Thread(target=watch, daemon=True).start()
    try:
        assert progressed.wait(60) and proc.poll() is None, "the sweep ended before the kill"
        proc.send_signal(signal.SIGKILL)
        proc.wait(30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGKILL
    with h5py.File(killed, "r", swmr=True) as f:
        devices = json.loads(f["meta"].attrs["devices"])
        assert "outcome" not in f.attrs or f.attrs["outcome"] in ("", b"")  # killed: never finished
    applied = recorded_tables(devices)[1]
    assert applied["target"] == "station" and applied["sha256"] == pushed_sha and applied["bank"] == 1
    assert applied["store"].endswith("station-tables.json") and applied["enabled"] is True

    out, _ = station(capsys, "rollback", "--leg", "1", "--config", cfg, "--yes")
    assert "compensation target of leg 1: station" in out
    leg1 = _store(tmp_path)["legs"]["1"]
    assert leg1["active_bank"] == 0 and leg1["banks"][0]["error_fwd_um"] == []
    entries, _ = read_entries("runs/audit.jsonl")
    assert [(e.action, e.outcome, e.details.get("target")) for e in entries] == [
        ("push", "started", "station"), ("push", "ok", "station"),
        ("verify", "completed", "station"),
        ("rollback", "started", "station"), ("rollback", "ok", "station")]
    # rolled back: a second rollback is refused, nothing changes
    _, err = station(capsys, "rollback", "--leg", "1", "--config", cfg, "--yes", rc=2)
    assert "already rolled back" in err
    assert _store(tmp_path)["legs"]["1"]["active_bank"] == 0


def test_target_drive_on_a_drive_without_table_is_refused_offering_the_others(capsys, tmp_path):
    profile = no_table_profile(tmp_path / "notable.toml")
    cfg = str(config(tmp_path / "drive.toml", profile, target="drive"))
    Path("table.csv").write_text("leg,position_mm,error_fwd_um,error_rev_um\n1,-6,1.0,0.5\n1,0,1.5,1.0\n1,6,2.0,1.5\n")
    _, err = station(capsys, "push", "table.csv", "--leg", "1", "--config", cfg, "--yes", rc=2)
    assert "holds no compensation table" in err and "station" in err and "controller" in err
    assert not Path("runs/station-tables.json").exists()
    entries, _ = read_entries("runs/audit.jsonl")
    assert [(e.action, e.outcome, e.details.get("target")) for e in entries] == [("push", "refused", "drive")]

    ctl = str(config(tmp_path / "ctl.toml", profile, target="drive", legs='legs = { 1 = "controller" }'))
    _, err = station(capsys, "push", "table.csv", "--leg", "1", "--config", ctl, "--yes", rc=2)
    assert "compensation target is controller" in err and "--format linuxcnc" in err
