"""CSV interchange: import checks, round trip, and nothing written on bad input."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from procedures.io.csv_io import OPTIONAL_COLUMNS, REQUIRED_COLUMNS, export_csv, import_csv, read_csv_points
from procedures.vocabulary import InputError
from procedures.io.recording.schema import FLAG_IMPORTED
from procedures.io.recording.writer import SessionWriter


def _csv_files(shared: Path) -> list[Path]:
    return sorted((shared / "real").glob("*.csv")) + sorted((shared / "examples").glob("*.csv"))


def _read_plain(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        return list(reader.fieldnames), list(reader)


def test_round_trip_of_every_shared_file_preserves_values(shared_data, tmp_path):
    files = _csv_files(shared_data)
    assert len(files) >= 10
    for src in files:
        h5, back = tmp_path / f"{src.stem}.h5", tmp_path / f"{src.stem}.csv"
        session = import_csv(src, h5)
        summary = export_csv(h5, back)
        cols_in, rows_in = _read_plain(src)
        cols_out, rows_out = _read_plain(back)
        assert cols_out == cols_in, src.name  # the shared files have every optional column filled or absent
        assert summary.rows == len(rows_in) == len(rows_out) == len(session.points)
        for a, b in zip(rows_in, rows_out):
            for c in cols_in:
                assert float(a[c]) == float(b[c]), (src.name, c, a, b)


def test_imported_points_are_derived_as_documented(shared_data, tmp_path):
    src = shared_data / "real" / "ecmccomgui_report_2.csv"
    _, rows = _read_plain(src)
    s = import_csv(src, tmp_path / "r.h5", operator="olga")
    p = s.points
    assert s.attrs["rig"] == "import" and s.outcome == "completed" and s.attrs["operator"] == "olga"
    assert s.plan["kind"] == "import" and s.plan["source"] == src.name and len(s.plan["source_sha256"]) == 64
    assert list(p["index"]) == list(range(len(rows)))
    target = np.array([float(r["target_mm"]) for r in rows])
    error = np.array([float(r["error_um"]) for r in rows])
    assert np.array_equal(p["target_mm"], target) and np.array_equal(p["commanded_mm"], target)
    assert np.array_equal(p["error_um"], error)
    assert np.allclose(p["measured_mm"], target + error / 1000, rtol=0, atol=1e-12)
    assert np.all(p["flags"] == FLAG_IMPORTED)
    assert list(p["direction"]) == [int(r["direction"]) for r in rows]
    # columns the file does not have are unknown, never zero
    for name in OPTIONAL_COLUMNS + ("drive_position_mm", "signal_pct"):
        assert np.all(np.isnan(p[name])), name


def test_missing_optional_values_stay_unknown_and_all_unknown_columns_are_not_exported(tmp_path):
    src = tmp_path / "in.csv"
    src.write_text("leg,run,direction,target_mm,error_um,air_temp_c,load_n\n"
                   "1,1,+1,0.0,1.5,20.5,\n"
                   "1,1,1,1.0,-0.25,,nan\n"
                   "1,2,-1,1.0,0.75,21,\n")
    s = import_csv(src, tmp_path / "s.h5")
    assert np.array_equal(s.points["air_temp_c"], [20.5, np.nan, 21.0], equal_nan=True)
    assert np.all(np.isnan(s.points["load_n"])) and np.all(np.isnan(s.points["time_s"]))
    summary = export_csv(tmp_path / "s.h5", tmp_path / "out.csv")
    cols, rows = _read_plain(tmp_path / "out.csv")
    assert cols == list(REQUIRED_COLUMNS) + ["air_temp_c"] == list(summary.columns)
    assert [r["air_temp_c"] for r in rows] == ["20.5", "", "21.0"]
    assert [r["direction"] for r in rows] == ["1", "1", "-1"]


def test_export_orders_by_plan_index_and_skips_points_without_error(tmp_path):
    path = tmp_path / "s.h5"
    with SessionWriter.create(path, session_id="x", operator="", rig="sim", plan={}, station_config={},
                              devices={}, software_version="t") as w:
        for i in (2, 0, 1, 3):  # recorded out of order, as after a resume
            w.append_point(dict(index=i, leg=1, run=1, direction=1, target_mm=float(i),
                                error_um=math.nan if i == 3 else i / 4))
        w.finish("completed")
    summary = export_csv(path, tmp_path / "out.csv")
    _, rows = _read_plain(tmp_path / "out.csv")
    assert [r["target_mm"] for r in rows] == ["0.0", "1.0", "2.0"] and summary.skipped_no_error == 1


BAD = {
    "missing_column": ("leg,run,direction,error_um\n1,1,1,0.5\n", r"line 1: missing required column target_mm"),
    "non_numeric": ("leg,run,direction,target_mm,error_um\n1,1,1,0,0.1\n1,1,1,2,abc\n",
                    r"line 3, field error_um: 'abc' is not a number"),
    "nan_required": ("leg,run,direction,target_mm,error_um\n1,1,1,nan,0.1\n",
                     r"line 2, field target_mm: 'nan': the value is NaN"),
    "empty_required": ("leg,run,direction,target_mm,error_um\n1,1,1,0,\n", r"line 2, field error_um: empty"),
    "direction": ("leg,run,direction,target_mm,error_um\n1,1,1,0,0\n1,2,0,0,0\n",
                  r"line 3, field direction: 0 is not \+1 or -1"),
    "leg_zero": ("leg,run,direction,target_mm,error_um\n0,1,1,0,0\n", r"line 2, field leg: 0 is not allowed"),
    "fractional_run": ("leg,run,direction,target_mm,error_um\n1,1.5,1,0,0\n",
                       r"line 2, field run: '1.5' is not a whole number"),
    "mixed_run": ("leg,run,direction,target_mm,error_um\n1,1,1,0,0\n1,1,1,1,0\n1,1,-1,2,0\n",
                  r"line 4, field direction: run 1 of leg 1 mixes directions \(\+1 from line 2, -1 here\)"),
    "duplicate": ("leg,run,direction,target_mm,error_um\n1,1,1,0,0\n1,1,1,1,0\n1,1,1,1.000,0.3\n",
                  r"line 4: duplicate of line 3 \(leg 1, run 1, target_mm 1.0\)"),
    "field_count": ("leg,run,direction,target_mm,error_um\n1,1,1,0\n", r"line 2: 4 fields, but the header has 5"),
    "unknown_column": ("leg,run,direction,target_mm,error_um,temperature\n1,1,1,0,0,20\n",
                       r"line 1, field temperature: unknown column"),
    "empty": ("", r"the file is empty"),
    "header_only": ("leg,run,direction,target_mm,error_um\n", r"header but no data rows"),
    "semicolons": ("leg;run;direction;target_mm;error_um\n1;1;1;0;0\n", r"semicolon-separated"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_csv_is_refused_with_line_and_reason_and_nothing_is_written(tmp_path, case):
    text, pattern = BAD[case]
    src = tmp_path / "bad.csv"
    src.write_text(text)
    out = tmp_path / "out.h5"
    with pytest.raises(InputError, match=pattern) as err:
        import_csv(src, out)
    assert str(err.value).startswith(str(src))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.csv"], "nothing may be written"


def test_several_problems_are_reported_together(tmp_path):
    src = tmp_path / "bad.csv"
    src.write_text("leg,run,direction,target_mm,error_um\n" + "".join(f"1,{i},1,0,x\n" for i in range(1, 10)))
    with pytest.raises(InputError) as err:
        read_csv_points(src)
    msg = str(err.value)
    assert "line 2," in msg and "line 6," in msg and "line 7," not in msg and "(and 4 more problems)" in msg


def test_existing_output_is_not_replaced_without_overwrite(shared_data, tmp_path):
    src = shared_data / "real" / "ecmccomgui_report_7.csv"
    out = tmp_path / "s.h5"
    out.write_bytes(b"precious")
    with pytest.raises(InputError, match="exists; add --force"):
        import_csv(src, out)
    assert out.read_bytes() == b"precious"
    assert len(import_csv(src, out, overwrite=True).points) == 50
