"""Fuzzing the interchange CSV reader (procedures/io/csv_io.py): read_csv_points and import_csv.

Property: a result whose rows hold what a leg can produce, or InputError naming the file;
never another exception, and a failed import leaves no file behind.
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import example, given, settings, strategies as st

from procedures.io.csv_io import OPTIONAL_COLUMNS, REQUIRED_COLUMNS, import_csv, read_csv_points
from procedures.vocabulary import InputError
from procedures.io.ranges import PointLimits
from tests.fuzz.budget import examples, fed

COLUMNS = REQUIRED_COLUMNS + OPTIONAL_COLUMNS

# cells: mostly plausible values, some garbage, so rows get past the first checks
cell = st.one_of(
    st.integers(-3, 8).map(str),
    st.floats(-120, 120).map(repr),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["", "nan", "NaN", "inf", "-inf", "1e400", "1_0", "0x10", " 1 ", "+1", "-1", "1.0", "1.5",
                     "9" * 5000, "1e-400", "١", "\u00a0", '"1,2"', "1;2"]),
    st.text(max_size=12),
)


@st.composite
def csv_text(draw) -> str:
    header = draw(st.one_of(
        st.permutations(COLUMNS).flatmap(lambda cols: st.integers(5, len(cols)).map(lambda n: list(cols[:n]))),
        st.lists(st.one_of(st.sampled_from(COLUMNS), st.text(max_size=8)), max_size=12),
    ))
    rows = draw(st.lists(st.lists(cell, min_size=max(0, len(header) - 1), max_size=len(header) + 1), max_size=12))
    sep = draw(st.sampled_from(["\n", "\r\n", "\r"]))
    bom = draw(st.sampled_from(["", "\ufeff"]))
    return bom + sep.join(",".join(r) for r in [header] + rows) + draw(st.sampled_from(["", sep]))


@st.composite
def valid_ish_csv(draw) -> str:
    """Rows a leg can produce, then one cell (or none) replaced by garbage."""
    n = draw(st.integers(1, 10))
    lines = ["leg,run,direction,target_mm,error_um,air_temp_c"]
    for i in range(n):
        lines.append(f"{draw(st.integers(1, 6))},{1 + i % 3},{1 if i % 3 != 1 else -1},{i * 5.0 - 20},"
                     f"{draw(st.floats(-50, 50))!r},{draw(st.sampled_from(['', '20.5', 'nan']))}")
    if draw(st.booleans()):
        row = draw(st.integers(0, n))
        cells = lines[row].split(",")
        cells[draw(st.integers(0, len(cells) - 1))] = draw(cell)
        lines[row] = ",".join(cells)
    return "\n".join(lines) + "\n"


def _check(path: Path, data: bytes, reader: str) -> tuple[np.ndarray, list[str]] | None:
    path.write_bytes(data)
    try:
        points, optional = read_csv_points(path)
    except InputError as exc:
        fed(reader, refused=True)
        assert str(path) in str(exc), f"the message does not name the file: {exc}"
        return None
    fed(reader)
    # accepted: every row is something a leg produces
    lim = PointLimits()
    assert len(points) > 0
    assert set(np.unique(points["leg"])) <= set(lim.legs)
    assert set(np.unique(points["direction"])) <= {-1, 1}
    assert np.all(points["run"] >= 1)
    assert np.all(np.isfinite(points["target_mm"])) and np.all(np.isfinite(points["error_um"]))
    assert np.all(np.abs(points["error_um"]) <= lim.max_error_um)
    assert np.all((points["target_mm"] >= lim.stroke_mm[0]) & (points["target_mm"] <= lim.stroke_mm[1]))
    assert set(optional) <= set(OPTIONAL_COLUMNS)
    for name in OPTIONAL_COLUMNS:
        assert not np.any(np.isinf(points[name]))
    return points, optional


@settings(max_examples=examples(150))
@given(st.one_of(csv_text().map(lambda t: t.encode("utf-8", "surrogatepass")), valid_ish_csv().map(str.encode),
                 st.binary(max_size=300)))
@example(b"leg,run,direction,target_mm,error_um\n1,1,1,0,1\n")
@example(b"leg,run,direction,target_mm,error_um\n1,1e30,1,0,1\n")  # run beyond any int: refused by line
@example(b"leg,run,direction,target_mm,error_um\n" + b"9" * 5000 + b",1,1,0,1\n")
@example(b"\xff\xfeleg")
@example(b"leg,run,direction,target_mm,error_um\n\"1,1,1,0,1\n")
def test_read_csv_points_fuzzed(data):
    with tempfile.TemporaryDirectory() as d:
        _check(Path(d) / "in.csv", data, "interchange CSV (read_csv_points)")


@settings(max_examples=examples(25))
@given(valid_ish_csv())
def test_import_csv_leaves_nothing_on_refusal(text):
    with tempfile.TemporaryDirectory() as d:
        src, out = Path(d) / "in.csv", Path(d) / "out.h5"
        src.write_text(text)
        try:
            session = import_csv(src, out)
        except InputError as exc:
            fed("interchange CSV (import_csv -> HDF5)", refused=True)
            assert str(src) in str(exc)
            assert sorted(os.listdir(d)) == ["in.csv"], "a refused import left a file behind"
            return
        fed("interchange CSV (import_csv -> HDF5)")
        assert sorted(os.listdir(d)) == ["in.csv", "out.h5"]
        points, _ = read_csv_points(src)
        assert len(session.points) == len(points)
        assert np.array_equal(session.points["error_um"], points["error_um"])
        assert all(math.isfinite(v) for v in session.points["target_mm"])
