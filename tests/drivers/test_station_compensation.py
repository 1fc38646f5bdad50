"""Station-side compensation (drivers/station_compensation.py) over the real Modbus client and the
simulated drive on 127.0.0.1: the same sign and interpolation as a drive applying its own table,
position read back in commanded space, soft limits on the compensated command, the store's
bank rules, atomic writes and refusal of a damaged store."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from drivers.errors import SoftLimitError, TableError
from drivers.interfaces import TableBank
from drivers.plant.leg import PlantConfig
from drivers.station_compensation import (
    StationCompensatedAxis,
    StationTableStore,
    StoreError,
    correction_um,
)

TABLE = TableBank(-90.0, 6.0, tuple(2.0 + 0.1 * i for i in range(31)), tuple(-1.0 - 0.05 * i for i in range(31)))


def _pushed(axis, table=TABLE):
    bank = 1 - axis.active_bank()
    axis.write_table(bank, table)
    axis.activate_table(bank)
    return bank


def test_correction_interpolates_and_holds_ends():
    assert correction_um(TABLE, -90.0, 1) == pytest.approx(2.0)
    assert correction_um(TABLE, -87.0, 1) == pytest.approx(2.05)
    assert correction_um(TABLE, -87.0, -1) == pytest.approx(-1.025)
    assert correction_um(TABLE, -200.0, 1) == pytest.approx(2.0)
    assert correction_um(TABLE, 200.0, -1) == pytest.approx(-2.5)
    assert correction_um(TableBank(0, 0, (), ()), 5.0, 1) == 0.0


def test_station_table_moves_like_a_drive_table(sim_drives, tmp_path):
    """The same plant, once with the drive applying the table and once with the station applying it:
    the nut goes to the same place and both report the same position (commanded space)."""
    ideal = [PlantConfig().only()] * 2
    sd = sim_drives(configs=ideal)
    drive_axis, raw = sd.axis(1), sd.axis(2)
    station_axis = StationCompensatedAxis(raw, StationTableStore(tmp_path / "st.json"))
    _pushed(drive_axis)
    _pushed(station_axis)
    for ax in (drive_axis, station_axis):
        ax.enable()
    for target, direction in ((-50.0, -1), (-20.5, 1), (10.0, 1), (3.3, -1), (-40.0, -1), (-40.0, -1), (60.0, 1)):
        a = drive_axis.move_to(target)
        b = station_axis.move_to(target)
        with sd.lock:
            nut_drive, nut_station = sd.plants[1].x_mm, sd.plants[2].x_mm
        e = correction_um(TABLE, target, direction)
        assert nut_station == pytest.approx(target - e * 1e-3, abs=2e-6)
        assert nut_station == pytest.approx(nut_drive, abs=2e-6)
        assert a.position_mm == pytest.approx(target, abs=2e-6)
        assert b.position_mm == pytest.approx(target, abs=2e-6)
        assert station_axis.status().position_mm == pytest.approx(target, abs=2e-6)
    st = station_axis.status()
    assert (st.active_bank, st.table_enabled) == (1, True)
    station_axis.set_table_enabled(False)
    station_axis.move_to(0.0)
    with sd.lock:
        assert sd.plants[2].x_mm == pytest.approx(0.0, abs=2e-6)


def test_soft_limits_apply_to_the_compensated_command(sim_drives, tmp_path):
    sd = sim_drives(configs=[PlantConfig().only()])
    ax = StationCompensatedAxis(sd.axis(1), StationTableStore(tmp_path / "st.json"))
    lim = ax.limits()
    # +250 um of error at the lower end: the command there goes 0.25 mm below the target
    big = TableBank(lim.min_mm, lim.max_mm - lim.min_mm, (250.0, 250.0), (250.0, 250.0))
    _pushed(ax, big)
    ax.enable()
    ax.move_to(0.0)
    with pytest.raises(SoftLimitError, match="compensated by the station's table"):
        ax.move_to(lim.min_mm + 0.1)
    with pytest.raises(SoftLimitError, match="outside the soft limits"):
        ax.move_to(lim.max_mm + 0.1)
    with sd.lock:
        assert sd.plants[1].x_mm == pytest.approx(0.0 - 0.25, abs=1e-6)  # nothing moved since


def test_store_banks_and_persistence(sim_drives, tmp_path):
    sd = sim_drives(configs=[PlantConfig().only()])
    path = tmp_path / "st.json"
    ax = StationCompensatedAxis(sd.axis(1), StationTableStore(path))
    assert ax.active_bank() == 0 and ax.read_table(0).point_count == 0
    with pytest.raises(TableError, match="active table"):
        ax.write_table(0, TABLE)
    bank = _pushed(ax)
    assert bank == 1
    doc = json.loads(path.read_text())
    assert doc["format"] == "station-compensation-tables" and doc["legs"]["1"]["active_bank"] == 1
    assert doc["legs"]["1"]["drive"] == ax.identity()
    # a second process (new wrapper) sees the same state; a change by one is seen by the other
    other = StationCompensatedAxis(sd.axis(1), StationTableStore(path))
    assert other.active_bank() == 1 and other.read_table(1).error_fwd_um == pytest.approx(TABLE.error_fwd_um, abs=1e-9)
    other.activate_table(0)
    assert ax.active_bank() == 0
    assert not [p for p in os.listdir(tmp_path) if p.endswith(".tmp")]


def test_damaged_store_is_refused_naming_file_and_key(sim_drives, tmp_path):
    sd = sim_drives(configs=[PlantConfig().only()])
    path = tmp_path / "st.json"
    ax = StationCompensatedAxis(sd.axis(1), StationTableStore(path))
    _pushed(ax)
    doc = json.loads(path.read_text())
    doc["legs"]["1"]["banks"][1]["error_fwd_um"][3] += 1.0
    path.write_text(json.dumps(doc))
    with pytest.raises(StoreError, match=r"st\.json: key legs\.1\.banks\[1\]\.sha256"):
        StationCompensatedAxis(sd.axis(1), StationTableStore(path)).read_table(1)
    path.write_text("{not json")
    with pytest.raises(StoreError, match="not valid JSON"):
        StationTableStore(path).read()


def test_drive_with_its_own_table_is_refused(sim_drives, tmp_path):
    sd = sim_drives(configs=[PlantConfig().only()])
    raw = sd.axis(1)
    _pushed(raw)
    with pytest.raises(TableError, match="corrected twice"):
        StationCompensatedAxis(raw, StationTableStore(tmp_path / "st.json")).check_drive_table()
    raw.set_table_enabled(False)
    StationCompensatedAxis(raw, StationTableStore(tmp_path / "st.json")).check_drive_table()


def test_after_a_move_that_failed_the_direction_comes_from_where_the_leg_stopped(sim_drives, tmp_path):
    """Like the drive, which takes the next direction from where a halted leg is: a move to 50 mm
    stalled at about 10 mm and timed out, then a move to 30 mm approaches upwards (from 10)."""
    sd = sim_drives(configs=[PlantConfig().only()], time_scale=0.0)
    ax = StationCompensatedAxis(sd.axis(1), StationTableStore(tmp_path / "st.json"))
    _pushed(ax)
    ax.enable()
    ax.move_to(10.0)
    sd.server.set_stalled(1, True)
    with pytest.raises(Exception):
        ax.move_to(50.0, timeout_s=0.5)
    sd.server.set_stalled(1, False)
    ax.reset_fault()
    ax.enable()
    assert ax.command_for(30.0)[2] == 1
    ax.move_to(30.0)
    assert sd.plants[1].x_mm == pytest.approx(30.0 - correction_um(TABLE, 30.0, 1) * 1e-3, abs=2e-6)


def test_station_compensation_through_a_real_drive_profile_without_table(tmp_path):
    """The Kinco FD profile (CiA 402 objects mapped to registers, no table, 13107.2 counts/mm,
    two words per request) served by the simulated drive: the compensated command lands on the
    drive's nearest count to target - e, and reads back as the target within half a count."""
    import threading

    from drivers.clock import VirtualClock
    from drivers.modbus.client import connect_axes
    from drivers.modbus.profile import DriveProfile
    from drivers.sim.drive_server import SimDriveServer
    from drivers.plant.leg import LegPlant

    profile = DriveProfile.load(str(Path(__file__).resolve().parents[2] / "drivers/modbus/profiles/kinco_fd.toml"))
    assert profile.table is None
    clock = VirtualClock(0.0)
    plants = {1: LegPlant(PlantConfig().only(), seed=1)}
    server = SimDriveServer(plants, clock, profile, lock=threading.RLock())
    url = f"tcp://127.0.0.1:{server.start_tcp('127.0.0.1', 0)}"
    try:
        raw = connect_axes(url, (1,), profile, clock=clock)[1]
        assert raw.table_spec() is None
        ax = StationCompensatedAxis(raw, StationTableStore(tmp_path / "st.json"))
        ax.check_drive_table()  # no table of its own: nothing to correct twice
        _pushed(ax)
        ax.enable()
        q_mm = 1 / 13107.2
        for target, direction in ((-33.3, -1), (12.34, 1), (5.0, -1)):
            st = ax.move_to(target)
            want = target - correction_um(TABLE, target, direction) * 1e-3
            assert abs(plants[1].x_mm - want) <= q_mm / 2 + 1e-9
            assert abs(st.position_mm - target) <= q_mm / 2 + 1e-9
        ax.close()
    finally:
        server.stop()
