"""Fuzzing the HDF5 session reader (procedures/io/recording/reader.py read_session).

A valid session, written by the real SessionWriter, is damaged: random bytes, cut short,
blocks overwritten, and -- through h5py -- root and /meta attributes of other types and
values, /points and /faults of wrong dtypes, shapes and kinds, impossible point values.
Property: a Session whose points pass the reader's checks, or InputError (SchemaError is one)
naming the file, within the deadline (the reader bounds HDF5's own loops); never another
exception. An accepted session also exports to CSV, or is refused, leaving no partial file.
"""

from __future__ import annotations

import functools
import os
import tempfile
from pathlib import Path

import h5py
import numpy as np
from hypothesis import example, given, settings, strategies as st

from procedures.io.csv_io import export_csv
from procedures.vocabulary import InputError
from procedures.io.recording.reader import check_points, read_session
from procedures.io.recording.schema import FAULT_DTYPE, POINT_DTYPE
from procedures.io.recording.writer import SessionWriter
from tests.fuzz.budget import examples, fed


@functools.cache
def seed_bytes() -> bytes:
    """A small completed session: 2 legs x 2 passes x 5 targets, one fault."""
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "seed.h5"
        rows = np.zeros(20, POINT_DTYPE)
        for name in POINT_DTYPE.names:
            if POINT_DTYPE[name].kind == "f":
                rows[name] = np.nan
        k = np.arange(20)
        rows["index"] = k
        rows["leg"] = 1 + k // 10
        rows["run"] = 1 + (k // 5) % 2
        rows["direction"] = np.where((k // 5) % 2 == 0, 1, -1)
        rows["target_mm"] = (k % 5) * 10.0 - 20
        rows["commanded_mm"] = rows["target_mm"]
        rows["error_um"] = np.sin(k)
        rows["measured_mm"] = rows["target_mm"] + rows["error_um"] / 1000
        rows["time_s"] = k * 2.0
        rows["air_temp_c"] = 20.1
        with SessionWriter.create(path, session_id="fuzz", operator="fuzz", rig="sim",
                                  plan={"kind": "test", "legs": [1, 2]}, station_config={}, devices={},
                                  software_version="test",
                                  identity={"station": {"id": "s", "host": "h"}, "legs": {"1": {"serial": "HX-1"}}}) as w:
            w.append_points(rows)
            w.append_fault({"index": 3, "leg": 1, "run": 1, "target_mm": 10.0, "time_s": 6.0,
                            "kind": "beam_break", "attempt": 1, "gave_up": 0, "message": "beam"})
            w.finish("completed")
        return path.read_bytes()


junk = st.one_of(
    st.none(), st.integers(-(2**40), 2**40), st.floats(), st.text(max_size=20), st.binary(max_size=20),
    st.sampled_from(["1.0", "2.0", "0.9", "x.y", "1", "", "[]", "5", "{}", '"[1]"', "null", "[1, 2]", '{"legs": 5}',
                     '{"legs": [1, 7]}', "[\"2026-01-01T00:00:00Z\"]", "NaN", "1e999"]),
    st.lists(st.integers(0, 9), min_size=1, max_size=3).map(np.array),
    st.just(np.zeros((2, 2))),
)
ROOT = ["schema_version", "software_version", "session_id", "operator", "rig", "started_utc", "ended_utc",
        "outcome", "resumed_utc"]
META = ["plan", "station_config", "devices", "identity"]
VALUES = {  # impossible point values: what a damaged block of raw data holds
    "leg": [0, 7, -1, 32767], "run": [0, -5, 2**31 - 1], "direction": [0, 2, -128], "index": [-1, -7, 5, 2**62],
    "target_mm": [np.nan, np.inf, -1e300, 5e3], "error_um": [np.inf, 1e300, -1e12, np.nan],
    "time_s": [np.inf, -1.0, 1e300], "air_temp_c": [np.inf, 1e30, -300.0], "load_n": [np.inf, 1e15],
}


def _dataset_kinds(name: str, dtype: np.dtype):
    n = 4
    drop = np.dtype([(f, dtype[f]) for f in dtype.names if f not in ("leg", "index")])
    as_text = np.dtype([(f, "S8" if f == "leg" else dtype[f]) for f in dtype.names])
    return {
        "float array": np.zeros(n),
        "2-D": np.zeros((n, 2), dtype),
        "scalar": np.zeros((), dtype),
        "missing fields": np.zeros(n, drop),
        "text field": np.zeros(n, as_text),
        "empty": np.zeros(0, dtype),
        "strings": np.array([b"a", b"b"]),
    }


@st.composite
def h5_damage(draw) -> list:
    """A list of edits applied with h5py to a copy of the seed file."""
    edits = []
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["root", "meta", "delete", "dataset", "value", "group"]))
        if kind == "root":
            edits.append(("attr", "/", draw(st.sampled_from(ROOT)), draw(junk)))
        elif kind == "meta":
            edits.append(("attr", "/meta", draw(st.sampled_from(META)), draw(junk)))
        elif kind == "delete":
            edits.append(("delete", draw(st.sampled_from(["/points", "/faults", "/meta"] + ROOT)), None, None))
        elif kind == "dataset":
            name = draw(st.sampled_from(["points", "faults"]))
            edits.append(("dataset", name, draw(st.sampled_from(sorted(_dataset_kinds(name, POINT_DTYPE)))), None))
        elif kind == "group":
            edits.append(("group", draw(st.sampled_from(["points", "faults"])), None, None))
        else:
            name = draw(st.sampled_from(sorted(VALUES)))
            edits.append(("value", name, draw(st.integers(0, 19)), draw(st.sampled_from(VALUES[name]))))
    return edits


def _apply(path: Path, edits: list) -> None:
    with h5py.File(path, "r+") as f:
        for what, where, key, value in edits:
            if what == "attr":
                if value is None:
                    f[where].attrs.pop(key, None) if where in f else None
                elif where in f:
                    try:
                        f[where].attrs[key] = value
                    except (TypeError, ValueError):  # h5py cannot store it (a NUL in text): no edit
                        pass
            elif what == "delete":
                if where.startswith("/"):
                    if where in f:
                        del f[where]
                else:
                    f.attrs.pop(where, None)
            elif what in ("dataset", "group"):
                if where in f:
                    del f[where]
                if what == "group":
                    f.create_group(where)
                else:
                    dtype = POINT_DTYPE if where == "points" else FAULT_DTYPE
                    f.create_dataset(where, data=_dataset_kinds(where, dtype)[key])
            elif "points" in f and isinstance(f["points"], h5py.Dataset) and f["points"].dtype.names \
                    and where in f["points"].dtype.names and f["points"].ndim == 1 and key < len(f["points"]):
                row = f["points"][key]
                row[where] = value
                f["points"][key] = row


def _read(path: Path, reader: str) -> None:
    try:
        session = read_session(path)
    except InputError as exc:
        fed(reader, refused=True)
        assert str(path) in str(exc), exc
        assert "\n" not in str(exc)
        return
    fed(reader)
    check_points(session.points, path, session.plan)  # what was accepted is what a rig records
    assert isinstance(session.resumed_utc, list)
    for name in ("plan", "station_config", "devices"):
        assert isinstance(getattr(session, name), dict), f"{name} = {getattr(session, name)!r}"
    out = path.with_suffix(".csv")
    try:
        export_csv(path, out)
    except InputError as exc:
        assert str(path) in str(exc)
        assert not out.exists()
    assert not [p for p in os.listdir(path.parent) if p.endswith(".tmp")], "a temporary file was left"


@settings(max_examples=examples(40))
@given(h5_damage())
@example([("attr", "/", "resumed_utc", "5")])  # found: a JSON number in resumed_utc raised TypeError
@example([("attr", "/", "resumed_utc", np.zeros((2, 2)))])  # found: an array there raised TypeError
@example([("attr", "/meta", "plan", "[1, 2]")])  # found: a plan that is not an object was accepted
@example([("attr", "/", "schema_version", np.array([1, 2]))])
@example([("attr", "/", "schema_version", b"\x00")])
@example([("dataset", "points", "text field", None)])
@example([("value", "index", 0, 2**62)])
def test_damaged_by_h5py(edits):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "s.h5"
        path.write_bytes(seed_bytes())
        _apply(path, edits)
        _read(path, "HDF5 session (h5py-damaged valid file)")


@settings(max_examples=examples(40))
@given(st.data())
def test_damaged_bytes(data):
    raw = seed_bytes()
    how = data.draw(st.sampled_from(["random", "cut", "overwrite", "zero"]))
    if how == "random":
        blob = data.draw(st.binary(max_size=600))
    elif how == "cut":
        blob = raw[: data.draw(st.integers(0, len(raw) - 1))]
    else:
        at = data.draw(st.integers(0, len(raw) - 1))
        n = data.draw(st.integers(1, 256))
        fill = bytes(n) if how == "zero" else data.draw(st.binary(min_size=n, max_size=n))
        blob = (raw[:at] + fill + raw[at + n:])[: len(raw)]
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "s.h5"
        path.write_bytes(blob)
        _read(path, f"HDF5 session (bytes: {how})")


def test_seed_reads():
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "s.h5"
        path.write_bytes(seed_bytes())
        s = read_session(path)
        assert len(s.points) == 20 and len(s.faults) == 1 and s.outcome == "completed"
