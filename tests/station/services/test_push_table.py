"""station.services.table_jobs.push_table / rollback (procedures.compensation.push run through the runner,
its outcome raised as PushRefused / PushFailed) over the real Modbus client and the simulated drive:
the safe path, the backup in the audit log, rollback, refusals that write nothing, and failures
that leave the previous table active (a read-back that differs, a refused or unanswered switch, a
link lost mid-push)."""

from __future__ import annotations

import json
import logging
import random
import threading

import pytest
from pymodbus.constants import ExcCodes

from drivers.clock import VirtualClock
from drivers.interfaces import TableBank
from drivers.modbus.client import ModbusBus, ModbusServoAxis
from drivers.modbus.profile import DriveProfile
from drivers.sim.drive_server import SimDriveServer
from drivers.plant.leg import LegPlant, PlantConfig
from procedures.compensation.audit import AuditLog
from procedures.compensation.push import (
    PushFailed,
    PushRefused,
    prepare_push,
    quantize,
    table_sha256,
)
from station.services.table_jobs import push_table, rollback  # the one way to run a push: the runner
from drivers.modbus.client import table_spec
from drivers.sim.modbus_tcp import NoReply  # the simulated drive answers nothing
from procedures.compensation.table import LegTable

IDEAL = PlantConfig().only()
PROFILE = DriveProfile.load()
SPEC = table_spec(PROFILE)
# 300 points per direction: three entry chunks of <= 123 registers per direction, then the header
TABLE_A = TableBank(-90.0, 0.6, tuple(1.234 + 0.01 * i for i in range(300)), tuple(-0.5 - 0.013 * i for i in range(300)))
TABLE_B = TableBank(-90.0, 6.0, tuple(0.1 * i for i in range(31)), tuple(-0.1 * i for i in range(31)))


@pytest.fixture(autouse=True, scope="module")
def _quiet_pymodbus():
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


class Drive:
    """A simulated drive server (two legs) and a client axis for leg 1, on 127.0.0.1."""

    def __init__(self, tmp_path, time_scale: float = 0.0, timeout_s: float = 0.5):
        self.clock = VirtualClock(time_scale)
        self.plants = {leg: LegPlant(IDEAL, seed=leg) for leg in (1, 2)}
        self.server = SimDriveServer(self.plants, self.clock, PROFILE, nv_path=tmp_path / "nv.json")
        self.url = f"tcp://127.0.0.1:{self.server.start_tcp()}"
        self.timeout_s = timeout_s
        self.axes: list[ModbusServoAxis] = []
        self.axis = self.new_axis()

    def new_axis(self, leg: int = 1) -> ModbusServoAxis:
        ax = ModbusServoAxis(ModbusBus.from_url(self.url, timeout_s=self.timeout_s), leg, PROFILE, clock=self.clock)
        self.axes.append(ax)
        return ax

    def writes(self, leg: int = 1) -> int:
        return self.server.request_counts(leg)[1]

    def model(self, leg: int = 1):
        return self.server._models[leg]  # fault injection into the simulated drive

    def close(self) -> None:
        for ax in self.axes:
            ax.close()
        self.server.stop()


@pytest.fixture
def drive(tmp_path):
    d = Drive(tmp_path)
    yield d
    d.close()


@pytest.fixture
def audit(tmp_path):
    return AuditLog(tmp_path / "audit.jsonl", operator="tester")


def _table_writes(model, on_write):
    """Wrap the simulated drive's register writes: `on_write(address, values, original)`."""
    original = model.write
    model.write = lambda address, values: on_write(address, values, original)


def test_push_writes_the_inactive_bank_switches_and_records_the_backup(drive, audit):
    ax = drive.axis
    before = ax.read_table(0)
    result = push_table(ax, TABLE_A, audit=audit, drive_url=drive.url)
    assert (result.bank, result.previous_bank, ax.active_bank()) == (1, 0, 1)
    stored = ax.read_table(1)
    assert stored.error_fwd_um == pytest.approx(quantize(TABLE_A).error_fwd_um, abs=1e-9)
    assert table_sha256(stored) == result.table_sha256 == table_sha256(quantize(TABLE_A))
    assert result.points == 300 and result.event().bank == 1 and result.event().table_sha256 == result.table_sha256
    entries = audit.entries()
    assert [(e.action, e.outcome) for e in entries] == [("push", "started"), ("push", "ok")]
    started, ok = entries
    assert started.op_id == ok.op_id and started.backup is not None
    assert started.backup["sha256"] == table_sha256(before) and started.backup["error_fwd_um"] == []
    assert ok.drive == ax.identity() and ok.drive_url == drive.url and ok.operator == "tester"
    assert (ok.bank, ok.previous_bank, ok.table_sha256) == (1, 0, result.table_sha256)

    # a second push backs up the first table in full and goes to the other bank
    second = push_table(ax, TABLE_B, audit=audit)
    assert (second.bank, second.previous_bank, ax.active_bank()) == (0, 1, 0)
    backup = audit.entries()[-1].backup
    assert backup["bank"] == 1 and len(backup["error_fwd_um"]) == 300
    assert backup["error_rev_um"] == pytest.approx(list(quantize(TABLE_A).error_rev_um), abs=1e-9)


def test_a_leg_table_from_a_csv_is_accepted(drive):
    t = LegTable(1, -10.0, 5.0, (0.5, 1.0, 1.5, 2.0, 2.5), (0.0, 0.1, 0.2, 0.3, 0.4))
    result = push_table(drive.axis, t)
    assert drive.axis.read_table(result.bank).error_fwd_um == pytest.approx(t.error_fwd_um)


def test_rollback_restores_the_backup_of_the_last_push(drive, audit):
    ax = drive.axis
    push_table(ax, TABLE_A, audit=audit)
    push_table(ax, TABLE_B, audit=audit)
    result = rollback(ax, audit)
    assert ax.active_bank() == result.bank == 1
    assert table_sha256(ax.read_table(1)) == table_sha256(quantize(TABLE_A)) == result.table_sha256
    last = audit.entries()[-1]
    assert (last.action, last.outcome) == ("rollback", "ok")
    assert last.backup["sha256"] == table_sha256(quantize(TABLE_B)), "the rollback backs up what it replaced"
    # a second rollback would not undo the right thing: refused, nothing written
    writes = drive.writes()
    with pytest.raises(PushRefused, match="already rolled back"):
        rollback(ax, audit)
    assert drive.writes() == writes
    assert audit.entries()[-1].outcome == "refused"


def test_rollback_to_an_empty_table(drive, audit):
    ax = drive.axis
    push_table(ax, TABLE_B, audit=audit)
    rollback(ax, audit)
    assert ax.read_table(ax.active_bank()).point_count == 0


def test_rollback_refuses_when_the_drive_was_changed_outside_the_log(drive, audit):
    ax = drive.axis
    push_table(ax, TABLE_A, audit=audit)
    ax.write_table(0, TABLE_B)  # someone else pushes without the audit log
    ax.activate_table(0)
    writes = drive.writes()
    with pytest.raises(PushRefused, match="not the table the last push wrote"):
        rollback(ax, audit)
    assert drive.writes() == writes and ax.active_bank() == 0


def test_rollback_without_a_push_is_refused(drive, audit):
    with pytest.raises(PushRefused, match="no successful push"):
        rollback(drive.axis, audit)


def test_rollback_matches_the_drive_by_identity(drive, audit):
    push_table(drive.axis, TABLE_A, audit=audit)
    leg2 = drive.new_axis(2)
    with pytest.raises(PushRefused, match="no successful push"):
        rollback(leg2, audit)


@pytest.mark.parametrize(
    "table, words",
    [
        (TableBank(-90.0, 0.3, (0.0,) * 513, (0.0,) * 513), "at most 512"),
        (TableBank(-90.0, 1.0, (0.0, 300.5, 0.0), (0.0, 0.0, 0.0)), r"point 2 \(-89.0000 mm\), field error_fwd_um: 300.5 um"),
        (TableBank(-90.0, 1.0, (0.0, 1.0), (0.0,)), "1 reverse entries"),
        (TableBank(-90.0, 0.0, (0.0, 1.0), (0.0, 1.0)), "step 0 mm"),
        (TableBank(-90.0, -1.0, (0.0, 1.0), (0.0, 1.0)), "step -1 mm"),
        (TableBank(-90.0, 1.0, (0.0,), (0.0,)), "a table needs at least 2"),
        (TableBank(-90.0, 10.0, (0.0,) * 20, (0.0,) * 20), r"-90.000 .. \+100.000 mm, beyond the soft limits"),
        (TableBank(-90.0, 1.0, (0.0, float("inf")), (0.0, 1.0)), "error_fwd_um"),
    ],
)
def test_tables_the_drive_should_not_get_are_refused_and_nothing_is_written(drive, audit, table, words):
    writes = drive.writes()
    with pytest.raises(PushRefused, match=words) as info:
        push_table(drive.axis, table, audit=audit, spec=SPEC)
    assert "Nothing was written" in str(info.value)
    assert drive.writes() == writes and drive.axis.active_bank() == 0
    assert [e.outcome for e in audit.entries()] == ["refused"]


def test_push_is_refused_while_the_axis_moves(tmp_path, audit):
    d = Drive(tmp_path, time_scale=1.0)  # real time: a 60 mm move takes 6 s
    try:
        ax = d.axis
        ax.enable()
        p = PROFILE
        ax.bus.write(1, p.address("controlword"), [0x1F] + p.registers["target_position"].encode(60.0))
        assert ax.status().moving
        writes = d.writes()
        with pytest.raises(PushRefused, match="moving") as info:
            push_table(ax, TABLE_B, audit=audit)
        assert "Nothing was written" in str(info.value)
        assert d.writes() == writes and ax.active_bank() == 0
        assert audit.entries()[-1].outcome == "refused" and "moving" in audit.entries()[-1].message
    finally:
        d.axis.stop()
        d.close()


def test_a_read_back_that_differs_leaves_the_previous_table_active(drive, audit):
    ax = drive.axis
    push_table(ax, TABLE_B, audit=audit)  # bank 1 active
    previous = ax.read_table(1)
    flip = PROFILE.table.fwd_address(0) + 7

    def corrupt(address, values, original):
        # a drive whose memory does not keep what it was sent: one entry comes back different
        if address <= flip < address + len(values):
            values = list(values)
            values[flip - address] ^= 0x0001
        return original(address, values)

    _table_writes(drive.model(), corrupt)
    with pytest.raises(PushFailed) as info:
        push_table(ax, TABLE_A, audit=audit)
    text = str(info.value)
    assert "read-back" in text and "bank 0" in text
    assert "The previous table (bank 1" in text and "is still active" in text
    assert ax.active_bank() == 1 and ax.read_table(1) == previous
    assert [e.outcome for e in audit.entries()[-2:]] == ["started", "failed"]


def test_a_refused_switch_leaves_the_previous_table_active(drive, audit):
    ax = drive.axis
    reg = PROFILE.registers["active_bank"]

    def busy(address, values, original):
        if address <= reg.address < address + len(values):
            return ExcCodes.DEVICE_BUSY
        return original(address, values)

    _table_writes(drive.model(), busy)
    with pytest.raises(PushFailed, match=r"activating bank 1: .*refused.*previous table \(bank 0\) is still active"):
        push_table(ax, TABLE_A, audit=audit)
    assert ax.active_bank() == 0


def test_an_unanswered_switch_that_landed_counts_as_done(drive, audit):
    ax = drive.axis
    reg = PROFILE.registers["active_bank"]

    def silent_after(address, values, original):
        res = original(address, values)
        if address <= reg.address < address + len(values):
            raise NoReply("reply lost")  # applied, but no answer
        return res

    _table_writes(drive.model(), silent_after)
    result = push_table(ax, TABLE_A, audit=audit)
    assert ax.active_bank() == result.bank == 1
    assert "got no answer" in audit.entries()[-1].message


def test_an_unanswered_switch_with_a_dead_drive_says_the_state_is_unknown(drive, audit):
    ax = drive.axis
    reg = PROFILE.registers["active_bank"]
    model = drive.model()

    def dies(address, values, original):
        if address <= reg.address < address + len(values):
            model.unresponsive = True
            raise NoReply("drive died")
        return original(address, values)

    _table_writes(model, dies)
    with pytest.raises(PushFailed, match="NOT known whether the drive switched"):
        push_table(ax, TABLE_A, audit=audit)
    assert audit.entries()[-1].outcome == "failed"


def test_link_lost_at_a_random_chunk_leaves_the_previous_table_active(drive, audit):
    ax = drive.axis
    push_table(ax, TABLE_B, audit=audit)  # bank 1 active, bank 0 the target
    previous = ax.read_table(1)
    model = drive.model()
    seed = random.randrange(1 << 30)
    die_at = random.Random(seed).randint(1, 7)  # 3 + 3 entry chunks, then the header
    count = {"n": 0}

    def maybe_die(address, values, original):
        if PROFILE.table.bank_base[0] <= address < PROFILE.table.bank_end(0):
            count["n"] += 1
            if count["n"] == die_at:
                model.unresponsive = True
                raise NoReply("link lost")
        return original(address, values)

    _table_writes(model, maybe_die)
    with pytest.raises(PushFailed) as info:
        push_table(ax, TABLE_A, audit=audit)
    text = str(info.value)
    assert "interrupted" in text and "still active" in text, f"seed {seed}: {text}"
    model.unresponsive = False  # the link comes back
    fresh = drive.new_axis()
    assert fresh.active_bank() == 1 and fresh.read_table(1) == previous, f"seed {seed}, died at write {die_at}"
    assert count["n"] == die_at
    # and a complete push afterwards works
    del model.write  # the drive behaves again
    assert push_table(fresh, TABLE_A, audit=audit).bank == 0


def test_audit_log_that_cannot_be_written_stops_the_push_before_it_starts(drive, tmp_path):
    (tmp_path / "log-is-a-dir").mkdir()
    writes = drive.writes()
    with pytest.raises(PushRefused, match="cannot open it for appending.*not started"):
        push_table(drive.axis, TABLE_A, audit=AuditLog(tmp_path / "log-is-a-dir"))
    assert drive.writes() == writes


def test_push_notices_a_drive_changed_after_the_plan(drive, audit):
    ax = drive.axis
    plan = prepare_push(ax, TABLE_A)
    other = drive.new_axis()
    other.write_table(1, TABLE_B)
    other.activate_table(1)
    with pytest.raises(PushRefused, match="changed since"):
        push_table(ax, plan=plan, audit=audit)
    assert ax.active_bank() == 1 and table_sha256(ax.read_table(1)) == table_sha256(quantize(TABLE_B))


def test_damaged_backup_is_not_restored(drive, audit, tmp_path):
    push_table(drive.axis, TABLE_B, audit=audit)
    lines = audit.path.read_text().splitlines()
    doc = json.loads(lines[-1])
    doc["backup"]["error_fwd_um"] = [5.0]
    doc["backup"]["error_rev_um"] = [5.0]
    forged = AuditLog(tmp_path / "forged.jsonl")
    forged.path.write_text("\n".join(lines[:-1] + [json.dumps(doc)]) + "\n")
    with pytest.raises(PushRefused, match="does not match its recorded sha256"):
        rollback(drive.axis, forged)


def test_concurrent_pushes_to_two_legs_on_one_bus(drive, audit):
    leg2 = ModbusServoAxis(drive.axis.bus, 2, PROFILE, clock=drive.clock)
    errors = []

    def go(ax, table):
        try:
            push_table(ax, table, audit=audit)
        except Exception as exc:  # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=go, args=(drive.axis, TABLE_A)), threading.Thread(target=go, args=(leg2, TABLE_B))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    assert table_sha256(drive.axis.read_table(1)) == table_sha256(quantize(TABLE_A))
    assert table_sha256(leg2.read_table(1)) == table_sha256(quantize(TABLE_B))
    assert sorted(e.leg for e in audit.entries() if e.outcome == "ok") == [1, 2]
