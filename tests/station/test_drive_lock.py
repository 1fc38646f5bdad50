"""Two stations, one drive (station/services/drive_lock.py): two real `station` processes on the simulated
rig sharing a drive (its table memory file). The second is refused with exit code 2 and a message
naming leg, drive, PID, host, time and command; the first is unaffected; once the first has
ended the second succeeds; a SIGKILLed holder leaves no stale lock."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from procedures.io.recording.reader import read_session
from procedures.compensation.table import CompTable, LegTable, table_csv_text
from station.services import drive_lock
from station.services.config import StationConfig

STATION = str(Path(sys.executable).with_name("station"))


@pytest.fixture()
def bench(tmp_path, monkeypatch):
    """A folder with a station config on the simulated rig (table memory in runs/nv.json), a
    one-leg table for leg 3, one for leg 4, one for all six legs, and its own lock folder."""
    (tmp_path / "runs").mkdir()
    nv = tmp_path / "runs" / "nv.json"
    (tmp_path / "cfg.toml").write_text(
        f'[drive]\nurl = "sim"\n[interferometer]\nport = "sim"\n[sim]\ntime_scale = 0.05\nnv_path = "{nv}"\n')
    tables = {leg: LegTable(leg, -90.0, 10.0, tuple(0.5 + 0.1 * i for i in range(19)),
                            tuple(-0.5 - 0.1 * i for i in range(19))) for leg in range(1, 7)}
    for leg in (3, 4):
        (tmp_path / f"leg{leg}.csv").write_text(table_csv_text(CompTable({leg: tables[leg]})))
    (tmp_path / "all.csv").write_text(table_csv_text(CompTable(tables)))
    env = dict(os.environ, STATION_LOCK_DIR=str(tmp_path / "locks"), OPENBLAS_NUM_THREADS="1")
    env.pop("STATION_DEBUG", None)
    monkeypatch.setenv("STATION_LOCK_DIR", str(tmp_path / "locks"))
    return tmp_path, nv, env


def _station(bench, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    folder, _nv, env = bench
    return subprocess.run([STATION, *args], cwd=folder, env=env, capture_output=True, text=True, timeout=timeout)


def _start_sweep(bench, out: str) -> subprocess.Popen:
    """A long sweep of leg 3 (the paper plan: minutes at time scale 0.05), started and holding its lock."""
    folder, nv, env = bench
    proc = subprocess.Popen([STATION, "sweep", "--config", "cfg.toml", "--legs", "3", "--plan", "paper", "--out", out],
                            cwd=folder, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    lock = folder / "locks"
    while time.monotonic() < deadline:
        for f in lock.glob("*-leg3.lock") if lock.is_dir() else ():
            try:
                if json.loads(f.read_text() or "{}").get("pid") == proc.pid:
                    return proc
            except ValueError:
                pass  # being written
        if proc.poll() is not None:
            pytest.fail(f"the sweep ended early: {proc.communicate()}")
        time.sleep(0.05)
    proc.kill()
    pytest.fail("the sweep did not lock leg 3 within 60 s")


def _refusal(pid: int, nv: Path, command: str) -> re.Pattern:
    return re.compile(rf"leg 3 of sim:{re.escape(str(nv.resolve()))} is in use by station PID {pid} on "
                      rf"{re.escape(socket.gethostname())} since \d{{4}}-\d\d-\d\dT\d\d:\d\d:\d\dZ, running "
                      rf"`station {command}`\. Nothing was sent to the drive")


def test_a_second_station_is_refused_while_the_first_sweeps_then_succeeds(bench):
    folder, nv, _env = bench
    first = _start_sweep(bench, "runs/a.h5")
    try:
        for args in (("push", "leg3.csv", "--leg", "3", "--config", "cfg.toml", "--yes"),
                     ("rollback", "--leg", "3", "--config", "cfg.toml", "--yes"),
                     ("sweep", "--config", "cfg.toml", "--legs", "2-4", "--cycles", "1", "--out", "runs/b.h5"),
                     ("push", "all.csv", "--leg", "all", "--config", "cfg.toml", "--yes")):
            got = _station(bench, *args)
            assert got.returncode == 2, (args, got.stdout, got.stderr)
            assert _refusal(first.pid, nv, "sweep").search(got.stderr), (args, got.stderr)
            assert "Traceback" not in got.stderr and len(got.stderr.strip().splitlines()) == 1
        assert not (folder / "runs" / "b.h5").exists()
        # another leg of the same drive is free
        other = _station(bench, "push", "leg4.csv", "--leg", "4", "--config", "cfg.toml", "--yes")
        assert other.returncode == 0, other.stderr
        assert first.poll() is None, "the first station was disturbed"
    finally:
        first.send_signal(signal.SIGINT)  # Ctrl-C: stops the motion, finishes the file
        out, err = first.communicate(timeout=120)
    assert first.returncode == 130, (out, err)
    session = read_session(folder / "runs" / "a.h5")
    assert len(session.points) > 0 and len(session.faults) == 0, "the refused stations interfered with the sweep"
    # the first has ended: the second now succeeds, and the table is active
    got = _station(bench, "push", "leg3.csv", "--leg", "3", "--config", "cfg.toml", "--yes")
    assert got.returncode == 0, got.stderr
    assert "pushed: leg 3" in got.stdout


def test_a_killed_holder_leaves_no_stale_lock(bench):
    folder, nv, _env = bench
    first = _start_sweep(bench, "runs/a.h5")
    first.kill()  # SIGKILL: no cleanup runs
    first.communicate(timeout=60)
    got = _station(bench, "push", "leg3.csv", "--leg", "3", "--config", "cfg.toml", "--yes")
    assert got.returncode == 0, got.stderr
    assert "pushed: leg 3" in got.stdout


def _cfg(tmp_path: Path, url: str = "sim") -> StationConfig:
    cfg = StationConfig()
    cfg.drive.url = url
    cfg.sim.nv_path = str(tmp_path / "nv.json")
    return cfg


def test_lock_is_per_drive_and_leg_reentrant_in_a_process_and_released(tmp_path, monkeypatch):
    monkeypatch.setenv("STATION_LOCK_DIR", str(tmp_path / "locks"))
    cfg = _cfg(tmp_path)
    held = drive_lock.lock_for(cfg, (1, 3), whole_rig=False)
    again = drive_lock.lock_for(cfg, 3, whole_rig=False)  # the same process (the UI reconnecting)
    # another process is refused leg 3, naming this one; leg 2 is free
    probe = ("import sys; from station.services import drive_lock as d\n"
             "try:\n    d.acquire(sys.argv[1], [int(sys.argv[2])], command='station push').release(); print('free')\n"
             "except d.DriveInUse as e:\n    print(e)\n")
    drive = f"sim:{(tmp_path / 'nv.json').resolve()}"

    def other(leg: int) -> str:
        return subprocess.run([sys.executable, "-c", probe, drive, str(leg)], capture_output=True, text=True,
                              env=dict(os.environ), cwd=Path(__file__).resolve().parents[2], timeout=60).stdout.strip()

    assert other(2) == "free"
    assert re.match(rf"leg 3 of {re.escape(drive)} is in use by station PID {os.getpid()} on ", other(3))
    held.release()
    assert other(3).startswith("leg 3 of"), "released while another hold of this process was open"
    again.release()
    assert other(3) == "free" and other(1) == "free"
    held.release()  # twice: nothing more happens


def test_drive_identity():
    cfg = StationConfig()
    cfg.drive.url = "tcp://Drive-Box:502"
    assert drive_lock.drive_identity(cfg, whole_rig=False) == "tcp://drive-box:502"
    cfg.drive.url = "tcp://10.0.0.5"
    assert drive_lock.drive_identity(cfg, whole_rig=False) == "tcp://10.0.0.5:502"
    cfg.drive.url = "rtu:///dev/../dev/ttyUSB0?baud=115200"
    assert drive_lock.drive_identity(cfg, whole_rig=False) == "rtu:///dev/ttyUSB0"
    cfg.drive.url = "sim"
    assert drive_lock.drive_identity(cfg, whole_rig=False) is None  # no memory file: private to the process
    cfg.sim.nv_path = "runs/nv.json"
    assert drive_lock.drive_identity(cfg, whole_rig=False) == f"sim:{Path('runs/nv.json').resolve()}"
    cfg.drive.url, cfg.interferometer.port = "tcp://10.0.0.5:502", "sim"
    assert drive_lock.drive_identity(cfg, whole_rig=True).startswith("sim:")  # open_rig simulates it all
    assert drive_lock.drive_identity(cfg, whole_rig=False) == "tcp://10.0.0.5:502"
