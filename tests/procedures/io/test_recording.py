"""Session files: what the writer puts in, the reader gets back, and what it refuses."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from tests.tooling import require_tool
from procedures.vocabulary import InputError, SchemaError
from procedures.io.recording.reader import LiveReader, file_sha256, read_session
from procedures.io.recording.schema import FAULT_DTYPE, POINT_DTYPE, POINT_UNITS, SCHEMA_VERSION
from procedures.io.recording.writer import SessionWriter

REPO = Path(__file__).resolve().parents[3]
PLAN = {"kind": "iso230", "targets_mm": [-10.0, 0.0, 12.5], "cycles": 2}
DEVICES = {"leg1": "simdrive 1.0 sn 7", "laser": "simlaser sn 3"}


def _create(path: Path, **kw) -> SessionWriter:
    args = dict(session_id="abc", operator="ana", rig="sim", plan=PLAN, station_config={"x": 1},
                devices=DEVICES, software_version="9.9.9")
    args.update(kw)
    return SessionWriter.create(path, **args)


def _point(i: int, **extra) -> dict:
    rec = dict(index=i, leg=1 + i % 2, run=1 + i // 6, direction=1 if (i // 6) % 2 == 0 else -1,
               target_mm=0.5 * i, commanded_mm=0.5 * i, error_um=0.01 * i - 0.3, time_s=2.0 * i)
    rec.update(extra)
    return rec


def test_points_faults_and_metadata_round_trip(tmp_path):
    path = tmp_path / "s.h5"
    with _create(path) as w:
        for i in range(13):
            w.append_point(_point(i))
        w.append_fault(dict(index=5, leg=2, run=1, target_mm=2.5, time_s=10.0, kind="beam_break",
                            attempt=2, gave_up=True, message="beam blocked at 2.5 mm"))
        assert w.points_written == 13 and w.faults_written == 1
        assert w.indices_written() == set(range(13))
        w.finish("completed")
    s = read_session(path)
    assert s.schema_version == SCHEMA_VERSION and s.outcome == "completed"
    assert s.plan == PLAN and s.devices == DEVICES and s.station_config == {"x": 1}
    assert s.attrs["operator"] == "ana" and s.attrs["software_version"] == "9.9.9"
    assert s.attrs["rig"] == "sim" and s.attrs["session_id"] == "abc"
    assert s.attrs["started_utc"] <= s.attrs["ended_utc"] and s.resumed_utc == []
    assert s.points.dtype == POINT_DTYPE and list(s.points["index"]) == list(range(13))
    assert np.array_equal(s.points["error_um"], 0.01 * np.arange(13) - 0.3)
    # fields the record did not give are unknown (NaN), never zero
    assert np.all(np.isnan(s.points["material_temp_c"])) and np.all(np.isnan(s.points["measured_mm"]))
    assert np.all(s.points["flags"] == 0)
    f = s.faults[0]
    assert f["kind"] == b"beam_break" and f["gave_up"] == 1 and f["attempt"] == 2 and f["index"] == 5
    assert s.sha256 == file_sha256(path) and len(s.sha256) == 64
    with h5py.File(path, "r") as h:
        for name, unit in POINT_UNITS.items():
            assert h["points"].attrs[f"units_{name}"] == unit


def test_numpy_record_is_accepted_and_long_message_is_cut_to_valid_utf8(tmp_path):
    path = tmp_path / "s.h5"
    row = np.zeros((), POINT_DTYPE)
    row["index"], row["leg"], row["run"], row["direction"], row["target_mm"] = 4, 3, 2, -1, 7.25
    with _create(path) as w:
        w.append_point(row[()])
        w.append_fault(dict(index=4, kind="drive_fault", message="é" * 150))
        w.finish("aborted")
    s = read_session(path)
    assert s.points[0]["leg"] == 3 and s.points[0]["target_mm"] == 7.25 and s.outcome == "aborted"
    msg = s.faults[0]["message"].decode("utf-8")  # still valid UTF-8 after the cut
    assert msg == "é" * (FAULT_DTYPE["message"].itemsize // 2)


def test_writer_refuses_bad_records_duplicates_and_existing_files(tmp_path):
    path = tmp_path / "s.h5"
    with _create(path) as w:
        w.append_point(_point(0))
        with pytest.raises(InputError, match="index 0 is already recorded"):
            w.append_point(_point(0))
        with pytest.raises(SchemaError, match="unknown field 'eror_um'"):
            w.append_point(dict(_point(1), eror_um=1.0))
        with pytest.raises(SchemaError, match="lacks required field.*target_mm"):
            w.append_point({k: v for k, v in _point(1).items() if k != "target_mm"})
        with pytest.raises(InputError, match="direction must be"):
            w.append_point(_point(1, direction=0))
        w.append_point(_point(1))
        with pytest.raises(ValueError, match="outcome must be one of"):
            w.finish("done")
    assert list(read_session(path).points["index"]) == [0, 1]
    assert read_session(path).outcome == "incomplete"  # closed without finish
    with pytest.raises(InputError, match="file exists"):
        _create(path)


def test_append_points_batch_and_context_manager_marks_failures(tmp_path):
    path = tmp_path / "s.h5"
    rows = np.zeros(5, POINT_DTYPE)
    rows["index"] = np.arange(5)
    rows["leg"], rows["run"], rows["direction"] = 1, 1, 1
    with pytest.raises(RuntimeError):
        with _create(path) as w:
            w.append_points(rows)
            with pytest.raises(InputError, match="recorded twice"):
                w.append_points(rows[:1])
            raise RuntimeError("the drive caught fire")
    s = read_session(path)
    assert s.outcome == "failed" and len(s.points) == 5


def test_finished_file_is_cleanly_closed_and_readable_without_swmr(tmp_path):
    path = tmp_path / "s.h5"
    with _create(path) as w:
        w.append_point(_point(0))
        w.finish("completed")
    with h5py.File(path, "r") as h:  # a killed or open file would need swmr=True
        assert h.attrs["outcome"] == "completed"


def _write_copy_with(path: Path, target: Path, edit) -> None:
    with _create(path) as w:
        w.append_point(_point(0))
        w.finish("completed")
    target.write_bytes(path.read_bytes())
    with h5py.File(target, "a") as h:
        edit(h)


def test_reader_refuses_newer_major_version(tmp_path):
    bad = tmp_path / "v2.h5"
    _write_copy_with(tmp_path / "s.h5", bad, lambda h: h.attrs.__setitem__("schema_version", "2.0"))
    with pytest.raises(SchemaError) as err:
        read_session(bad)
    assert str(err.value) == (
        f"{bad}: schema version 2.0 is newer than this station understands (1.x); update station"
    )


def test_reader_accepts_newer_minor_version_with_extra_fields(tmp_path):
    src = tmp_path / "s.h5"
    newer = tmp_path / "v1_9.h5"

    def edit(h):
        old = h["points"][...]
        dt = np.dtype(POINT_DTYPE.descr + [("new_thing", "<f8")])
        rows = np.zeros(len(old), dt)
        for n in POINT_DTYPE.names:
            rows[n] = old[n]
        rows["new_thing"] = 42.0
        del h["points"]
        h.create_dataset("points", data=rows, maxshape=(None,), chunks=True)
        h.attrs["schema_version"] = "1.9"

    _write_copy_with(src, newer, edit)
    s = read_session(newer)
    assert s.schema_version == "1.9" and s.points.dtype == POINT_DTYPE and s.points[0]["index"] == 0


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda h: h.__delitem__("faults"), "dataset /faults is missing"),
        (lambda h: h.attrs.__delitem__("schema_version"), "not a station session file"),
        (lambda h: h["meta"].attrs.__setitem__("plan", "{not json"), "/meta/plan is not valid JSON"),
        (lambda h: h.attrs.__delitem__("operator"), "root attribute operator is missing"),
    ],
)
def test_reader_names_what_is_missing(tmp_path, edit, message):
    bad = tmp_path / "bad.h5"
    _write_copy_with(tmp_path / "s.h5", bad, edit)
    with pytest.raises(SchemaError, match=re.escape(message)):
        read_session(bad)


def test_reader_names_a_missing_point_field(tmp_path):
    bad = tmp_path / "bad.h5"

    def edit(h):
        old = h["points"][...]
        keep = [n for n in POINT_DTYPE.names if n != "error_um"]
        del h["points"]
        h.create_dataset("points", data=old[keep])

    _write_copy_with(tmp_path / "s.h5", bad, edit)
    with pytest.raises(SchemaError, match=r"/points lacks field\(s\) error_um"):
        read_session(bad)


def test_reader_refuses_non_hdf5_and_missing_files(tmp_path):
    csv = tmp_path / "x.csv"
    csv.write_text("leg,run\n1,1\n")
    with pytest.raises(InputError, match="not an HDF5 file"):
        read_session(csv)
    with pytest.raises(InputError, match="no such file"):
        read_session(tmp_path / "nope.h5")


def test_live_reader_in_the_same_process_sees_each_point_once(tmp_path):
    path = tmp_path / "s.h5"
    with _create(path) as w, LiveReader(path) as live:
        seen = []
        for i in range(40):
            w.append_point(_point(i))
            seen.extend(live.poll()["index"].tolist())
        assert seen == list(range(40)) and len(live.poll()) == 0


def test_h5dump_shows_the_schema(tmp_path):
    h5dump = require_tool("h5dump")
    path = tmp_path / "s.h5"
    with _create(path) as w:
        w.append_point(_point(0))
        w.finish("completed")
    out = subprocess.run([h5dump, "-H", str(path)], capture_output=True, text=True, check=True).stdout
    for name in POINT_DTYPE.names + FAULT_DTYPE.names:
        assert f'"{name}"' in out, name
    for attr in ("schema_version", "outcome", "started_utc", "units_error_um", "plan", "devices"):
        assert f'ATTRIBUTE "{attr}"' in out, attr
    assert 'DATASET "points"' in out and 'GROUP "meta"' in out


def test_plain_h5py_snippet_in_the_docs_reads_a_session(tmp_path):
    """The snippet in docs/session-schema.md runs without project code and prints the points."""
    doc = (REPO / "docs" / "session-schema.md").read_text()
    snippet = re.search(r"```python\n(.*?)```", doc, re.S).group(1)
    assert "procedures" not in snippet and "station" not in snippet.replace("station_config", "")
    path = tmp_path / "s.h5"
    with _create(path) as w:  # left open: the snippet must cope with a file being written
        for i in range(7):
            w.append_point(_point(i))
        w.flush()  # a plain HDF5 reader sees the points the writer has moved from its journal
        proc = subprocess.run([sys.executable, "-c", snippet, str(path)], capture_output=True, text=True,
                              cwd=tmp_path, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "7 points" in proc.stdout and json.dumps(PLAN["kind"]).strip('"') in proc.stdout


@pytest.mark.filterwarnings("ignore:overflow encountered in cast:RuntimeWarning")  # float32 overflow: inf, both ways
def test_point_bytes_are_the_bytes_of_the_numpy_row():
    """The recorder packs a point with struct; the bytes must be numpy's row's, whatever the
    values' types (numpy scalars, bools, a float in an integer field, text numbers, NaN, -0.0,
    float32 rounding and overflow), and bad records are refused alike."""
    import random

    from procedures.io.recording.writer import point_bytes, point_row

    rnd = random.Random(3)
    floats = [0.0, -0.0, float("nan"), float("inf"), -1.5e-310, 1e300, 123.456789, np.float64(2.5), np.float32(0.1), 7]
    records = [dict(index=5, leg=1, run=1, direction=-1, target_mm=0.0),  # the fields in file order, as a sweep
               {name: (i if name in ("index", "leg", "run") else 1 if name == "direction" else 0.5 + i)
                for i, name in enumerate(POINT_DTYPE.names)}]
    for i in range(300):
        rec = dict(index=rnd.choice([i, np.int64(i), 2**40 + i]), leg=rnd.choice([1, 6, np.int16(3), True]),
                   run=rnd.randint(1, 100_000), direction=rnd.choice([1, -1, np.int8(-1), 1.0]),
                   target_mm=rnd.choice(floats), flags=rnd.choice([0, 3, 2**32 - 1]))
        for name in ("measured_mm", "error_um", "signal_pct", "air_temp_c", "speed_mm_s"):
            if rnd.random() < 0.7:
                rec[name] = rnd.choice(floats + ["1.25", rnd.uniform(-1e3, 1e3)])
        records.append(rec)
    for rec in records:
        index, raw = point_bytes(rec)
        row = point_row(rec)
        assert raw == row.tobytes() and index == int(row[0]["index"]), rec
    assert point_bytes(point_row(records[0])[0]) == (5, point_row(records[0]).tobytes())
    for bad, error in ((dict(index=-1, leg=1, run=1, direction=1, target_mm=0.0), InputError),
                       (dict(index=1, leg=1, run=1, direction=2, target_mm=0.0), InputError),
                       (dict(index=1, leg=1, run=1, direction=1), SchemaError),
                       (dict(index=1, leg=1, run=1, direction=1, target_mm=0.0, typo=1), SchemaError)):
        with pytest.raises(error):
            point_bytes(bad)
        with pytest.raises(error):
            point_row(bad)
