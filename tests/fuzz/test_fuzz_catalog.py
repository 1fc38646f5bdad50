"""Fuzzing the catalog's readers (station/catalog/readers.py, identity_reader.py): a session identity,
a model, a report's iso230-2.json, a table CSV and an audit line, valid ones damaged at any depth,
cut short or with bytes flipped, and arbitrary bytes.
Property: a record or None (not a record of that kind), never an exception; and every record
goes into a real (SQLite) catalog: texts bounded, leg numbers 1..99, figures finite or None."""

from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path

import sqlalchemy as sa
from hypothesis import example, given, settings, strategies as st

from station.catalog import db, identity_reader, readers
from station.catalog.store import write_recs
from tests.fuzz.budget import examples, fed
from tests.fuzz.jsondamage import damaged_json, json_value

IDENTITY = {"station": {"id": "ST-A", "host": "pc"}, "operator": "jdoe", "software_version": "0.1",
            "instrument": {"model": "XL-80", "serial": "LZ-1", "calibration_due": "2027-01-01",
                           "calibrated_on": "2026-01-01", "traceable": True},
            "legs": {"1": {"serial": "HX-1", "part_number": "P", "leg_type": "T", "screw_lot": "L",
                           "drive": {"vendor": "V", "product_code": "P", "revision": "1", "serial": "D", "source": "config"}}}}
MODEL = {"format": "station-leg-error-model", "version": 1, "method": "default", "created_utc": "2026-01-01T00:00:00Z",
         "source": {"path": "s.h5", "sha256": "ab" * 32}, "options": {}, "identity": IDENTITY,
         "legs": {"1": {"stats": {"heldout_rms_um": 0.3, "noise_floor_um": 0.2, "heldout_ratio": 1.5,
                                  "range_before_um": 9.0}}}}
REPORT = {"identification": {"source": {"sha256": "ab" * 32}}, "identity": IDENTITY,
          "legs": {"1": {"values": {"E": {"value_um": 3.0, "U_um": 0.3}, "B": {"value_um": 1.0, "U_um": 0.1}}}}}
AUDIT = {"v": 1, "id": "0123456789abcdef", "op_id": "op", "time_utc": "2026-01-01T00:00:00.000000Z", "operator": "j",
         "host": "pc", "action": "verify", "leg": 1, "drive": "d", "drive_url": "sim", "outcome": "completed",
         "message": "m", "table_sha256": "cd" * 32, "bank": 1, "previous_bank": 0, "backup": None, "source": None,
         "details": {"ratio": 1.2, "after": {"iso230": {"E": 2.0, "B": 0.5}}}, "leg_serial": "HX-1", "station_id": "ST-A"}
TABLE = "# leg_serial: 1=HX-1\nleg,position_mm,error_fwd_um,error_rev_um\n1,-10,1.5,-0.5\n1,0,0.2,0.1\n2,0,3,4\n"

_ENGINE = None


def _engine():
    global _ENGINE
    if _ENGINE is None:
        _ENGINE = db.open_engine(db.sqlite_url(Path(tempfile.mkdtemp()) / "fuzz.sqlite"))
    return _ENGINE


def _indexable(rec) -> None:
    """A record the catalog can hold; written into a real one."""
    assert rec.kind in ("session", "model", "table", "push", "verification", "rollback", "report")
    assert all(1 <= leg <= 99 for leg in rec.legs)
    for row in rec.legs.values():
        for name in ("E", "A", "B", "R", "M"):
            for key in (f"{name}_um", f"{name}_U_um"):
                v = row.get(key)
                assert v is None or (isinstance(v, float) and math.isfinite(v)), (key, v)
        assert row.get("leg_serial") is None or 0 < len(row["leg_serial"]) <= 128
    with _engine().begin() as conn:
        write_recs(conn, [rec], "ST-F", queue=False)


def _bytes_of(draw, doc) -> bytes:
    text = json.dumps(doc).encode()
    how = draw(st.sampled_from([None, None, "cut", "flip"]))
    if how == "cut":
        text = text[: draw(st.integers(0, len(text)))]
    elif how == "flip":
        i = draw(st.integers(0, len(text) - 1))
        text = text[:i] + bytes([draw(st.integers(0, 255))]) + text[i + 1:]
    return text


@st.composite
def damaged(draw, seed: dict) -> bytes:
    return _bytes_of(draw, damaged_json(draw, seed, 3))


def _any(seed: dict):
    return st.one_of(damaged(seed), st.binary(max_size=80), json_value.map(lambda v: json.dumps(v).encode()))


@settings(max_examples=examples(120))
@given(_any(MODEL))
@example(json.dumps({**MODEL, "legs": {"1": {"stats": {"heldout_rms_um": 10**400}}}}).encode())
def test_model_reader_fuzzed(data):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "model.json"
        path.write_bytes(data)
        rec = readers.model_rec(path, lambda sha: {1: "HX-S"})
        fed("catalog: model record", refused=rec is None)
        if rec is not None:
            _indexable(rec)


@settings(max_examples=examples(120))
@given(_any(REPORT))
def test_report_reader_fuzzed(data):
    with tempfile.TemporaryDirectory() as d:
        (Path(d) / readers.REPORT_FILE).write_bytes(data)
        rec = readers.report_rec(d)
        fed("catalog: report record", refused=rec is None)
        if rec is not None:
            _indexable(rec)


@settings(max_examples=examples(120))
@given(st.one_of(damaged(AUDIT), json_value.map(lambda v: json.dumps(v).encode()), st.binary(max_size=80)))
@example(json.dumps({**AUDIT, "v": 1e300}).encode())
def test_audit_reader_fuzzed(data):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "audit.jsonl"
        path.write_bytes(data + b"\n")
        recs = list(readers.audit_recs(path))
        fed("catalog: audit records", refused=not recs)
        for rec in recs:
            _indexable(rec)


@settings(max_examples=examples(120))
@given(_any(IDENTITY))
@example(json.dumps({"legs": {"1": {"serial": 10**400}}}).encode())
def test_identity_reader_fuzzed(data):
    ident = identity_reader.parse_identity(data)
    rec = readers.Rec(kind="session", key="x" * 64, time_utc="2026-01-01T00:00:00Z")
    readers._apply_identity(rec, ident)
    fed("catalog: identity", refused=not rec.legs)
    _indexable(rec)


@settings(max_examples=examples(120))
@given(st.one_of(st.text(max_size=200).map(str.encode), st.binary(max_size=120),
                 st.integers(0, len(TABLE)).map(lambda n: TABLE[:n].encode()),
                 st.tuples(st.integers(0, len(TABLE) - 1), st.integers(0, 255)).map(
                     lambda t: TABLE.encode()[:t[0]] + bytes([t[1]]) + TABLE.encode()[t[0] + 1:])))
@example(TABLE.encode())
@example(b"# leg_serial: \xc2\xb2=X\nleg,position_mm,error_fwd_um,error_rev_um\n1,0,nan,inf\n")
def test_table_reader_fuzzed(data):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "table.csv"
        path.write_bytes(data)
        rec = readers.table_rec(path)
        fed("catalog: table record", refused=rec is None)
        if rec is not None:
            _indexable(rec)


def test_seeds_are_records(tmp_path):
    """The fuzzer's seeds are good inputs (else damaging them tests nothing)."""
    (tmp_path / "m.json").write_text(json.dumps(MODEL))
    assert readers.model_rec(tmp_path / "m.json").legs[1]["leg_serial"] == "HX-1"
    (tmp_path / readers.REPORT_FILE).write_text(json.dumps(REPORT))
    assert readers.report_rec(tmp_path).legs[1]["E_U_um"] == 0.3
    (tmp_path / "a.jsonl").write_text(json.dumps(AUDIT) + "\n")
    [rec] = readers.audit_recs(tmp_path / "a.jsonl")
    assert rec.kind == "verification" and rec.legs[1]["verification_ratio"] == 1.2 and rec.legs[1]["E_um"] == 2.0
    (tmp_path / "t.csv").write_text(TABLE)
    t = readers.table_rec(tmp_path / "t.csv")
    assert t.legs[1]["leg_serial"] == "HX-1" and t.legs[1]["figures"]["max_correction_um"] == 1.5 and "leg_serial" not in t.legs[2]
    with _engine().connect() as conn:
        assert conn.execute(sa.text("SELECT 1")).scalar_one() == 1
