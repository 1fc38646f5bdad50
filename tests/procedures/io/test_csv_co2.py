"""The optional co2_ppm column of the interchange CSV: imported beside /points, exported back,
refused out of range naming file, line and field; files without it read as before."""

from __future__ import annotations

import numpy as np
import pytest

from procedures.io.csv_io import export_csv, import_csv, read_csv_points
from procedures.vocabulary import InputError
from procedures.io.recording.columns import read_point_column

HEAD = "leg,run,direction,target_mm,error_um"


def test_co2_column_round_trip(tmp_path):
    src = tmp_path / "in.csv"
    src.write_text(f"{HEAD},co2_ppm\n1,1,1,0,0.5,420\n1,1,1,10,0.6,\n1,2,-1,10,0.7,455.5\n")
    session = import_csv(src, tmp_path / "s.h5")
    co2 = read_point_column(tmp_path / "s.h5", "co2_ppm")
    assert np.array_equal(co2, [420.0, np.nan, 455.5], equal_nan=True)
    assert "co2_ppm" in session.plan["optional_columns"] and "co2_ppm" not in session.points.dtype.names
    summary = export_csv(tmp_path / "s.h5", tmp_path / "out.csv")
    assert summary.columns[-1] == "co2_ppm"
    lines = (tmp_path / "out.csv").read_text().splitlines()
    assert lines[0] == f"{HEAD},co2_ppm" and lines[1].endswith(",420.0") and lines[2].endswith(",")


def test_files_without_co2_read_and_export_as_before(tmp_path):
    src = tmp_path / "in.csv"
    src.write_text(f"{HEAD}\n1,1,1,0,0.5\n1,1,1,10,0.6\n")
    import_csv(src, tmp_path / "s.h5")
    assert read_point_column(tmp_path / "s.h5", "co2_ppm") is None
    assert export_csv(tmp_path / "s.h5", tmp_path / "out.csv").columns == tuple(HEAD.split(","))


@pytest.mark.parametrize("cell, reason", [("-5", "outside 0 .. 5000 ppm"), ("9000", "outside 0 .. 5000 ppm"),
                                          ("lots", "is not a number")])
def test_bad_co2_refused_naming_line_and_field(tmp_path, cell, reason):
    src = tmp_path / "in.csv"
    src.write_text(f"{HEAD},co2_ppm\n1,1,1,0,0.5,420\n1,1,1,10,0.6,{cell}\n")
    with pytest.raises(InputError) as exc:
        read_csv_points(src)
    assert f"{src}, line 3, field co2_ppm: " in str(exc.value) and reason in str(exc.value)
    with pytest.raises(InputError):
        import_csv(src, tmp_path / "s.h5")
    assert not (tmp_path / "s.h5").exists()
