"""The point record type owns the /points schema: its fields make the row type of every writer and
reader, and the files written before it existed keep the same row type, byte for byte."""

from __future__ import annotations

import math
from dataclasses import FrozenInstanceError, replace
from pathlib import Path

import h5py
import numpy as np
import pytest

from procedures.io.recording.reader import read_session
from procedures.io.recording.schema import ADDED_POINT_FIELDS, POINT_DTYPE, POINT_REQUIRED_KEYS, POINT_UNITS, PointRecord
from procedures.io.recording.writer import SessionWriter, point_bytes, point_row
from procedures.vocabulary import InputError

REPO = Path(__file__).resolve().parents[3]
SAMPLES = sorted((REPO / "recordings").glob("*.h5"))

RECORD = PointRecord(index=7, leg=2, run=3, direction=-1, target_mm=12.5, commanded_mm=12.5,
                     drive_position_mm=12.5001, measured_mm=12.5021, error_um=2.1, time_s=5.0, air_temp_c=20.5,
                     air_pressure_hpa=1012.0, humidity_pct=45.0, material_temp_c=21.25, load_n=3.0,
                     signal_pct=88.0, flags=1, speed_mm_s=-4.0)


def test_the_row_type_is_the_one_of_schema_1():
    # written out, not derived: a field moved or retyped in PointRecord must fail here
    assert POINT_DTYPE.descr == [
        ("index", "<i8"), ("leg", "<i2"), ("run", "<i4"), ("direction", "|i1"), ("target_mm", "<f8"),
        ("commanded_mm", "<f8"), ("drive_position_mm", "<f8"), ("measured_mm", "<f8"), ("error_um", "<f8"),
        ("time_s", "<f8"), ("air_temp_c", "<f8"), ("air_pressure_hpa", "<f8"), ("humidity_pct", "<f8"),
        ("material_temp_c", "<f8"), ("load_n", "<f8"), ("signal_pct", "<f4"), ("flags", "<u4"), ("speed_mm_s", "<f8")]
    assert POINT_DTYPE.itemsize == 119
    assert POINT_UNITS["error_um"] == "um" and POINT_UNITS["speed_mm_s"] == "mm/s" and POINT_UNITS["flags"] == "bitfield"
    assert POINT_REQUIRED_KEYS == ("index", "leg", "run", "direction", "target_mm")


@pytest.mark.skipif(not SAMPLES, reason="no committed sample sessions in recordings/")
@pytest.mark.parametrize("sample", SAMPLES, ids=lambda p: p.name)
def test_the_committed_samples_have_the_records_row_type_and_read_back_as_records(sample):
    """A sample from before a field was added (ADDED_POINT_FIELDS) has the others, same types,
    same order; it reads with the added ones unknown, and each row is a record's row."""
    with h5py.File(sample, "r") as f:
        stored = f["points"].dtype
        units = {k[len("units_"):]: v for k, v in f["points"].attrs.items() if k.startswith("units_")}
        raw = f["points"][...]
    n = len(stored.names)
    assert stored.names == POINT_DTYPE.names[:n] and POINT_DTYPE.names[n:] in ((), ADDED_POINT_FIELDS)
    assert all(stored[name] == POINT_DTYPE[name] for name in stored.names)
    assert units == {name: POINT_UNITS[name] for name in stored.names}
    points = read_session(sample).points
    assert points.dtype == POINT_DTYPE
    for name in stored.names:
        assert raw[name][: len(points)].tobytes() == points[name].tobytes()
    for row in (points[0], points[len(points) // 2], points[-1]):
        rec = PointRecord.from_row(row)
        assert point_row(rec).tobytes() == row.tobytes() == point_bytes(rec)[1]


def test_a_record_is_its_row_in_field_order_and_reads_as_a_mapping():
    row = point_row(RECORD)[0]
    assert RECORD.to_row() == tuple(getattr(RECORD, n) for n in POINT_DTYPE.names)
    assert point_bytes(RECORD) == (7, row.tobytes())
    back = PointRecord.from_row(row)
    assert back.to_row()[:15] == RECORD.to_row()[:15] and back.signal_pct == 88.0 and back.speed_mm_s == -4.0
    assert list(RECORD) == list(POINT_DTYPE.names) and len(RECORD) == 18
    assert RECORD["error_um"] == 2.1 and dict(RECORD)["leg"] == 2 and RECORD.get("flags") == 1
    with pytest.raises(KeyError):
        RECORD["error_mm"]
    with pytest.raises(FrozenInstanceError):
        RECORD.flags = 0  # type: ignore[misc]
    # unknown values: NaN (not measured), flags 0
    short = PointRecord(index=0, leg=1, run=1, direction=1, target_mm=0.0)
    assert math.isnan(short.error_um) and math.isnan(short.speed_mm_s) and short.flags == 0
    assert point_row(short).tobytes() == point_row({"index": 0, "leg": 1, "run": 1, "direction": 1, "target_mm": 0.0}).tobytes()


def test_the_recorder_refuses_a_bad_record_with_a_message(tmp_path):
    w = SessionWriter.create(tmp_path / "s.h5", session_id="abc", operator="ana", rig="sim", plan={"kind": "iso230"},
                             station_config={}, devices={}, software_version="9.9.9")
    try:
        with pytest.raises(InputError, match="point 7: direction must be"):
            w.append_point(replace(RECORD, direction=0))
        with pytest.raises(InputError, match="leg and run are 1-based"):
            w.append_point(replace(RECORD, leg=0))
        w.append_point(RECORD)
        w.finish("completed")
    finally:
        w.close()
    (row,) = read_session(tmp_path / "s.h5").points
    assert row.tobytes() == point_row(RECORD).tobytes()
