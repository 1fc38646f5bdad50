"""A drive process SIGKILLed at a random write of a push (station.services.table_jobs.push_table running
procedures.compensation.push, over Modbus TCP): after a
restart from its non-volatile memory the previous table is active and intact, the error said so,
and the audit log holds the backup and the failure."""

from __future__ import annotations

import logging
import os
import random

import pytest

from drivers.interfaces import TableBank
from drivers.modbus.client import ModbusBus, ModbusServoAxis
from drivers.modbus.profile import DriveProfile
from procedures.compensation.audit import AuditLog
from procedures.compensation.push import PushFailed, quantize, table_sha256
from station.services.table_jobs import push_table  # the one way to run a push: the runner
from tests.tooling import kill_process, start_drive_process

PROFILE = DriveProfile.load()
PREVIOUS = TableBank(-90.0, 1.0, tuple(round(0.01 * i, 2) for i in range(181)), tuple(round(-0.02 * i, 2) for i in range(181)))
# 300 points per direction: 3 + 3 entry chunks and the header = 7 table writes, then the switch
NEW = TableBank(-90.0, 0.6, tuple(3.0 + 0.001 * i for i in range(300)), tuple(-3.0 for _ in range(300)))
TABLE_WRITES = 7


@pytest.fixture(autouse=True, scope="module")
def _quiet_pymodbus():
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def _axis(url: str) -> ModbusServoAxis:
    return ModbusServoAxis(ModbusBus.from_url(url, timeout_s=0.4), 1, PROFILE)


def test_drive_killed_at_a_random_write_of_a_push_keeps_the_previous_table(tmp_path):
    nv = tmp_path / "nv.json"
    audit = AuditLog(tmp_path / "audit.jsonl")
    proc, url = start_drive_process(nv, legs=1)
    try:
        ax = _axis(url)
        push_table(ax, PREVIOUS, audit=audit)  # bank 1 active: the table to keep
        ax.close()
    finally:
        kill_process(proc)
    previous_sha = table_sha256(quantize(PREVIOUS))
    seed = int(os.environ.get("KILL_SEED", random.randrange(1 << 30)))
    kill_at = random.Random(seed).randint(1, TABLE_WRITES + 1)  # a table chunk, the header or the switch
    proc, url = start_drive_process(nv, legs=1)
    writes = 0

    def before_request(kind, unit, address, count):
        nonlocal writes
        if kind == "write":
            writes += 1
            if writes == kill_at:
                kill_process(proc)

    try:
        ax = _axis(url)
        ax.bus.on_request = before_request
        with pytest.raises(PushFailed) as info:
            push_table(ax, NEW, audit=audit)
        ax.close()
    finally:
        kill_process(proc)
    text = str(info.value)
    if kill_at <= TABLE_WRITES:
        assert "previous table (bank 1" in text and "is still active" in text, f"seed {seed}: {text}"
    else:  # killed just before the switch: the station cannot know, and says so
        assert "NOT known whether the drive switched" in text, f"seed {seed}: {text}"
    entries = audit.entries()
    assert [e.outcome for e in entries[-2:]] == ["started", "failed"], f"seed {seed}"
    assert entries[-2].backup["sha256"] == previous_sha

    proc, url = start_drive_process(nv, legs=1)  # the drive powers up again from its NV memory
    try:
        ax = _axis(url)
        assert ax.active_bank() == 1, f"seed {seed}, killed at write {kill_at}"
        assert table_sha256(ax.read_table(1)) == previous_sha, f"seed {seed}, killed at write {kill_at}"
        if 1 < kill_at <= TABLE_WRITES:  # the first chunk had landed: the bank holds part of the new table
            assert ax.bus.read(1, PROFILE.table.fwd_address(0), 5) != [0] * 5, f"seed {seed}"
        # and the push goes through once the drive is back
        result = push_table(ax, NEW, audit=audit)
        assert result.bank == 0 and table_sha256(ax.read_table(0)) == table_sha256(quantize(NEW))
        ax.close()
    finally:
        kill_process(proc)
