"""Compensation tables: from a model, CSV and LinuxCNC formats, limits, bad input refused."""

from __future__ import annotations

import hashlib
import re

import numpy as np
import pytest

from drivers.errors import TableRefused
from drivers.interfaces import TableBank
from drivers.plant.leg import PlantConfig
from procedures.synthetic import synth_session
from procedures.vocabulary import InputError
from procedures.fit import fit
from procedures.compensation.controllers.linuxcnc import LINUXCNC_LIMITS, read_linuxcnc_comp, write_linuxcnc_comp
from procedures.compensation.table import (
    CSV_HEADER,
    CompTable,
    LegTable,
    TableSpec,
    make_table,
    read_table_csv,
    TableValidationError,
    write_table_csv,
)

TARGETS = np.linspace(-90, 90, 121)  # 1.5 mm


@pytest.fixture(scope="module")
def model():
    cfg = PlantConfig(reversal_um=2.0).only("backlash", "lead", "longwave", "wobble", "noise")
    pts = synth_session({1: cfg, 2: cfg}, TARGETS, cycles=3, seed=7)
    return fit(pts, lead_mm=5.0)


def test_table_covers_the_stroke_at_the_recording_spacing(model):
    table = make_table(model)
    assert list(table.legs) == [1, 2]
    for leg, t in table.legs.items():
        assert t.start_mm == -90.0 and t.step_mm == pytest.approx(1.5) and t.point_count == 121
        assert t.end_mm == pytest.approx(90.0)
        np.testing.assert_allclose(t.error_fwd_um, model.predict_um(leg, t.positions_mm, 1))
        np.testing.assert_allclose(t.error_rev_um, model.predict_um(leg, t.positions_mm, -1))
        # the reversal: approaching downwards the leg is longer by ~2 um
        assert np.mean(np.subtract(t.error_rev_um, t.error_fwd_um)) == pytest.approx(2.0, abs=0.05)
    rows = list(table.rows())
    assert rows == sorted(rows, key=lambda r: (r[0], r[1]))


def test_step_is_coarsened_to_fit_the_point_limit(model):
    table = make_table(model, spec=TableSpec(max_points=50))
    t = table.legs[1]
    assert t.point_count <= 50 and t.end_mm >= 90.0 - 1e-9
    # whole steps span the stroke: the table ends on the stroke end (within the nm rounding),
    # never up to a step beyond it where it could cross the soft limits
    assert t.end_mm <= 90.0 + t.point_count * 1e-6
    assert round(t.step_mm * 1e6) == pytest.approx(t.step_mm * 1e6, abs=1e-6)  # whole nanometres


def test_too_fine_a_step_is_refused(model):
    with pytest.raises(TableRefused) as err:
        make_table(model, step_mm=0.1, spec=TableSpec(max_points=512))
    assert "1801 points" in str(err.value) and "512" in str(err.value) and "at least 0.353" in str(err.value)


def test_correction_beyond_the_drive_limit_is_refused(model):
    with pytest.raises(TableRefused, match=r"beyond the correction limit of the drive, \+/-1 um"):
        make_table(model, spec=TableSpec(max_correction_um=1.0))


def test_csv_format_and_round_trip(model, tmp_path):
    table = make_table(model)
    path = write_table_csv(table, tmp_path / "t.csv")
    record, *lines = path.read_text().splitlines()
    assert re.fullmatch(r"# integrity: table rows=242 sha256=[0-9a-f]{64}", record)  # first: procedures/io/integrity.py
    assert hashlib.sha256(("\n".join(lines) + "\n").encode()).hexdigest() == record[-64:]
    assert lines[0] == "leg,position_mm,error_fwd_um,error_rev_um" == ",".join(CSV_HEADER)
    assert len(lines) == 1 + 2 * 121
    assert lines[1].startswith("1,-90.000000,") and lines[-1].startswith("2,90.000000,")
    back = read_table_csv(path, expected_legs=2)
    for leg in (1, 2):
        a, b = table.legs[leg], back.legs[leg]
        assert b.start_mm == a.start_mm and b.step_mm == pytest.approx(a.step_mm, abs=1e-9)
        np.testing.assert_allclose(b.error_fwd_um, a.error_fwd_um, atol=5e-5)
        np.testing.assert_allclose(b.error_rev_um, a.error_rev_um, atol=5e-5)
    bank = back.legs[2].to_bank()
    assert isinstance(bank, TableBank) and bank.point_count == 121 and bank.spacing_mm == pytest.approx(1.5)


def test_invalid_table_is_not_written(tmp_path):
    t = LegTable(1, 0.0, 1.0, (0.0, 400.0), (0.0, 0.0))
    target = tmp_path / "t.csv"
    with pytest.raises(TableRefused, match="point 2 .*error_fwd_um"):
        write_table_csv(CompTable({1: t}), target)
    assert not target.exists() and list(tmp_path.iterdir()) == []
    target.write_text("keep me\n")
    with pytest.raises(TableRefused):
        write_table_csv(CompTable({1: t}), target)
    assert target.read_text() == "keep me\n"


GOOD = ["leg,position_mm,error_fwd_um,error_rev_um"] + [
    f"{leg},{x:.6f},{0.1 * i:.4f},{0.1 * i + 1:.4f}" for leg in (1, 2) for i, x in enumerate(np.arange(-2.0, 2.01, 0.5))
]


def _write(tmp_path, lines, name="bad.csv"):
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


def test_good_csv_reads(tmp_path):
    t = read_table_csv(_write(tmp_path, GOOD, "good.csv"), expected_legs=2)
    assert t.legs[1].point_count == 9 and t.legs[2].step_mm == pytest.approx(0.5)


def _replace(row, field, value):
    cells = GOOD[row - 1].split(",")
    cells[CSV_HEADER.index(field)] = value
    out = list(GOOD)
    out[row - 1] = ",".join(cells)
    return out


@pytest.mark.parametrize(
    "lines, limits, expected_legs, where",
    [
        (_replace(4, "position_mm", "-1.500000"), None, None, "row 4, field position_mm"),  # repeated position
        (_replace(4, "position_mm", "-1.700000"), None, None, "row 4, field position_mm"),  # not increasing
        (_replace(5, "position_mm", "-0.400000"), None, None, "row 5, field position_mm: step"),  # uneven
        (_replace(6, "error_rev_um", "301"), None, None, "row 6, field error_rev_um"),  # beyond 300 um
        (_replace(3, "error_fwd_um", "abc"), None, None, "row 3, field error_fwd_um"),
        (_replace(3, "leg", "x"), None, None, "row 3, field leg"),
        (_replace(3, "error_fwd_um", "nan"), None, None, "row 3, field error_fwd_um"),
        (GOOD, TableSpec(max_points=8), None, "leg 1: the table has 9 points (row 10 is one too many)"),  # too many points
        (GOOD, None, 6, "expected [1, 2, 3, 4, 5, 6]"),  # another leg count
        (GOOD[:1] + GOOD[10:] + GOOD[1:10], None, None, "row 11, field leg"),  # legs out of order
        (["position_mm,leg,error_fwd_um,error_rev_um"] + GOOD[1:], None, None, "row 1: header"),
        (GOOD[:2] + ["1,-1.5,0.1"] + GOOD[3:], None, None, "row 3: 3 field(s)"),
        (GOOD, TableSpec(min_step_mm=1.0), None, "row 3, field position_mm: the step 0.5 mm is not a number >= the minimum"),
    ],
)
def test_bad_csv_is_refused_naming_file_row_and_field(tmp_path, lines, limits, expected_legs, where):
    path = _write(tmp_path, lines)
    with pytest.raises((InputError, TableRefused)) as err:  # malformed file / a table the drive cannot hold
        read_table_csv(path, limits, expected_legs)
    msg = str(err.value)
    assert str(path) in msg and where in msg


# -- LinuxCNC -----------------------------------------------------------------------------------

def linuxcnc_load(path, comp_type):
    """What LinuxCNC does (usrmotLoadComp): read triplets until a line is not three numbers;
    type 0 is converted to trims as nominal - value."""
    nom, fwd, rev = [], [], []
    for line in open(path):
        parts = line.split()
        if len(parts) != 3:
            break
        n, a, b = map(float, parts)
        if comp_type == 0:
            a, b = n - a, n - b
        nom.append(n)
        fwd.append(a)
        rev.append(b)
    return np.array(nom), np.array(fwd), np.array(rev)


def linuxcnc_motor_mm(nom, fwd_trim, rev_trim, pos_cmd_mm, moving_up):
    """control.c: trim interpolated linearly at the commanded position, chosen by the sign of
    the commanded velocity, ends held; motor command = position command + trim."""
    trim = np.interp(pos_cmd_mm, nom, fwd_trim if moving_up else rev_trim)
    return pos_cmd_mm + trim


@pytest.mark.parametrize("comp_type", [0, 1])
def test_linuxcnc_files_cancel_the_modelled_error(model, tmp_path, comp_type):
    table = make_table(model, spec=LINUXCNC_LIMITS)
    paths = write_linuxcnc_comp(table, tmp_path / "comp", comp_type)
    assert [p.name for p in paths] == ["joint0.comp", "joint1.comp"]
    for leg, path in zip((1, 2), paths):
        lines = path.read_text().splitlines()
        assert 2 <= len(lines) <= 256
        rows = [tuple(map(float, line.split())) for line in lines]  # every line: three numbers, no header
        assert all(len(r) == 3 for r in rows)
        nominal = [r[0] for r in rows]
        assert all(b > a for a, b in zip(nominal, nominal[1:]))
        nom, fwd, rev = linuxcnc_load(path, comp_type)
        assert len(nom) == len(lines)  # the parser read every line
        np.testing.assert_allclose(np.column_stack(read_linuxcnc_comp(path, comp_type)), np.column_stack([nom, fwd, rev]))
        x = np.linspace(-89.0, 89.0, 301)
        for up in (True, False):
            d = 1 if up else -1
            motor = linuxcnc_motor_mm(nom, fwd, rev, x, up)
            actual = motor + model.predict_um(leg, motor, d) / 1000.0  # the leg's error at the motor command
            uncompensated = model.predict_um(leg, x, d)
            left_um = (actual - x) * 1000.0
            assert np.abs(uncompensated).max() > 1.0
            # what is left is only the table's linear interpolation between its points (the 5 mm
            # wobble on a 1.5 mm step), up to second-order terms and the 1 nm file resolution
            interpolation_um = uncompensated - table.legs[leg].correction_um(x, d)
            np.testing.assert_allclose(left_um, interpolation_um, atol=0.005)
            assert np.abs(left_um).max() < 0.1


def test_linuxcnc_file_naming(model, tmp_path):
    table = make_table(model, spec=LINUXCNC_LIMITS)
    paths = write_linuxcnc_comp(table, tmp_path / "leg.comp", 1)
    assert [p.name for p in paths] == ["leg_joint0.comp", "leg_joint1.comp"]


def test_linuxcnc_refuses_more_than_256_lines_and_writes_nothing(tmp_path):
    t = LegTable(1, 0.0, 0.1, tuple([0.0] * 300), tuple([0.0] * 300))
    t2 = LegTable(2, 0.0, 0.1, tuple([0.0] * 10), tuple([0.0] * 10))
    with pytest.raises(TableRefused, match="LinuxCNC holds at most 256"):
        write_linuxcnc_comp(CompTable({1: t, 2: t2}), tmp_path / "out.comp", 0)
    assert list(tmp_path.iterdir()) == []


def test_positions_near_the_float_limit_are_refused_naming_the_rows(tmp_path):
    # found by fuzzing: the mean step of such positions overflowed to inf (a RuntimeWarning, then
    # a table with an infinite step when read unchecked)
    p = tmp_path / "t.csv"
    p.write_text("leg,position_mm,error_fwd_um,error_rev_um\n1,-1.7e308,0,0\n1,0,0,0\n1,1.7e308,0,0\n")
    with pytest.raises(TableValidationError, match=r"rows 2\.\.4, field position_mm: leg 1's positions span"):
        read_table_csv(p, check=False)
