"""[compensation] in the station config: targets per leg, the store's path, bad values refused
naming the file and the key; wiring refuses a station-target leg whose drive applies its own
table (it would be corrected twice) and wraps the others."""

from __future__ import annotations

import logging

import pytest

from drivers.errors import TableError
from drivers.interfaces import TableBank
from procedures.vocabulary import InputError
from station.services.config import StationConfig, load_config
from station.services.wiring import leg_table_spec, open_drive

HEAD = '[drive]\nurl = "sim"\n[interferometer]\nport = "sim"\n'


@pytest.fixture(autouse=True)
def _quiet_pymodbus():
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def _load(tmp_path, text: str) -> StationConfig:
    p = tmp_path / "station.toml"
    p.write_text(HEAD + text)
    return load_config(p)


def test_targets_per_leg_and_the_store_path(tmp_path):
    cfg = _load(tmp_path, '[station]\nrecordings_dir = "r"\n')
    assert [cfg.compensation.target_of(leg) for leg in (1, 6)] == ["drive", "drive"]
    assert str(cfg.station_tables_path) == "r/station-tables.json"
    cfg = _load(tmp_path, '[compensation]\ntarget = "controller"\nlegs = { 3 = "station", 5 = "drive" }\n'
                          'tables_path = "/x/t.json"\n')
    assert [cfg.compensation.target_of(leg) for leg in range(1, 7)] == [
        "controller", "controller", "station", "controller", "drive", "controller"]
    assert str(cfg.station_tables_path) == "/x/t.json"
    assert cfg.to_dict()["compensation"]["legs"] == {"3": "station", "5": "drive"}
    assert leg_table_spec(cfg, 3).holder.startswith("the station's table store (/x/t.json)")
    with pytest.raises(InputError, match="compensation target is controller"):
        leg_table_spec(cfg, 1)
    assert leg_table_spec(cfg, 5).max_points == 512  # the built-in drive's


@pytest.mark.parametrize("text, words", [
    ('[compensation]\ntarget = "drives"\n', r"station.toml: \[compensation\] target = 'drives': must be one of drive, station, controller"),
    ('[compensation]\nlegs = { 7 = "station" }\n', r"\[compensation\] legs key '7': not a leg number 1..6"),
    ('[compensation]\nlegs = { 2 = "plc" }\n', r"\[compensation\] legs.2 = 'plc': must be one of"),
    ('[compensation]\nlegs = "station"\n', r"\[compensation\] legs: expected a dict"),
    ('[compensation]\nbanks = 2\n', r"\[compensation\] banks: unknown key"),
])
def test_bad_compensation_sections_are_refused_naming_file_and_key(tmp_path, text, words):
    with pytest.raises(InputError, match=words):
        _load(tmp_path, text)


def test_a_station_leg_whose_drive_applies_a_table_is_refused(tmp_path):
    cfg = StationConfig(operator="test")
    cfg.recordings_dir = str(tmp_path / "runs")
    cfg.with_sim_memory()
    with open_drive(cfg, 2) as drive:  # target drive: give the drive a table of its own
        axis = drive.axis
        axis.write_table(1 - axis.active_bank(), TableBank(-90.0, 90.0, (1.0, 1.0, 1.0), (1.0, 1.0, 1.0)))
        axis.activate_table(1 - axis.active_bank())
    cfg.compensation.legs = {2: "station"}
    with pytest.raises(TableError, match="leg 2: compensation target is station, but the drive applies its own table"):
        open_drive(cfg, 2)
    with open_drive(cfg, 1) as drive:  # leg 1: target drive, not wrapped
        assert getattr(drive.axis, "compensation_target", "drive") == "drive"
    cfg.compensation.legs = {1: "station"}
    with open_drive(cfg, 1) as drive:
        assert drive.axis.compensation_target == "station" and drive.axis.table_spec().max_points == 4096
