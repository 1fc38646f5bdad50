"""Fuzzing the station-side table store reader (drivers/station_compensation.py
StationTableStore.read): the file the station reads back before every compensated move.

A valid store (written by the store itself) is damaged value by value and as bytes.
Property: the legs' tables (finite entries matching their hashes), or StoreError naming the
file; never another exception.
"""

from __future__ import annotations

import functools
import json
import math
import tempfile
from pathlib import Path

from hypothesis import example, given, settings, strategies as st

from drivers.interfaces import TableBank
from drivers.station_compensation import LegTables, StationTableStore, StoreError
from tests.fuzz.budget import examples, fed
from tests.fuzz.jsondamage import damaged_json


@functools.cache
def store_doc() -> dict:
    with tempfile.TemporaryDirectory() as d:
        store = StationTableStore(Path(d) / "station-tables.json")
        t = TableBank(-50.0, 25.0, (1.0, 2.0, 3.0, 4.0, 5.0), (-1.0, -2.0, -3.0, -4.0, -5.0))
        store.update(3, lambda old: LegTables((old.banks[0], t), 1, True), drive="sim")
        store.update(5, lambda old: LegTables((t, old.banks[1]), 0, False), drive="sim")
        return json.loads(store.path.read_text())


@st.composite
def damaged_store(draw) -> bytes:
    doc = damaged_json(draw, store_doc(), 2)
    text = json.dumps(doc).encode()
    if draw(st.integers(0, 5)) == 0:
        i = draw(st.integers(0, len(text) - 1))
        text = text[:i] + bytes([draw(st.integers(0, 255))]) + text[i + 1:]
    return text


@settings(max_examples=examples(150))
@given(st.one_of(damaged_store(), st.binary(max_size=80)))
@example(b"\xff{}")  # found: not UTF-8 raised UnicodeDecodeError
@example(json.dumps({"format": "station-compensation-tables", "version": 1, "legs": {"3": {
    "banks": [{"start_mm": 10**400, "spacing_mm": 1, "error_fwd_um": [], "error_rev_um": [], "sha256": ""}] * 2,
    "active_bank": 0, "enabled": True}}}).encode())  # found: an integer beyond any float raised OverflowError
def test_station_table_store_fuzzed(data):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "station-tables.json"
        path.write_bytes(data)
        try:
            legs = StationTableStore(path).read()
        except StoreError as exc:
            fed("station table store JSON (StationTableStore.read)", refused=True)
            assert str(path) in str(exc), exc
            return
        fed("station table store JSON (StationTableStore.read)")
        for leg, t in legs.items():
            assert leg >= 1 and t.active_bank in (0, 1) and isinstance(t.enabled, bool) and len(t.banks) == 2
            for b in t.banks:
                assert len(b.error_fwd_um) == len(b.error_rev_um)
                assert all(math.isfinite(v) for v in (b.start_mm, b.spacing_mm, *b.error_fwd_um, *b.error_rev_um))


def test_seed_store_reads():
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "s.json"
        path.write_text(json.dumps(store_doc()))
        legs = StationTableStore(path).read()
        assert sorted(legs) == [3, 5] and legs[3].active_bank == 1 and legs[3].enabled
