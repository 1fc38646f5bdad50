"""Import of other laser software's CSV through a mapping file (procedures.io.import_map): units, sign
conventions, direction from a column or the target order, run numbering, delimiters and decimal
commas, header lines; bad maps and bad files refused naming the file, line and field/key, and
nothing written. (The example maps and the refusals of `station import`: tests/station/test_cli_import_map.py.)"""

from __future__ import annotations

import numpy as np
import pytest

from procedures.vocabulary import InputError
from procedures.io.import_map import convert, load_map


def write_map(tmp_path, text, name="m.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


BASIC = """
[file]
delimiter = "{delimiter}"
decimal = "{decimal}"
[columns]
target = "T"
{error_key} = "E"
{extra}
[units]
target = "{tu}"
error = "{eu}"
[convention]
error = "{conv}"
[defaults]
leg = 3
"""


def basic_map(tmp_path, delimiter=",", decimal=".", error_key="error", tu="mm", eu="um", conv="measured-nominal",
              extra=""):
    return write_map(tmp_path, BASIC.format(delimiter=delimiter, decimal=decimal, error_key=error_key, tu=tu, eu=eu,
                                            conv=conv, extra=extra))


@pytest.mark.parametrize("tu, eu, t_text, e_text, target_mm, error_um", [
    ("mm", "um", "12.5", "1.5", 12.5, 1.5),
    ("inch", "inch", "1", "0.0001", 25.4, 2.54),
    ("um", "nm", "-2500", "750", -2.5, 0.75),
    ("mm", "mm", "3", "-0.002", 3.0, -2.0),
])
def test_units(tmp_path, tu, eu, t_text, e_text, target_mm, error_um):
    m = load_map(basic_map(tmp_path, tu=tu, eu=eu))
    data = tmp_path / "d.csv"
    data.write_text(f"T,E\n{t_text},{e_text}\n{float(t_text) + 1},{e_text}\n")
    conv = convert(data, m)
    row = conv.csv_text.splitlines()[1].split(",")
    assert row[0] == "3" and row[2] == "+1"
    assert float(row[3]) == pytest.approx(target_mm) and float(row[4]) == pytest.approx(error_um)


def test_sign_convention_and_measured_position(tmp_path):
    data = tmp_path / "d.csv"
    data.write_text("T,E\n10,2\n20,3\n")
    ours = convert(data, load_map(basic_map(tmp_path)))
    theirs = convert(data, load_map(basic_map(tmp_path, conv="nominal-measured")))
    assert [float(r.split(",")[4]) for r in ours.csv_text.splitlines()[1:]] == [2.0, 3.0]
    assert [float(r.split(",")[4]) for r in theirs.csv_text.splitlines()[1:]] == [-2.0, -3.0]
    data.write_text("T,E\n10,10.002\n20,19.999\n")  # measured positions, mm
    measured = convert(data, load_map(basic_map(tmp_path, error_key="measured", eu="mm")))
    np.testing.assert_allclose([float(r.split(",")[4]) for r in measured.csv_text.splitlines()[1:]], [2.0, -1.0], atol=1e-9)


def test_direction_from_order_splits_passes_into_runs(tmp_path):
    data = tmp_path / "d.csv"
    # two forward passes in a row, then one backward: three runs
    data.write_text("T,E\n0,1\n5,1\n10,1\n0,2\n5,2\n10,2\n10,3\n5,3\n0,3\n")
    rows = [r.split(",") for r in convert(data, load_map(basic_map(tmp_path))).csv_text.splitlines()[1:]]
    assert [r[1] for r in rows] == ["1"] * 3 + ["2"] * 3 + ["3"] * 3
    assert [r[2] for r in rows] == ["+1"] * 6 + ["-1"] * 3


def test_direction_column_semicolons_decimal_comma_header_lines_and_indices(tmp_path):
    m = write_map(tmp_path, """
[file]
delimiter = ";"
decimal = ","
skip_lines = 2
header = false
[columns]
target = 2
error = 4
direction = 3
leg = 1
[convention]
forward = ["up"]
reverse = ["down"]
""")
    data = tmp_path / "d.txt"
    data.write_text("title\n\n4;1,5;up;0,25\n4;3,0;up;0,5\n4;3,0;down;0,75\n")
    rows = [r.split(",") for r in convert(data, load_map(m)).csv_text.splitlines()[1:]]
    assert rows == [["4", "1", "+1", "1.5", "0.25"], ["4", "1", "+1", "3.0", "0.5"], ["4", "2", "-1", "3.0", "0.75"]]


@pytest.mark.parametrize("text, where", [
    ("[columns]\ntarget = 'T'\nerror = 'E'\n[defaults]\nleg = 1\n[units]\nerror = 'furlong'\n", "key units.error: 'furlong'"),
    ("[columns]\ntarget = 'T'\nerror = 'E'\nmeasured = 'M'\n[defaults]\nleg = 1\n", "key columns.error: give exactly one"),
    ("[columns]\nerror = 'E'\n[defaults]\nleg = 1\n", "key columns.target: missing"),
    ("[columns]\ntarget = 'T'\nerror = 'E'\n", "key defaults.leg: missing"),
    ("[columns]\ntarget = 'T'\nerror = 'E'\ncolour = 'C'\n[defaults]\nleg = 1\n", "key columns.colour: unknown key"),
    ("[file]\ndecimal = ','\n[columns]\ntarget = 'T'\nerror = 'E'\n[defaults]\nleg = 1\n", "key file.decimal: a decimal comma"),
    ("[file]\nheader = false\n[columns]\ntarget = 'T'\nerror = 2\n[defaults]\nleg = 1\n", "key columns.target: 'T' is a name"),
    ("[columns]\ntarget = 0\nerror = 'E'\n[defaults]\nleg = 1\n", "key columns.target: 0 must be"),
    ("[convention]\nerror = 'sideways'\n[columns]\ntarget = 'T'\nerror = 'E'\n[defaults]\nleg = 1\n", "key convention.error"),
    ("columns = [", "not a TOML map file"),
])
def test_bad_maps_are_refused_naming_the_key(tmp_path, text, where):
    path = write_map(tmp_path, text)
    with pytest.raises(InputError) as exc:
        load_map(path)
    assert str(path) in str(exc.value) and where in str(exc.value)


@pytest.mark.parametrize("data, where", [
    ("T,E\n1,2\nx,3\n", "d.csv, line 3, column 'T' (map key columns.target): 'x' is not a number"),
    ("T,E\n1,2\n2,3,4\n", "d.csv, line 3: 3 fields, but the header has 2"),
    ("A,E\n1,2\n", "d.csv, line 1: no column 'T' (map"),
    ("T,E\n1,2\n1,2\n", "d.csv, line 2: cannot tell the approach direction"),
    ("T,E\n1,\"1,5\"\n2,3\n", "d.csv, line 2, column 'E' (map key columns.error): '1,5' is not a number (decimal comma?"),
])
def test_bad_files_are_refused_naming_line_and_column(tmp_path, data, where):
    path = tmp_path / "d.csv"
    path.write_text(data)
    with pytest.raises(InputError, match=None) as exc:
        convert(path, load_map(basic_map(tmp_path)))
    assert where in str(exc.value)
