"""A table made for one leg serial is refused on a drive whose leg carries another, before
anything is written: over the real Modbus client and the simulated drive (TCP on 127.0.0.1),
the drive's table registers (both banks, read over Modbus and as the drive holds them), its table
memory file and its write counter are compared before and after."""

from __future__ import annotations

import logging

import pytest

from drivers.clock import VirtualClock
from drivers.modbus.client import ModbusBus, ModbusServoAxis
from drivers.modbus.profile import DriveProfile
from drivers.sim.drive_server import SimDriveServer
from drivers.plant.leg import LegPlant, PlantConfig
from procedures.compensation.audit import AuditLog, AuditSink
from procedures.compensation.push import OperationFinished, check_leg_serial, finished, push_legs_procedure, \
    push_procedure, table_sha256
from procedures.engine.runner import ListSink, run
from procedures.compensation.table import CompTable, LegTable, read_table_csv, write_table_csv

PROFILE = DriveProfile.load()


@pytest.fixture(autouse=True, scope="module")
def _quiet_pymodbus():
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


@pytest.fixture
def rig(tmp_path):
    """Two simulated drives (legs 1, 2) with their table memory in a file, and a client axis each."""
    clock = VirtualClock(0.0)
    plants = {leg: LegPlant(PlantConfig().only(), seed=leg) for leg in (1, 2)}
    server = SimDriveServer(plants, clock, PROFILE, nv_path=tmp_path / "nv.json")
    url = f"tcp://127.0.0.1:{server.start_tcp()}"
    axes = {leg: ModbusServoAxis(ModbusBus.from_url(url, timeout_s=0.5), leg, PROFILE, clock=clock) for leg in (1, 2)}
    yield server, axes, tmp_path / "nv.json"
    for ax in axes.values():
        ax.close()
    server.stop()


def _table(leg: int, offset_um: float) -> LegTable:
    n = 31
    return LegTable(leg, -90.0, 6.0, tuple(offset_um + 0.1 * i for i in range(n)), tuple(-offset_um - 0.1 * i for i in range(n)))


def _push(axis, table, audit: AuditLog | None = None, **options) -> OperationFinished:
    """push_procedure run to its end through the runner (with the audit sink on `audit`): how it ended."""
    events = ListSink()
    run(push_procedure(axis, table, **options), [events] + ([AuditSink(audit)] if audit is not None else []))
    end = finished(events.events)
    assert end is not None, "the push ended without an outcome"
    return end


def _drive_memory(server, axes, nv_path):
    """Everything a push could change: both banks as read over Modbus, the raw registers of both
    banks as the drive holds them, the active bank, the table memory file, the write counters."""
    state = {}
    for leg, ax in axes.items():
        banks = {b: table_sha256(ax.read_table(b)) for b in (0, 1)}
        with server.lock:
            raw = {b: list(server._models[leg].bank_registers(b)) for b in (0, 1)}
        state[leg] = (banks, raw, ax.active_bank(), server.request_counts(leg)[1])
    return state, nv_path.read_bytes() if nv_path.exists() else None


def test_wrong_serial_refused_before_anything_is_written(rig, tmp_path):
    server, axes, nv = rig
    audit = AuditLog(tmp_path / "audit.jsonl", station_id="bench-a", leg_serials={1: "HX-0077"})
    # the drive holds a table already (pushed for the right leg), so "nothing written" is not trivially "empty"
    assert _push(axes[1], _table(1, 1.0), audit, source={"leg_serial": "HX-0077"}, leg_serial="HX-0077").outcome == "ok"
    before = _drive_memory(server, axes, nv)
    end = _push(axes[1], _table(1, 5.0), audit, source={"path": "t.csv", "leg_serial": "HX-0042"}, leg_serial="HX-0077")
    assert end.outcome == "refused" and end.result is None
    text = end.message
    assert "HX-0042" in text and "HX-0077" in text and "Nothing was written" in text
    assert _drive_memory(server, axes, nv) == before
    last = audit.entries()[-1]
    assert (last.outcome, last.leg_serial, last.station_id) == ("refused", "HX-0077", "bench-a")
    assert last.source["leg_serial"] == "HX-0042"


def test_matching_serial_or_unknown_serial_pushes(rig, tmp_path):
    server, axes, _ = rig
    table = _table(1, 2.0)
    end = _push(axes[1], table, source={"leg_serial": "HX-0042"}, leg_serial="HX-0042")
    assert end.outcome == "ok", end.message
    got = end.result
    assert axes[1].active_bank() == got.bank and got.table_sha256 == table_sha256(axes[1].read_table(got.bank))
    # a table without a serial (made before 1.1) and a leg without a configured serial both go on
    for source, serial, offset_um in (({}, "HX-0042", 3.0), ({"leg_serial": "HX-0042"}, None, 4.0)):
        end = _push(axes[1], _table(1, offset_um), source=source, leg_serial=serial)
        assert end.outcome == "ok", end.message
        assert end.result.table_sha256 == table_sha256(axes[1].read_table(axes[1].active_bank()))
    check_leg_serial(1, None, None)


def test_several_legs_one_wrong_nothing_written_to_any(rig, tmp_path):
    server, axes, nv = rig
    before = _drive_memory(server, axes, nv)
    sink = ListSink()
    procedure = push_legs_procedure(axes, {1: _table(1, 1.0), 2: _table(2, 1.0)},
                                    sources={1: {"leg_serial": "HX-0001"}, 2: {"leg_serial": "HX-0002"}},
                                    leg_serials={1: "HX-0001", 2: "HX-0099"})
    run(procedure, [sink])
    end = [e for e in sink.events if type(e).__name__ == "OperationFinished"][-1]
    assert end.outcome == "refused" and "HX-0002" in end.message and "HX-0099" in end.message
    assert "nothing was written to any leg" in end.message
    assert _drive_memory(server, axes, nv) == before


def test_table_csv_carries_the_serial_and_old_tables_still_read(tmp_path):
    table = CompTable({1: _table(1, 1.0), 3: _table(3, 2.0)}, {3: "HX-0042"})
    path = write_table_csv(table, tmp_path / "t.csv")
    text = path.read_text()
    assert text.splitlines()[0].startswith("# integrity: table rows=") and text.splitlines()[1] == "# leg_serial: 3=HX-0042"
    back = read_table_csv(path)
    assert dict(back.serials) == {3: "HX-0042"}
    assert back.legs[3].error_fwd_um == pytest.approx(table.legs[3].error_fwd_um, abs=1e-4)  # written to 1e-4 um
    assert back.legs[3].rows[0] == 4 + 31  # rows counted in the file: record, comment, header, leg 1's 31 rows
    old = tmp_path / "old.csv"  # before serials and the integrity record
    old.write_text("\n".join(text.splitlines()[2:]) + "\n")
    assert dict(read_table_csv(old).serials) == {}


@pytest.mark.parametrize("line, reason", [
    ("# leg_serial: HX-0042", "write it as"),
    ("# leg_serial: 3=", "write it as"),
    ("# leg_serial: 5=HX-1", "which the table has no rows for"),
])
def test_bad_serial_comment_names_the_row(tmp_path, line, reason):
    rows = "\n".join(f"3,{-90 + 6 * i:.6f},0.1,0.2" for i in range(3))
    p = tmp_path / "t.csv"
    p.write_text(f"# made by hand\n{line}\nleg,position_mm,error_fwd_um,error_rev_um\n{rows}\n")
    with pytest.raises(Exception, match=reason) as exc:
        read_table_csv(p)
    assert str(p) in str(exc.value) and "row 2" in str(exc.value)
