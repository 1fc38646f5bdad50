"""COMP? (the interferometer's air compensation record): framing both ways, refusals, and the
client against the simulated instrument over a real pty; the sweep records it in the session."""

from __future__ import annotations

import json
import math
import threading

import pytest

from drivers.clock import VirtualClock
from drivers.interferometer import protocol as p
from drivers.interferometer.client import SerialInterferometer
from drivers.sim.interferometer_server import SimInterferometer
from drivers.plant.leg import LegPlant, PlantConfig
from procedures.acquisition.sweep import laser_compensation_record


def _reply(line: bytes) -> list[str]:
    return p.split_reply(line)


def test_compensation_round_trip_and_nan_fields():
    auto = p.CompensationReply("AUTO", "EDLEN", 632.991, math.nan, math.nan, math.nan, 450.0, 0.0)
    line = p.format_compensation(auto)
    assert line.startswith(b"COMP,AUTO,EDLEN,632.9910,NAN,NAN,NAN,450.0,0.000*")
    back = p.parse_compensation(_reply(line))
    assert back.mode == "AUTO" and back.equation == "EDLEN" and back.wavelength_nm == 632.991
    assert back.to_json()["air_temp_c"] is None and back.to_json()["co2_ppm"] == 450.0
    manual = p.CompensationReply("MANUAL", "CIDDOR", 632.8, 20.5, 1001.25, 40.0, 400.0, 150.0)
    assert p.parse_compensation(_reply(p.format_compensation(manual))) == manual


@pytest.mark.parametrize("fields, why", [
    ("COMP,SOMETIMES,EDLEN,632.991,NAN,NAN,NAN,450,0", "mode"),
    ("COMP,AUTO,LORENTZ,632.991,NAN,NAN,NAN,450,0", "equation"),
    ("COMP,OFF,EDLEN,632.991,NAN,NAN,NAN,450,0", "OFF goes with NONE"),
    ("COMP,AUTO,EDLEN,10600,NAN,NAN,NAN,450,0", "wavelength_nm"),
    ("COMP,MANUAL,EDLEN,632.991,20,NAN,50,450,0", "MANUAL compensation without its air values"),
    ("COMP,AUTO,EDLEN,632.991,NAN,NAN,NAN,450", "fields"),
])
def test_malformed_compensation_replies_refused(fields, why):
    with pytest.raises(p.ProtocolError, match=why):
        p.parse_compensation(fields.split(","))


def test_client_reads_the_simulated_instruments_record_over_a_pty():
    clock, lock = VirtualClock(0.0), threading.RLock()
    sim = SimInterferometer({1: LegPlant(PlantConfig(), seed=1)}, clock, lock=lock)
    port = sim.start()
    laser = SerialInterferometer(port, timeout_s=0.2)
    try:
        rec = laser.compensation()
        assert rec == {"mode": "AUTO", "equation": "EDLEN", "wavelength_nm": 632.991, "air_temp_c": None,
                       "air_pressure_hpa": None, "humidity_pct": None, "co2_ppm": 450.0, "dead_path_mm": 0.0}
        sim.set_compensation(p.CompensationReply("MANUAL", "EDLEN", 632.991, 21.0, 1005.0, 35.0, 450.0, 0.0))
        assert json.loads(laser_compensation_record(laser))["air_temp_c"] == 21.0
    finally:
        laser.close()
        sim.stop()


def test_an_instrument_without_the_query_is_recorded_as_not_reporting():
    class Old:
        def compensation(self):
            raise p.InstrumentError("interferometer refused 'COMP?': unknown command (ERR 1: unknown command COMP?).",
                                    code=1, instrument_text="unknown command COMP?")

    assert laser_compensation_record(Old()).startswith("not reported (interferometer refused 'COMP?'")
    assert laser_compensation_record(object()).startswith("not reported")
