"""Compensation tables on the simulated drive: applied to the motion, banks, checksum,
non-volatile memory, and a drive killed in the middle of a push."""

from __future__ import annotations

import json
import os
import random
import time
from pathlib import Path

import pytest

from drivers.errors import CommTimeout, TableError
from drivers.interfaces import TableBank
from drivers.modbus.client import ModbusBus, ModbusServoAxis, RequestRefused, table_registers
from drivers.sim.drive_server import NvError, SimDriveServer
from drivers.plant.leg import PlantConfig
from tests.tooling import kill_process, start_drive_process


# an error-free leg, so the nut position shows exactly what the table did
IDEAL = PlantConfig().only()

STEP_TABLE = TableBank(-10.0, 10.0, (2.0, 4.0, 6.0), (-1.0, -3.0, -5.0))


def _ideal_drives(sim_drives, **kw):
    return sim_drives(configs=[IDEAL] * 6, **kw)


def test_active_table_is_subtracted_from_the_motion(sim_drives):
    sd = _ideal_drives(sim_drives)
    ax = sd.axis(1)
    ax.write_table(1, STEP_TABLE)
    ax.activate_table(1)
    ax.enable()
    ax.move_to(-20.0)
    plant = sd.plants[1]
    # direction +1 at 5 mm: forward entries interpolated between 4 (0 mm) and 6 (10 mm) -> 5 um
    st = ax.move_to(5.0)
    assert plant.x_mm == pytest.approx(5.0 - 0.005, abs=1e-9)
    assert st.position_mm == pytest.approx(5.0, abs=1e-6), "the drive reports compensated position"
    # direction -1 at -5 mm: reverse entries between -1 (-10 mm) and -3 (0 mm) -> -2 um
    ax.move_to(-5.0)
    assert plant.x_mm == pytest.approx(-5.0 + 0.002, abs=1e-9)
    # outside the table the end values hold
    ax.move_to(50.0)
    assert plant.x_mm == pytest.approx(50.0 - 0.006, abs=1e-9)
    ax.move_to(-60.0)
    assert plant.x_mm == pytest.approx(-60.0 + 0.001, abs=1e-9)
    # switched off: no correction
    ax.set_table_enabled(False)
    st = ax.move_to(20.0)
    assert plant.x_mm == pytest.approx(20.0, abs=1e-9) and not st.table_enabled


def test_table_corrects_a_leg_with_errors(sim_drives):
    """A table built from the plant's own error map brings the real leg onto the target."""
    cfg = PlantConfig().only("lead", "longwave", "wobble", "backlash")
    sd = sim_drives(configs=[cfg] * 6)
    ax = sd.axis(2)
    plant = sd.plants[2]
    ax.enable()
    targets = [-42.0, -17.3, 0.0, 12.6, 44.4]
    uncorrected = []
    for t in targets:
        ax.move_to(t)
        sd.clock.sleep(cfg.settling_time_s)  # read the settled leg, after its ring-out (a sweep's dwell)
        uncorrected.append(abs(plant.true_position_mm(sd.clock.now()) - t) * 1000.0)
    from drivers.plant.leg import systematic_error_um

    start, spacing, n = -50.0, 0.25, 401
    xs = [start + i * spacing for i in range(n)]
    table = TableBank(start, spacing,
                      tuple(float(systematic_error_um(cfg, x, 1, 20.0, 0.0, 0.0)) for x in xs),
                      tuple(float(systematic_error_um(cfg, x, -1, 20.0, 0.0, 0.0)) for x in xs))
    ax.write_table(1, table)
    ax.activate_table(1)
    ax.move_to(-49.0)
    corrected = []
    for t in targets:
        ax.move_to(t)
        sd.clock.sleep(cfg.settling_time_s)
        corrected.append(abs(plant.true_position_mm(sd.clock.now()) - t) * 1000.0)
    assert max(uncorrected) > 0.5
    assert max(corrected) < 0.05, corrected


def test_activation_of_a_bank_with_a_bad_checksum_is_refused(sim_drives):
    sd = _ideal_drives(sim_drives)
    ax = sd.axis(3)
    ax.write_table(1, STEP_TABLE)
    ax.activate_table(1)
    # hand-write bank 0 with a header whose checksum does not match its entries
    t = sd.profile.table
    fwd, rev, header = table_registers(sd.profile, TableBank(0.0, 1.0, (9.0, 9.0), (9.0, 9.0)))
    ax.bus.write(3, t.fwd_address(0), fwd)
    ax.bus.write(3, t.rev_address(0), rev)
    ck = t.header["checksum"]
    header[ck.address] ^= 0x0001
    ax.bus.write(3, t.bank_base[0], header[:ck.end])
    with pytest.raises(TableError) as info:
        ax.activate_table(0)
    assert "checksum" in str(info.value) and "still active" in str(info.value)
    assert ax.active_bank() == 1
    with pytest.raises(TableError, match="inconsistent"):
        ax.read_table(0)
    ax.enable()
    ax.move_to(-20.0)
    ax.move_to(5.0)
    assert sd.plants[3].x_mm == pytest.approx(5.0 - 0.005, abs=1e-9), "the previous table still applies"


def test_drive_refuses_writes_to_the_active_bank(sim_drives):
    sd = _ideal_drives(sim_drives)
    ax = sd.axis(4)
    assert ax.active_bank() == 0
    t = sd.profile.table
    with pytest.raises(RequestRefused) as info:
        ax.bus.write(4, t.fwd_address(0), [1, 2, 3])
    assert info.value.exception_code == 2
    # the client refuses before writing anything
    reads, writes = sd.server.request_counts(4)
    with pytest.raises(TableError, match="active table"):
        ax.write_table(0, STEP_TABLE)
    assert sd.server.request_counts(4)[1] == writes


def test_activation_refused_while_moving(sim_drives):
    sd = _ideal_drives(sim_drives, time_scale=0.05)
    ax = sd.axis(5)
    ax.write_table(1, STEP_TABLE)
    ax.enable()
    p = sd.profile
    ax.bus.write(5, p.address("controlword"), [0x1F] + p.registers["target_position"].encode(60.0))
    assert ax.status().moving
    with pytest.raises(TableError, match="moving"):
        ax.activate_table(1)
    assert ax.active_bank() == 0


@pytest.mark.parametrize(
    "table, words",
    [
        (TableBank(0.0, 0.1, (0.0,) * 513, (0.0,) * 513), "at most 512"),
        (TableBank(0.0, 1.0, (0.0, 300.01), (0.0, 0.0)), "point 2 (+1.0000 mm), field error_fwd_um: 300.01"),
        (TableBank(0.0, 1.0, (0.0, 1.0), (0.0,)), "reverse entries"),
        (TableBank(0.0, 0.0, (0.0, 1.0), (0.0, 1.0)), "step"),
        (TableBank(0.0, 1.0, (0.0, float("nan")), (0.0, 1.0)), "field error_fwd_um: nan"),
        (TableBank(0.0, 1.0, (0.0, 1.0), (0.0, 1.0), checksum=0x1234), "checksum"),
    ],
)
def test_tables_the_drive_cannot_hold_are_refused_before_writing(sim_drives, table, words):
    sd = sim_drives()
    ax = sd.axis(6)
    tx = ax.bus.transactions
    with pytest.raises(TableError) as info:
        ax.write_table(1, table)
    assert words in str(info.value)
    assert ax.bus.transactions == tx, "nothing may be sent for a table the drive cannot hold"


def test_tables_survive_a_restart_in_nv_memory(sim_drives, tmp_path):
    nv = tmp_path / "drive-nv.json"
    sd = sim_drives(nv_path=nv)
    ax = sd.axis(2)
    ax.write_table(1, STEP_TABLE)
    ax.activate_table(1)
    ax.set_table_enabled(False)
    before = ax.read_table(1)
    sd.server.stop()
    sd2 = sim_drives(nv_path=nv)
    ax2 = sd2.axis(2)
    assert ax2.active_bank() == 1
    assert ax2.read_table(1) == before
    assert ax2.status().table_enabled is False
    assert sd2.axis(3).active_bank() == 0, "other legs keep their own memory"


def test_unreadable_nv_memory_is_explained(tmp_path, profile):
    from drivers.clock import VirtualClock
    from drivers.plant.leg import LegPlant

    nv = tmp_path / "nv.json"
    nv.write_text("{ half a file")
    with pytest.raises(NvError) as info:
        SimDriveServer({1: LegPlant(IDEAL)}, VirtualClock(), profile, nv_path=nv)
    assert str(nv) in str(info.value)
    nv.write_text(json.dumps({"format": "something-else"}))
    with pytest.raises(NvError, match="not a station-sim-drive-nv file"):
        SimDriveServer({1: LegPlant(IDEAL)}, VirtualClock(), profile, nv_path=nv)


# -- a drive killed in the middle of a push ----------------------------------------------------------





def _push_killed_at(nv: Path, profile, kill_at_write: int, new_table: TableBank) -> int:
    """Push `new_table` to the inactive bank of leg 1 and SIGKILL the drive process just
    before write number `kill_at_write`; returns the number of writes that got through."""
    proc, url = start_drive_process(nv, legs=2)
    bus = ModbusBus.from_url(url, timeout_s=0.5)
    writes = 0

    def before_request(kind, unit, address, count):
        nonlocal writes
        if kind == "write":
            writes += 1
            if writes == kill_at_write:
                kill_process(proc)

    try:
        ax = ModbusServoAxis(bus, 1, profile)
        inactive = 1 - ax.active_bank()
        bus.on_request = before_request
        with pytest.raises(CommTimeout) as info:
            ax.write_table(inactive, new_table)
        assert "interrupted" in str(info.value) and "still active" in str(info.value)
        ax.close()
    finally:
        kill_process(proc)
        bus.close()
    return writes - 1


def test_drive_killed_during_a_push_keeps_the_previous_table(tmp_path, profile, sim_drives):
    nv = tmp_path / "drive-nv.json"
    previous = TableBank(-90.0, 1.0, tuple(round(0.01 * i, 2) for i in range(181)),
                         tuple(round(-0.02 * i, 2) for i in range(181)))
    sd = sim_drives(legs=2, nv_path=nv)  # the drive's memory before the push
    ax = sd.axis(1)
    ax.write_table(1, previous)
    ax.activate_table(1)
    previous_back = ax.read_table(1)
    sd.server.stop()

    # 450 points per direction: 4 + 4 entry chunks and the header = 9 writes
    new = TableBank(-90.0, 0.4, tuple(5.0 + 0.001 * i for i in range(450)), tuple(-5.0 for _ in range(450)))
    fwd, rev, _ = table_registers(profile, new)
    n_writes = 9
    saved = nv.read_bytes()
    seed = int(os.environ.get("KILL_SEED", random.randrange(1 << 30)))
    kill_at = random.Random(seed).randint(2, n_writes)
    for k in sorted({kill_at, n_writes}):  # a random chunk, and just before the header
        nv.write_bytes(saved)  # every round starts from the same drive memory
        landed = _push_killed_at(nv, profile, k, new)
        assert landed == k - 1, f"seed {seed}"
        proc, url = start_drive_process(nv, legs=2)
        try:
            bus = ModbusBus.from_url(url, timeout_s=1.0)
            ax = ModbusServoAxis(bus, 1, profile)
            assert ax.active_bank() == 1, f"kill before write {k} (seed {seed}) changed the active bank"
            assert ax.read_table(1) == previous_back, f"kill before write {k} (seed {seed}) damaged the active table"
            # the kill really hit the middle of the push: the first chunk had landed in bank 0,
            # but not the header, so bank 0 does not claim the new table
            t = profile.table
            assert bus.read(1, t.fwd_address(0), 123) == fwd[:123], f"seed {seed}"
            assert ax.read_table(0).point_count == 0, f"seed {seed}"
            # and a complete push afterwards works
            ax.write_table(0, new)
            ax.activate_table(0)
            assert ax.active_bank() == 0
            ax.close()
        finally:
            kill_process(proc)
