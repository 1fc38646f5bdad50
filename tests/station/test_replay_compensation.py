"""The replay interferometer answers COMP? with the recording's own air-compensation record
(`laser_air_compensation`), so record -> replay keeps it; an old recording without one, or one
whose instrument did not report it, is answered with an explicit ERR, never the simulator's
default. Everything goes through the real pty (SerialInterferometer) and, for the sweeps, the
real Modbus TCP server on loopback."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import pytest

from drivers.interferometer import protocol as p
from drivers.replay.interferometer_server import ERR_NOT_RECORDED, ERR_REPLAYED, recorded_compensation_reply
from procedures.acquisition.plans import iso230_plan
from procedures.io.recording.reader import read_session
from station.services.config import StationConfig
from station.services.jobs import replay_sweep, run_sweep
from station.services.wiring import open_replay_rig, open_rig

CFG = StationConfig(operator="test")
KEY = "laser_air_compensation"
# a compensation unlike the simulator's default (AUTO, EDLEN, 632.991 nm, CO2 450 ppm, no dead path),
# with values that the protocol's fixed decimals would round (the replay sends them exactly)
MANUAL = p.CompensationReply("MANUAL", "CIDDOR", 632.99137, 21.3719, 1003.257, 41.23, 512.5, 12.3456)
SIM_DEFAULT = {"mode": "AUTO", "equation": "EDLEN", "wavelength_nm": 632.991, "air_temp_c": None,
               "air_pressure_hpa": None, "humidity_pct": None, "co2_ppm": 450.0, "dead_path_mm": 0.0}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    """One leg, 5 targets, 2 cycles on the simulated rig, the instrument reporting MANUAL."""
    path = tmp_path_factory.mktemp("comp") / "manual.h5"
    with open_rig(CFG, legs=(1,), time_scale=0.0) as rig:
        rig.sim.laser_server.set_compensation(MANUAL)
        result = run_sweep(rig, iso230_plan((1,), -80.0, 80.0, step_mm=40.0, cycles=2), path, CFG)
    assert result.outcome == "completed"
    return path


def _replay(original: Path, out: Path) -> dict:
    session = read_session(original)
    with open_replay_rig(original, None, CFG) as rig:
        result = replay_sweep(rig, session, out, CFG)
        assert rig.sim.mismatch is None
    assert result.outcome == "completed"
    replayed = read_session(out)
    assert (replayed.points["measured_mm"] == session.points["measured_mm"]).all()  # the points replay as before
    return replayed.devices


def _with_devices(original: Path, out: Path, change) -> Path:
    """A copy of `original` whose /meta devices record is changed by `change(devices)`."""
    shutil.copy(original, out)
    with h5py.File(out, "r+") as f:
        devices = json.loads(f["meta"].attrs["devices"])
        change(devices)
        f["meta"].attrs["devices"] = json.dumps(devices)
    return out


def test_record_then_replay_keeps_the_recorded_air_compensation(recorded, tmp_path):
    record = read_session(recorded).devices[KEY]
    # what the recorded instrument said (in the protocol's decimals)
    assert json.loads(record) == p.parse_compensation(p.split_reply(p.format_compensation(MANUAL))).to_json()
    assert json.loads(record)["mode"] == "MANUAL" and json.loads(record)["dead_path_mm"] == 12.346
    devices = _replay(recorded, tmp_path / "replayed.h5")
    assert devices[KEY] == record  # the same text, not the simulator's default
    assert json.loads(devices[KEY]) != SIM_DEFAULT
    # and a replay of the replay keeps it again
    assert _replay(tmp_path / "replayed.h5", tmp_path / "again.h5")[KEY] == record


def test_a_record_with_more_digits_than_the_protocol_is_replayed_exactly(recorded, tmp_path):
    """A record that did not come through the protocol's decimals (another instrument, an edit)
    comes back bit for bit: the numbers are sent with repr, as the replayed readings are."""
    exact = json.dumps(MANUAL.to_json(), sort_keys=True)
    edited = _with_devices(recorded, tmp_path / "exact.h5", lambda d: d.update({KEY: exact}))
    with open_replay_rig(edited, None, CFG) as rig:
        assert rig.laser.compensation() == MANUAL.to_json()
        assert rig.laser.compensation() == MANUAL.to_json()  # asked again: the same, nothing consumed
    assert _replay(edited, tmp_path / "exact-replayed.h5")[KEY] == exact


def test_an_old_recording_without_a_record_is_answered_explicitly(recorded, tmp_path):
    old = _with_devices(recorded, tmp_path / "old.h5", lambda d: d.pop(KEY))
    assert KEY not in read_session(old).devices
    with open_replay_rig(old, None, CFG) as rig:
        with pytest.raises(p.InstrumentError) as err:
            rig.laser.compensation()
    assert err.value.code == ERR_NOT_RECORDED
    assert err.value.instrument_text.startswith("replay: no air-compensation record (laser_air_compensation")
    assert "old.h5" in err.value.instrument_text
    # a replay still runs; the replayed session says there was nothing to report, not a default
    record = _replay(old, tmp_path / "old-replayed.h5")[KEY]
    assert record.startswith("not reported (") and "no air-compensation record" in record


def test_a_recorded_refusal_is_replayed_as_a_refusal(recorded, tmp_path):
    said = "not reported (the interferometer driver has no compensation query)"
    refused = _with_devices(recorded, tmp_path / "refused.h5", lambda d: d.update({KEY: said}))
    with open_replay_rig(refused, None, CFG) as rig:
        with pytest.raises(p.InstrumentError) as err:
            rig.laser.compensation()
    assert err.value.code == ERR_REPLAYED
    assert err.value.instrument_text == "replay: recorded as " + said
    record = _replay(refused, tmp_path / "refused-replayed.h5")[KEY]
    assert record.startswith("not reported (") and said in record


@pytest.mark.parametrize("record, why", [
    ("{not json", "cannot be replayed (Expecting property name"),
    (json.dumps({**SIM_DEFAULT, "mode": "SOMETIMES"}), "field 1 (mode) is 'SOMETIMES'"),
    (json.dumps({k: v for k, v in SIM_DEFAULT.items() if k != "co2_ppm"}), "missing key co2_ppm"),
    (json.dumps({**SIM_DEFAULT, "wavelength_nm": 2000.0}), "outside 400..1700"),
])
def test_a_record_that_cannot_be_sent_is_refused_naming_why(record, why):
    fields = p.split_reply(recorded_compensation_reply(record, "x.h5"))
    assert fields[:2] == ["ERR", str(ERR_NOT_RECORDED)]
    text = ",".join(fields[2:])
    assert text.startswith("replay: the air-compensation record cannot be replayed (") and why in text
    assert text.endswith("from x.h5")
