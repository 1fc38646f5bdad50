"""A station process SIGKILLed in the middle of a push to a station-compensated leg (station.services.table_jobs.push_table
running procedures.compensation.push through the station's table store, the drive reached over Modbus TCP on 127.0.0.1): just before
or just after each of the two file replacements (the table into the inactive bank, then the
switch). The store is always readable and consistent, the previous table stays active until the
switch has landed, and the audit log holds the backup. A failed store write (the file system
refusing it) fails the push and leaves the previous table active."""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest

from drivers.interfaces import TableBank
from drivers.station_compensation import StationTableStore, station_table_spec
from procedures.compensation.audit import AuditLog, read_entries
from procedures.compensation.push import PushFailed, table_sha256
from station.services.table_jobs import push_table  # the one way to run a push: the runner
from station.services.config import StationConfig
from station.services.wiring import open_drive

REPO = Path(__file__).resolve().parents[3]
PREVIOUS = TableBank(-90.0, 6.0, tuple(0.1 * i for i in range(31)), tuple(-0.1 * i for i in range(31)))
NEW = TableBank(-90.0, 3.0, tuple(2.0 - 0.01 * i for i in range(61)), tuple(1.0 for _ in range(61)))

CHILD = """
import os, signal, sys
from drivers.interfaces import TableBank
from procedures.compensation.audit import AuditLog
from station.services.table_jobs import push_table
from station.services.config import StationConfig
from station.services.wiring import open_drive

runs, kill_at, when = sys.argv[1], int(sys.argv[2]), sys.argv[3]
cfg = StationConfig(operator="test")
cfg.recordings_dir = runs
cfg.compensation.target = "station"
cfg.with_sim_memory()
real, calls = os.replace, [0]

def replace(a, b):
    calls[0] += 1
    if calls[0] == kill_at and when == "before":
        os.kill(os.getpid(), signal.SIGKILL)
    real(a, b)
    if calls[0] == kill_at and when == "after":
        os.kill(os.getpid(), signal.SIGKILL)

os.replace = replace
new = TableBank(-90.0, 3.0, tuple(2.0 - 0.01 * i for i in range(61)), tuple(1.0 for _ in range(61)))
with open_drive(cfg, 1) as drive:
    push_table(drive.axis, new, audit=AuditLog(os.path.join(runs, "audit.jsonl")))
print("not killed")
"""


@pytest.fixture(autouse=True)
def _quiet_pymodbus():
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def _cfg(runs: Path) -> StationConfig:
    cfg = StationConfig(operator="test")
    cfg.recordings_dir = str(runs)
    cfg.compensation.target = "station"
    return cfg.with_sim_memory()


def _sha(table: TableBank) -> str:
    return table_sha256(station_table_spec("x").quantize(table))


@pytest.mark.parametrize("kill_at, when, new_active", [(1, "before", False), (1, "after", False),
                                                       (2, "before", False), (2, "after", True)])
def test_killed_mid_push_keeps_a_consistent_store(tmp_path, kill_at, when, new_active):
    runs = tmp_path / "runs"
    with open_drive(_cfg(runs), 1) as drive:
        push_table(drive.axis, PREVIOUS, audit=AuditLog(runs / "audit.jsonl"))  # bank 1 active: the table to keep
    proc = subprocess.run([sys.executable, "-c", CHILD, str(runs), str(kill_at), when], cwd=REPO, capture_output=True,
                          text=True, timeout=120, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert proc.returncode == -9, proc.stdout + proc.stderr
    leg = StationTableStore(runs / "station-tables.json").leg(1)  # readable, hashes match (else StoreError)
    if new_active:
        assert leg.active_bank == 0 and table_sha256(leg.active) == _sha(NEW)
    else:
        assert leg.active_bank == 1 and table_sha256(leg.active) == _sha(PREVIOUS)
        written = (kill_at, when) != (1, "before")
        assert (table_sha256(leg.banks[0]) == _sha(NEW)) == written
    entries, _ = read_entries(runs / "audit.jsonl")
    last = entries[-1]
    assert (last.action, last.outcome, last.details["target"]) == ("push", "started", "station")
    assert last.backup["sha256"] == _sha(PREVIOUS) and last.backup["bank"] == 1
    # the store still takes a push afterwards (no lock held by the dead process)
    with open_drive(_cfg(runs), 1) as drive:
        push_table(drive.axis, PREVIOUS, audit=AuditLog(runs / "audit.jsonl"))
    assert table_sha256(StationTableStore(runs / "station-tables.json").leg(1).active) == _sha(PREVIOUS)


def test_a_store_write_that_fails_leaves_the_previous_table_active(tmp_path, monkeypatch):
    runs = tmp_path / "runs"
    cfg = _cfg(runs)
    with open_drive(cfg, 1) as drive:
        push_table(drive.axis, PREVIOUS, audit=AuditLog(runs / "audit.jsonl"))
    before = (runs / "station-tables.json").read_bytes()

    def refuse(a, b):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", refuse)
    with open_drive(cfg, 1) as drive:
        with pytest.raises(PushFailed, match=r"No space left on device.*previous table \(bank 1"):
            push_table(drive.axis, NEW, audit=AuditLog(runs / "audit.jsonl"))
    assert (runs / "station-tables.json").read_bytes() == before
    assert not [p for p in runs.iterdir() if p.name.endswith(".tmp")]
    doc = json.loads(before)
    assert doc["legs"]["1"]["active_bank"] == 1
    entries, _ = read_entries(runs / "audit.jsonl")
    assert (entries[-1].outcome, entries[-1].details["target"]) == ("failed", "station")
