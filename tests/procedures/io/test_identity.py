"""Session identity (schema 1.1, /meta identity): written, read back, carried into models; 1.0
files (the committed samples) read with the identity unknown; the laser's calibration state."""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path
from types import MappingProxyType

import h5py
import pytest

from procedures.vocabulary import SchemaError
from procedures.io.recording.identity import (
    NOT_STATED,
    DriveIdentity,
    LegIdentity,
    SessionIdentity,
    StationIdentity,
    calibration_warnings,
    identity_from_json,
    instrument_identity,
    model_identity,
    model_leg_serials,
)
from procedures.io.recording.reader import read_identity, read_session
from procedures.io.recording.schema import SCHEMA_VERSION
from procedures.io.recording.writer import SessionWriter

REPO = Path(__file__).resolve().parents[3]
SAMPLES = sorted((REPO / "recordings").glob("*.h5"))
DAY = dt.date(2026, 11, 26)


def _identity(due: str | None = "2027-03-01") -> SessionIdentity:
    drive = DriveIdentity("StationSim", "LegServo-402", "1.0.0", "SIM-0003", "modbus-device-id")
    inst = instrument_identity("XL-80", "L123", due, "2026-03-01", on=DAY)
    return SessionIdentity(StationIdentity("bench-a", "host-a"), "ana", "1.2.3", inst,
                           MappingProxyType({3: LegIdentity("HX-0042", "HX-L-300", "HX300", "L7", drive)}),
                           tuple(calibration_warnings(inst, DAY)))


def _write(path: Path, identity: dict | None) -> Path:
    with SessionWriter.create(path, session_id="s", operator="ana", rig="sim", plan={"legs": [3]}, station_config={},
                              devices={}, software_version="1.2.3", identity=identity) as w:
        w.append_point(dict(index=0, leg=3, run=1, direction=1, target_mm=0.0, error_um=0.1))
        w.finish("completed")
    return path


def test_identity_round_trips_through_a_session_file(tmp_path):
    ident = _identity()
    path = _write(tmp_path / "s.h5", ident.to_json())
    with h5py.File(path, "r") as f:
        assert f.attrs["schema_version"] == SCHEMA_VERSION == "1.2"
        stored = json.loads(f["meta"].attrs["identity"])
        assert read_identity(f) == ident  # from an open file too
    assert stored["legs"]["3"]["drive"]["source"] == "modbus-device-id"
    assert stored["instrument"] == {"model": "XL-80", "serial": "L123", "calibration_due": "2027-03-01",
                                    "calibrated_on": "2026-03-01", "traceable": True}
    assert read_identity(path) == ident and read_session(path).identity == ident
    assert read_identity(path).leg_serial(3) == "HX-0042" and read_identity(path).leg_serial(1) is None


@pytest.mark.skipif(not SAMPLES, reason="no committed sample sessions in recordings/")
def test_schema_1_0_samples_read_with_identity_unknown():
    for path in SAMPLES:
        session = read_session(path)
        assert session.schema_version == "1.0"
        assert session.identity == SessionIdentity.unknown() == read_identity(path)
        assert not session.identity.recorded and session.identity.leg_serial(1) is None
        assert session.identity.instrument.calibration_due is None and session.identity.station.id is None


def test_a_1_0_file_resumes_and_stays_1_0(tmp_path):
    path = tmp_path / "old.h5"
    w = SessionWriter.create(path, session_id="o", operator="t", rig="sim", plan={"legs": [1]}, station_config={},
                             devices={}, software_version="0")
    w.append_point(dict(index=0, leg=1, run=1, direction=1, target_mm=0.0, error_um=0.1))
    w.close()
    with h5py.File(path, "a") as f:  # as the previous version wrote it
        f.attrs["schema_version"] = "1.0"
    with SessionWriter.resume(path) as w:
        w.append_point(dict(index=1, leg=1, run=1, direction=1, target_mm=1.0, error_um=0.1))
        w.finish("completed")
    s = read_session(path)
    assert s.schema_version == "1.0" and len(s.points) == 2 and not s.identity.recorded


@pytest.mark.parametrize("damage, field", [
    ('{"legs": {"1": {"serial": 42}}}', "legs.1.serial"),
    ('{"instrument": {"calibration_due": "next year"}}', "instrument.calibration_due"),
    ('{"station": []}', "station"),
    ('[1, 2]', "not a JSON object"),
    ('{"legs": {"1": {', "not valid JSON"),
])
def test_a_damaged_identity_is_refused_naming_the_field(tmp_path, damage, field):
    path = _write(tmp_path / "d.h5", _identity().to_json())
    with h5py.File(path, "a") as f:
        f["meta"].attrs["identity"] = damage
    with pytest.raises(SchemaError, match="/meta/identity") as exc:
        read_session(path)
    assert field in str(exc.value) and str(path) in str(exc.value)


def test_calibration_state_of_the_laser():
    assert calibration_warnings(instrument_identity("XL-80", "L1", "2026-11-26", None, DAY), DAY) == []
    past = instrument_identity("XL-80", "L1", "2026-10-01", "2025-10-01", DAY)
    (text,) = calibration_warnings(past, DAY)
    assert not past.traceable and "2026-10-01" in text and "56 day(s)" in text and "not traceable" in text
    assert "XL-80 s/n L1" in text
    none = instrument_identity("", "", "", "", DAY)
    assert not none.traceable and calibration_warnings(none, DAY) == [f"the laser: {NOT_STATED}"]


def test_model_identity_and_the_serials_a_table_takes():
    mi = model_identity(_identity(), [3, 4])
    assert mi["station"] == {"id": "bench-a", "host": "host-a"} and mi["operator"] == "ana"
    assert mi["legs"] == {"3": {"serial": "HX-0042", "part_number": "HX-L-300", "leg_type": "HX300"},
                          "4": {"serial": None, "part_number": None, "leg_type": None}}
    assert model_leg_serials(mi) == {3: "HX-0042"}
    assert model_leg_serials({}) == {} and model_leg_serials(None) == {}
    # a 1.0 session gives a model identity with every field unknown
    assert model_leg_serials(model_identity(SessionIdentity.unknown(), [1])) == {}


def test_newer_minor_keys_are_ignored():
    doc = _identity().to_json()
    doc["calibration_certificate"] = "C-17"
    doc["legs"]["3"]["torque_nm"] = "1.2"
    assert identity_from_json(doc).leg(3).serial == "HX-0042"
