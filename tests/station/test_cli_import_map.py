"""`station import`: the example maps of docs/import-maps read into sessions (their points as the
reader gives them back), and problems of the source file named by file, line and field with
nothing written (the mapping itself, procedures.io.import_map: tests/procedures/io/test_import_map.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from procedures.io.recording.reader import read_session
from station.cli import main

MAPS = Path(__file__).resolve().parents[2] / "docs" / "import-maps"

BASIC = """
[file]
delimiter = ","
decimal = "."
[columns]
target = "T"
error = "E"

[units]
target = "mm"
error = "um"
[convention]
error = "measured-nominal"
[defaults]
leg = 3
"""
"""A map of columns T (target, mm) and E (error, um, measured - nominal), every row leg 3."""


def points(path):
    p = read_session(path).points
    return p[np.argsort(p["index"])]


def basic_map(tmp_path):
    path = tmp_path / "m.toml"
    path.write_text(BASIC)
    return path


def test_the_renishaw_like_example(tmp_path, capsys):
    out = tmp_path / "r.h5"
    assert main(["import", str(MAPS / "renishaw-like.csv"), "--map", str(MAPS / "renishaw-like.toml"),
                 "--out", str(out)]) == 0
    p = points(out)
    assert len(p) == 12 and set(p["leg"]) == {1}
    # source runs 1 and 2 each hold both directions: four one-direction runs
    np.testing.assert_array_equal(p["run"], [1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4])
    np.testing.assert_array_equal(p["direction"], [1, 1, 1, -1, -1, -1] * 2)
    np.testing.assert_allclose(p["target_mm"][:3], [-80, 0, 80])
    np.testing.assert_allclose(p["error_um"][:4], [1.82, 0.05, -1.37, 0.61])
    np.testing.assert_allclose(p["air_pressure_hpa"][0], 1012.8)
    np.testing.assert_allclose(p["material_temp_c"][-1], 20.44)
    assert "imported 12 points" in capsys.readouterr().out


def test_the_api_xd_like_example_inch_decimal_comma_and_reversed_sign(tmp_path):
    out = tmp_path / "a.h5"
    assert main(["import", str(MAPS / "api-xd-like.csv"), "--map", str(MAPS / "api-xd-like.toml"),
                 "--out", str(out)]) == 0
    p = points(out)
    assert set(p["leg"]) == {2}
    np.testing.assert_allclose(p["target_mm"][:3], [-76.2, 0.0, 76.2])
    # deviation -0,000072 in as nominal - measured: the leg was 0.000072 in = 1.8288 um long
    np.testing.assert_allclose(p["error_um"][0], 1.8288, atol=1e-9)
    # no direction column: out (+) and back (-) from the target order; each cycle gives two runs
    np.testing.assert_array_equal(p["direction"], [1, 1, 1, -1, -1, -1] * 2)
    np.testing.assert_array_equal(p["run"], [1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4])


def test_interchange_problems_are_named_in_the_source_file_and_nothing_is_written(tmp_path, capsys):
    data = tmp_path / "d.csv"
    data.write_text("T,E\n0,1\n10,1\n\n20,5000\n")  # 5 mm error: no leg does that (after a blank line)
    out = tmp_path / "x.h5"
    assert main(["import", str(data), "--map", str(basic_map(tmp_path)), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{data}, line 5, field error_um (column 'E')" in err and "Traceback" not in err
    assert not out.exists() and list(tmp_path.glob("*.h5")) == []
    data.write_text("T,E\n0,1\n10,1\n300,2\n")  # beyond the soft limits
    assert main(["import", str(data), "--map", str(basic_map(tmp_path)), "--out", str(out)]) == 2
    assert f"{data}, line 4, field target_mm (column 'T')" in capsys.readouterr().err
