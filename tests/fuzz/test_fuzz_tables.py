"""Fuzzing the compensation-table readers (procedures/compensation/table.py): the table CSV, and LinuxCNC
COMP_FILEs read back as LinuxCNC loads them.

Property: a table that fits the drive (TableSpec.check passes) or TableValidationError /
TableRefused naming the file; never another exception.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import example, given, settings, strategies as st

from drivers.errors import TableRefused
from procedures.vocabulary import InputError
from procedures.compensation.controllers.linuxcnc import read_linuxcnc_comp, write_linuxcnc_comp
from procedures.compensation.table import (
    CSV_HEADER,
    DEFAULT_SPEC,
    CompTable,
    LegTable,
    TableValidationError,
    read_table_csv,
)
from tests.fuzz.budget import examples, fed

number = st.one_of(
    st.floats(-400, 400).map(lambda v: f"{v:.4f}"),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["", "nan", "inf", "1e400", "0x1", "1_000", "-0", "9" * 400, "1e-320", " ", "abc"]),
)


@st.composite
def table_text(draw) -> str:
    """A well-formed table (legs in order, a fixed step) with, sometimes, one line damaged."""
    lines = [",".join(CSV_HEADER)]
    for leg in sorted(draw(st.sets(st.integers(1, 6), min_size=1, max_size=3))):
        n = draw(st.integers(1, 8))
        start = draw(st.floats(-100, 0))
        step = draw(st.sampled_from([0.5, 1.0, 12.5, 1e-7, 0.0]))
        for i in range(n):
            lines.append(f"{leg},{start + i * step:.6f},{draw(st.floats(-299, 299)):.4f},{draw(st.floats(-299, 299)):.4f}")
    if draw(st.booleans()):
        at = draw(st.integers(0, len(lines) - 1))
        kind = draw(st.sampled_from(["cell", "drop", "dup", "swap", "extra"]))
        cells = lines[at].split(",")
        if kind == "cell":
            cells[draw(st.integers(0, 3))] = draw(number)
            lines[at] = ",".join(cells)
        elif kind == "drop":
            del lines[at]
        elif kind == "dup":
            lines.insert(at, lines[at])
        elif kind == "swap" and at + 1 < len(lines):
            lines[at], lines[at + 1] = lines[at + 1], lines[at]
        else:
            lines[at] += "," + draw(number)
    return "\n".join(lines) + draw(st.sampled_from(["\n", "", "\n\n"]))


@settings(max_examples=examples(200))
@given(st.one_of(table_text().map(str.encode), st.binary(max_size=200),
                 st.text(alphabet="0123456789,.-+eE\n legpositn_mfwdruv", max_size=200).map(str.encode)))
@example(b"leg,position_mm,error_fwd_um,error_rev_um\n1,0,1,1\n1,1,1,1\n")
@example(b"leg,position_mm,error_fwd_um,error_rev_um\n1,-1e308,1,1\n1,1e308,1,1\n")  # step overflows
@example(b"leg,position_mm,error_fwd_um,error_rev_um\n" + b"9" * 5000 + b",0,1,1\n")
@example(b"\xff\xfe\x00")
def test_read_table_csv_fuzzed(data):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "table.csv"
        path.write_bytes(data)
        try:
            table = read_table_csv(path)
        except (TableValidationError, TableRefused) as exc:
            fed("table CSV (read_table_csv)", refused=True)
            assert str(path) in str(exc), exc
            return
        fed("table CSV (read_table_csv)")
        assert table.legs
        for leg, t in table.legs.items():
            assert leg >= 1
            DEFAULT_SPEC.check(t.to_bank(), "accepted table")  # what was accepted fits the drive
            assert t.point_count >= 2 and t.step_mm > 0 and math.isfinite(t.start_mm)


@settings(max_examples=examples(200))
@given(st.one_of(st.binary(max_size=200),
                 st.lists(st.lists(number, min_size=0, max_size=4).map(" ".join), max_size=10)
                 .map(lambda ls: "\n".join(ls).encode())))
@example(b"\xff 1 2\n")  # found: not UTF-8 raised UnicodeDecodeError (now: reading stops there)
@example(b"0 0 0\n1 1 1\n")
def test_read_linuxcnc_comp_fuzzed(data):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "joint0.comp"
        path.write_bytes(data)
        for comp_type in (0, 1):
            try:
                nom, fwd, rev = read_linuxcnc_comp(path, comp_type)
            except InputError as exc:
                fed("LinuxCNC COMP_FILE (read_linuxcnc_comp)", refused=True)
                assert str(path) in str(exc), exc
                continue
            fed("LinuxCNC COMP_FILE (read_linuxcnc_comp)")
            assert len(nom) == len(fwd) == len(rev)


@settings(max_examples=examples(40))
@given(st.integers(2, 256), st.floats(-90, 0), st.sampled_from([0.01, 0.5, 1.0]),
       st.lists(st.floats(-300, 300), min_size=2, max_size=2), st.sampled_from([0, 1]))
def test_linuxcnc_round_trip(n, start, step, ends, comp_type):
    """What write_linuxcnc_comp writes, LinuxCNC reads back as trims cancelling the error (to 1e-6 mm)."""
    fwd = tuple(np.linspace(ends[0], ends[1], n))
    rev = tuple(np.linspace(ends[1], ends[0], n))
    table = CompTable({1: LegTable(1, start, step, fwd, rev)})
    with tempfile.TemporaryDirectory() as d:
        (path,) = write_linuxcnc_comp(table, Path(d), comp_type)
        nom, tf, tr = read_linuxcnc_comp(path, comp_type)
        fed("LinuxCNC COMP_FILE round trip")
        assert len(nom) == n
        assert np.allclose(nom, start + step * np.arange(n), atol=1e-6)
        assert np.allclose(tf, -np.asarray(fwd) / 1000, atol=2e-6)
        assert np.allclose(tr, -np.asarray(rev) / 1000, atol=2e-6)


def test_linuxcnc_reading_stops_at_a_line_that_is_not_text(tmp_path):
    """Found by fuzzing: a byte that is not UTF-8 raised UnicodeDecodeError; LinuxCNC stops
    reading there, and so does read_linuxcnc_comp, keeping the lines before."""
    path = tmp_path / "joint0.comp"
    path.write_bytes(b"-1 -1.001 -0.999\n0 0.001 -0.001\n\xff 1 2\n1 1 1\n")
    nom, fwd, rev = read_linuxcnc_comp(path, 0)
    assert nom.tolist() == [-1.0, 0.0]
    assert np.allclose(fwd, [0.001, -0.001]) and np.allclose(rev, [-0.001, 0.001])
