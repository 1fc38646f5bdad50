"""Controller formats: each file, read back through its reader applying the controller's
documented rule (interpolation, direction selection, ends held), gives the correction -e(x) of
the modelled leg at many positions both ways, within the format's resolution; a file with a
flipped sign or swapped directions fails that check; malformed files are refused naming the
file, line and field."""

from __future__ import annotations

import re

import numpy as np
import pytest

from drivers.errors import TableRefused
from drivers.plant.leg import PlantConfig
from procedures.compensation.controllers import ecmc, heidenhain, linuxcnc, siemens840d, twincat
from procedures.compensation.controllers.common import ControllerFileError
from procedures.fit import fit
from procedures.compensation.controllers.linuxcnc import LINUXCNC_LIMITS
from procedures.compensation.table import CompTable, LegTable, make_table
from procedures.synthetic import synth_session

X = np.concatenate([np.linspace(-95, 95, 397), [-90.0, 0.0, 90.0]])  # between points, on them, beyond the table


@pytest.fixture(scope="module")
def model():
    cfg = PlantConfig(reversal_um=2.0).only("backlash", "lead", "longwave", "wobble", "noise")
    return fit(synth_session({1: cfg, 2: cfg}, np.linspace(-90, 90, 121), cycles=3, seed=7), lead_mm=5.0)


@pytest.fixture(scope="module")
def table(model):
    return make_table(model, spec=LINUXCNC_LIMITS)  # 121 points, 1.5 mm: fits every format


def deviation_mm(reader, expected, xs=X) -> float:
    """max over positions and both directions of |controller's correction - expected|."""
    return max(float(np.max(np.abs(reader.applied_mm(xs, d) - expected(xs, d)))) for d in (1, -1))


def minus_e(t: LegTable, shift_mm: float = 0.0):
    """The station table's -e(x) in mm (its own rule: linear, ends held), optionally shifted."""
    return lambda x, d: -(np.asarray(t.correction_um(x, d)) / 1000.0 - shift_mm)


def check_against_fit(model, leg, reader, resolution_mm, shift_mm=0.0):
    """On the table points the correction equals -e(x) of the fitted model itself."""
    t_pos = np.linspace(-90, 90, 121)
    fit_expected = lambda x, d: -(np.asarray(model.predict_um(leg, x, d)) / 1000.0 - shift_mm)  # noqa: E731
    assert deviation_mm(reader, fit_expected, t_pos) <= resolution_mm / 2 + 1e-12


def flip_numbers(text: str, pattern: str) -> str:
    """Negate the number after each match of `pattern` (a regex ending where the number starts)."""
    def neg(m):
        v = m.group(2)
        return m.group(1) + (v[1:] if v.startswith("-") else "-" + v.lstrip("+"))
    return re.sub(pattern + r"([-+]?\d[\d.]*)", neg, text, flags=re.M)


# -- LinuxCNC ---------------------------------------------------------------------------------

@pytest.mark.parametrize("comp_type", [0, 1])
def test_linuxcnc_round_trip_and_flips(model, table, tmp_path, comp_type):
    for path, (leg, t) in zip(linuxcnc.write(table, tmp_path / f"t{comp_type}", comp_type), table.legs.items()):
        comp = linuxcnc.load(path, comp_type)
        res = linuxcnc.RESOLUTION_MM * (2 if comp_type == 0 else 1)  # type 0: two rounded numbers per trim
        assert deviation_mm(comp, minus_e(t)) <= res / 2 + 1e-12
        check_against_fit(model, leg, comp, res)
        rows = [line.split() for line in path.read_text().splitlines()]
        swapped = tmp_path / f"swapped{leg}.comp"
        swapped.write_text("".join(f"{a} {c} {b}\n" for a, b, c in rows))
        assert deviation_mm(linuxcnc.load(swapped, comp_type), minus_e(t)) > 1e-3  # the 2 um reversal
        if comp_type == 1:
            flipped = tmp_path / f"flipped{leg}.comp"
            flipped.write_text("".join(f"{a} {-float(b):.6f} {-float(c):.6f}\n" for a, b, c in rows))
            assert deviation_mm(linuxcnc.load(flipped, 1), minus_e(t)) > 1e-3


# -- Siemens 840D -------------------------------------------------------------------------------

def test_siemens_cec_round_trip_zero_at_reference_and_flips(model, table, tmp_path):
    paths = siemens840d.write(table, tmp_path / "sie", reference_mm=0.0)
    assert [p.name for p in paths] == ["leg1.ini", "leg2.ini"]
    for path, (leg, t) in zip(paths, table.legs.items()):
        txt = path.read_text()
        assert f"$AN_CEC_INPUT_AXIS[{2 * leg - 2}]=(AX{leg})" in txt and f"$AN_CEC_DIRECTION[{2 * leg - 1}]=-1" in txt
        comp = siemens840d.load(path)
        shift = siemens840d.reference_shift_mm(t, 0.0)
        assert float(comp.value_mm(0.0, 1)) == pytest.approx(0.0, abs=1e-6)  # zero at the reference point
        assert deviation_mm(comp, minus_e(t, shift)) <= siemens840d.RESOLUTION_MM / 2 + 1e-12
        check_against_fit(model, leg, comp, siemens840d.RESOLUTION_MM, shift)
        swapped = path.with_name("swapped.ini")
        swapped.write_text(txt.replace("_DIRECTION[%d]=1" % (2 * leg - 2), "_DIRECTION[%d]=X" % (2 * leg - 2))
                           .replace("_DIRECTION[%d]=-1" % (2 * leg - 1), "_DIRECTION[%d]=1" % (2 * leg - 1))
                           .replace("_DIRECTION[%d]=X" % (2 * leg - 2), "_DIRECTION[%d]=-1" % (2 * leg - 2)))
        assert deviation_mm(siemens840d.load(swapped), minus_e(t, shift)) > 1e-3
        flipped = path.with_name("flipped.ini")
        flipped.write_text(flip_numbers(txt, r"^(\$AN_CEC\[\d+,\d+\]=)"))
        assert deviation_mm(siemens840d.load(flipped), minus_e(t, shift)) > 1e-3


def test_siemens_enc_comp_is_the_mean_of_both_directions(table, tmp_path):
    (path, _) = siemens840d.write(table, tmp_path / "enc.ini", mode="enc_comp")
    assert path.name == "enc_leg1.ini" and "$AA_ENC_COMP[0,0,AX1]=" in path.read_text()
    t = table.legs[1]
    comp = siemens840d.load(path)
    shift = siemens840d.reference_shift_mm(t, 0.0)
    mean = lambda x, d: -((np.asarray(t.correction_um(x, 1)) + np.asarray(t.correction_um(x, -1))) / 2000.0 - shift)  # noqa: E731
    assert deviation_mm(comp, mean) <= 1e-6
    # one table for both directions leaves half the reversal (~1 um) on each side
    assert 0.8e-3 < deviation_mm(comp, minus_e(t, shift)) < 1.2e-3


# -- HEIDENHAIN ---------------------------------------------------------------------------------

def test_heidenhain_round_trip_and_flips(model, table, tmp_path):
    paths = heidenhain.write(table, tmp_path / "hh")
    assert [p.name for p in paths] == ["leg1.COM", "leg2.COM"]
    for path, (leg, t) in zip(paths, table.legs.items()):
        lines = path.read_text().splitlines()
        assert lines[0] == f"BEGIN LEG{leg}.COM MM" and lines[1].split() == ["NR", "AXISPOS", "X", "BACKLASH"]
        assert lines[-1] == "[END]" and len(lines) == t.point_count + 3
        comp = heidenhain.load(path)
        assert deviation_mm(comp, minus_e(t)) <= heidenhain.RESOLUTION_MM / 2 + 1e-12
        check_against_fit(model, leg, comp, heidenhain.RESOLUTION_MM)
        swapped = path.with_name("swapped.COM")
        swapped.write_text("\n".join(lines[:2] + [" ".join(r.split()[i] for i in (0, 1, 3, 2)) for r in lines[2:-1]]
                                     + ["[END]"]) + "\n")
        assert deviation_mm(heidenhain.load(swapped), minus_e(t)) > 1e-3
        flipped = path.with_name("flipped.COM")
        flipped.write_text("\n".join(lines[:2] + [" ".join(c if i < 2 else f"{-float(c):+.4f}" for i, c in enumerate(r.split()))
                                                  for r in lines[2:-1]] + ["[END]"]) + "\n")
        assert deviation_mm(heidenhain.load(flipped), minus_e(t)) > 1e-3


def test_heidenhain_refuses_more_than_256_rows_and_writes_nothing(tmp_path):
    t = LegTable(1, 0.0, 0.1, tuple([0.0] * 300), tuple([0.0] * 300))
    with pytest.raises(TableRefused, match="256"):
        heidenhain.write(CompTable({1: t}), tmp_path / "out")
    assert not (tmp_path / "out").exists() or list((tmp_path / "out").iterdir()) == []


# -- Beckhoff TwinCAT ---------------------------------------------------------------------------

def test_twincat_round_trip_units_and_flips(model, table, tmp_path):
    paths = twincat.write(table, tmp_path / "tc")
    assert [p.name for p in paths] == ["achskw1.lis", "achskw2.lis"]
    for path, (leg, t) in zip(paths, table.legs.items()):
        txt = path.read_text()
        # 0.1 um units: -90 mm is -900000; the first value is e_fwd(-90 mm) in 0.1 um, measured - programmed
        assert re.search(r"^kw\.ssfk\.table\[0\]\.setpoint\s+-900000$", txt, re.M)
        assert re.search(rf"^kw\.ssfk\.table\[0\]\.pos\s+{round(t.error_fwd_um[0] * 10)}$", txt, re.M)
        comp = twincat.load(path)
        assert deviation_mm(comp, minus_e(t)) <= twincat.RESOLUTION_MM / 2 + 1e-12
        check_against_fit(model, leg, comp, twincat.RESOLUTION_MM)
        swapped = path.with_name("swapped.lis")
        swapped.write_text(txt.replace("].pos ", "].tmp ").replace("].neg ", "].pos ").replace("].tmp ", "].neg "))
        assert deviation_mm(twincat.load(swapped), minus_e(t)) > 1e-3
        flipped = path.with_name("flipped.lis")
        flipped.write_text(flip_numbers(txt, r"^(kw\.ssfk\.table\[\d+\]\.(?:pos|neg)\s+)"))
        assert deviation_mm(twincat.load(flipped), minus_e(t)) > 1e-3


# -- EPICS ecmc ---------------------------------------------------------------------------------

def exact_inverse(t: LegTable, direction: str):
    """Where the axis must stop (raw) so that raw + e(raw) = target, minus the target: what a
    correction on the encoder reading achieves."""
    def e_mm(x):
        f, r = np.asarray(t.correction_um(x, 1)) / 1000.0, np.asarray(t.correction_um(x, -1)) / 1000.0
        return {"mean": (f + r) / 2, "fwd": f, "rev": r}[direction]

    def expected(x, d):
        x = np.asarray(x, dtype=float)
        raw = x.copy()
        for _ in range(50):
            raw = x - e_mm(raw)
        return raw - x
    return expected


@pytest.mark.parametrize("direction", ["fwd", "rev", "mean"])
def test_ecmc_round_trip_scale_and_flips(table, tmp_path, direction):
    (path, _) = ecmc.write(table, tmp_path / f"{direction}.lut", direction=direction)
    t = table.legs[1]
    lines = path.read_text().splitlines()
    assert lines[0].startswith("#") and "PREC=10" in lines
    lut = ecmc.load(path)
    assert deviation_mm(lut, exact_inverse(t, direction)) <= 1e-9
    # the corrected reading at the stop is the target: the leg is where it was sent
    x = np.linspace(-95, 95, 50)
    np.testing.assert_allclose(lut.corrected_mm(x + lut.applied_mm(x)), x, atol=1e-12)
    # scale -1 flips the sign: the same file then doubles the error
    assert deviation_mm(ecmc.load(path, scale=-1.0), exact_inverse(t, direction)) > 1e-3
    if direction != "mean":
        other = "rev" if direction == "fwd" else "fwd"  # a table written for the other direction
        assert deviation_mm(lut, exact_inverse(t, other)) > 1e-3


# -- bad files ---------------------------------------------------------------------------------

@pytest.mark.parametrize("module, name, content, where", [
    (heidenhain, "a.COM", "BEGIN A.COM MM\nNR AXISPOS X BACKLASH\n0 -1.0 +0.001 +0.002\n1 x +0.001 +0.002\n[END]\n",
     r"a\.COM, line 4, field AXISPOS: 'x' is not a number"),
    (heidenhain, "b.COM", "BEGIN B.COM MM\nNR AXISPOS X BACKLASH\n0 -1.0 +0.001 +0.002\n1 -2.0 +0.001 +0.002\n[END]\n",
     r"b\.COM, line 4, field AXISPOS: -2 is not above"),
    (heidenhain, "c.COM", "BEGIN C.COM MM\nNR AXISPOS X BACKLASH\n0 -1.0 +0.001 +0.002\n1 0.0 +0.001 +0.002\n",
     r"c\.COM, line 4: no \[END\]"),
    (twincat, "a.lis", "kw.ssfk.unit 1\nkw.ssfk.bilateral 1\nkw.ssfk.table[0].setpoint 0\nkw.ssfk.table[1].setpoint 10\n"
     "kw.ssfk.table[0].pos 1.5\n", r"a\.lis, line 5, field kw\.ssfk\.table\[0\]\.pos: '1\.5' is not an integer"),
    (twincat, "b.lis", "kw.ssfk.unit 1\nkw.ssfk.bilateral 1\nkw.ssfk.table[0].setpoint 0\nkw.ssfk.table[1].setpoint 10\n"
     "kw.ssfk.table[0].pos 1\nkw.ssfk.table[1].pos 1\nkw.ssfk.table[0].neg 1\n", r"b\.lis, field kw\.ssfk\.table\[1\]\.neg: missing"),
    (twincat, "c.lis", "kw.ssfk.unit 2\n", r"c\.lis, line 1, field kw\.ssfk\.unit: 2 is not supported"),
    (ecmc, "a.lut", "# x\n0 0\n1 0\n1 0.1\n", r"a\.lut, line 4, field position: 1 is not above"),
    (ecmc, "b.lut", "0 0\n1 zero\n2 0\n", r"b\.lut, line 2, field correction: 'zero' is not a number"),
    (ecmc, "c.lut", "0 0\n1 0\n", r"c\.lut: 2 row\(s\); ecmc needs at least 3"),
    (siemens840d, "a.ini", "CHANDATA(1)\n$AN_CEC[0,0]=0.1\n$AN_CEC[0,1]=abc\n", r"a\.ini, line 3, field \$AN_CEC: 'abc'"),
    (siemens840d, "b.ini", "$AN_CEC[0,0]=0\n$AN_CEC[0,1]=0\n$AN_CEC_INPUT_AXIS[0]=(AX1)\n$AN_CEC_OUTPUT_AXIS[0]=(AX1)\n"
     "$AN_CEC_STEP[0]=1\n$AN_CEC_MIN[0]=0\n$AN_CEC_MAX[0]=1\n$AN_CEC_DIRECTION[0]=2\n",
     r"b\.ini, line 8, field \$AN_CEC_DIRECTION: 2 is not -1, 0 or 1"),
    (siemens840d, "c.ini", "$AN_CEC[0,0]=0\n$AN_CEC_INPUT_AXIS[0]=(AX1)\n$AN_CEC_OUTPUT_AXIS[0]=(AX1)\n"
     "$AN_CEC_STEP[0]=1\n$AN_CEC_MIN[0]=0\n$AN_CEC_MAX[0]=2\n", r"c\.ini, CEC table 0 \(line 1\): MIN/MAX/STEP give 3 points"),
    (siemens840d, "d.ini", "G1 X10\n", r"d\.ini, line 1: 'G1 X10' is not a \$AN_CEC"),
])
def test_bad_controller_files_are_refused_naming_line_and_field(tmp_path, module, name, content, where):
    path = tmp_path / name
    path.write_text(content)
    with pytest.raises(ControllerFileError, match=where):
        module.load(path)
