"""The state of a leg's compensation table as a structure: read from a simulated drive (a real Modbus
server on loopback), recorded by a session in words and as JSON, and read back from either."""

from __future__ import annotations

import json
import logging
import math

import pytest

from drivers.clock import VirtualClock
from drivers.interfaces import TableBank
from drivers.modbus.client import ModbusBus, ModbusServoAxis
from drivers.modbus.profile import DriveProfile
from drivers.sim.drive_server import SimDriveServer
from drivers.plant.leg import LegPlant, PlantConfig
from procedures.acquisition.sweep import table_state
from procedures.compensation.applied_table import TableState, applied_table
from procedures.compensation.push import finished, push_procedure
from procedures.engine.runner import ListSink, run
from procedures.io.recording.stage import active_tables

PROFILE = DriveProfile.load()
TABLE = TableBank(-90.0, 6.0, tuple(0.1 * i for i in range(31)), tuple(-0.1 * i for i in range(31)))


@pytest.fixture(scope="module")
def axis(tmp_path_factory):
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    clock = VirtualClock(0.0)
    server = SimDriveServer({1: LegPlant(PlantConfig().only(), seed=1)}, clock, PROFILE,
                            nv_path=tmp_path_factory.mktemp("drive") / "nv.json")
    url = f"tcp://127.0.0.1:{server.start_tcp()}"
    ax = ModbusServoAxis(ModbusBus.from_url(url, timeout_s=0.5), 1, PROFILE, clock=clock)
    yield ax
    ax.close()
    server.stop()


def test_the_drive_state_as_a_structure_and_its_words(axis):
    before = table_state(axis)
    assert not before.active and before.error == ""
    assert before.text in ("table compensation off", f"bank {before.bank} active, empty")

    events = ListSink()
    run(push_procedure(axis, TABLE, drive_url="sim"), [events])  # the push procedure itself, through the runner
    assert finished(events.events).outcome == "ok"
    state = table_state(axis)
    assert state.active and state.enabled and state.bank == axis.active_bank()
    assert (state.point_count, state.start_mm, state.spacing_mm) == (31, -90.0, 6.0)
    # the words the sessions have always recorded (older readers parse them)
    assert state.text == f"bank {state.bank} active, 31 points from -90.000 mm every 6 mm"

    # the JSON record of the same table reads back as the same state
    record = json.loads(json.dumps(applied_table(axis)))
    assert TableState.from_record(record) == state


def test_a_session_is_read_from_its_structure_or_from_the_words_of_an_older_file():
    state = TableState(enabled=True, bank=1, point_count=13, start_mm=-90.0, spacing_mm=15.0)
    record = json.dumps({"target": "drive", "enabled": True, "bank": 1, "points": 13, "sha256": "ab" * 32,
                         "start_mm": -90.0, "spacing_mm": 15.0})
    words = "bank 1 active, 13 points from -90.000 mm every 15 mm"
    assert state.text == words
    # new files carry both; the structure alone says the same; an older file has only the words
    assert active_tables({"leg2_compensation_table": record, "leg2_compensation": words}) == {2: words}
    assert active_tables({"leg2_compensation_table": record}) == {2: words}
    assert active_tables({"leg3_compensation": words, "leg3": "drive"}) == {3: words}
    # off, empty, unreadable: no table applied, whatever the words say
    off = json.dumps({"target": "drive", "enabled": False, "bank": 1, "points": 13})
    empty = json.dumps({"target": "drive", "enabled": True, "bank": 0, "points": 0, "sha256": ""})
    unknown = json.dumps({"target": "drive", "error": "no answer"})
    assert active_tables({"leg1_compensation_table": off, "leg1_compensation": words,
                          "leg4_compensation_table": empty, "leg5_compensation_table": unknown,
                          "leg6_compensation_table": "not json"}) == {}
    assert TableState.from_record(json.loads(unknown)).text == "unknown (no answer)"
    assert TableState.from_record(json.loads(empty)).text == "bank 0 active, empty"
    assert TableState.from_record(json.loads(off)).text == "table compensation off"
    assert math.isnan(TableState().start_mm) and not TableState().active
