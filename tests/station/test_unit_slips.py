"""Plausible unit slips are named, not silently kept (issue 22, item 6): a degC column holding
degF, an um column holding nm, a table correcting more than the error it was made from; and a
semicolon CSV points to --map. `--accept-implausible` states "yes, I mean it". Measured data are
refused only when physically impossible, else imported with a warning (issue 35)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from procedures.io.recording.reader import read_session
from station.cli import main

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "recordings" / "calibration-6legs.h5"

HEADER = "leg,run,direction,target_mm,error_um,material_temp_c,air_temp_c\n"
ROWS = [(1, 1, 1, -10.0, 1.5), (1, 1, 1, 0.0, 1.2), (1, 1, 1, 10.0, 0.7),
        (1, 2, -1, 10.0, 0.2), (1, 2, -1, 0.0, 0.5), (1, 2, -1, -10.0, 1.1)]


def _csv(path: Path, material_c: float = 20.0, air_c: float = 20.0, error_scale: float = 1.0, slip_row: int = 3) -> Path:
    lines = [HEADER]
    for i, (leg, run, d, x, e) in enumerate(ROWS, start=1):
        m = material_c if i == slip_row else 20.0
        a = air_c if i == slip_row else 20.0
        lines.append(f"{leg},{run},{d},{x},{e * error_scale:g},{m},{a}\n")
    path.write_text("".join(lines))
    return path


@pytest.mark.parametrize("field, kwargs, figure", [
    ("material_temp_c", {"material_c": 68.0}, "68 degC is above 40 degC, rare for a workshop or a leg; if the column "
                                               "holds degF it is 20.0 degC"),
    ("air_temp_c", {"air_c": 46.4}, "46.4 degC is above 40 degC, rare for a workshop or a leg; if the column holds degF "
                                    "it is 8.0 degC"),
    ("error_um", {"error_scale": 300.0}, "450 um is beyond 100 um: possible for an uncompensated axis or a screw of a "
                                          "low accuracy grade, unusual for a precision leg; if the column holds nm it is "
                                          "0.45 um (targets span 20 mm)"),
])
def test_an_import_of_unusual_values_keeps_them_and_warns_with_the_figure(tmp_path, capsys, field, kwargs, figure):
    # issue 35: possible values are never refused, only named with the figure and the slip they may be
    src = _csv(tmp_path / "in.csv", **kwargs)
    out = tmp_path / "s.h5"
    assert main(["import", str(src), "--legs", "1", "--out", str(out)]) == 0
    printed = capsys.readouterr().out.splitlines()
    warned = [line for line in printed if line.startswith("warning: ")]
    assert len(warned) == 1, printed
    line = 4 if field != "error_um" else 2  # the row holding it (the largest error is the first row's)
    assert warned[0].startswith(f"warning: {src}, line {line}, field {field} = "), warned[0]
    assert figure in warned[0] and "(imported as it is; check the unit if it should not be)" in warned[0]
    assert out.exists()


def test_axes_with_errors_of_275_um_import_with_a_warning(tmp_path, capsys):
    # real positioning axes, uncompensated: +/-80 to +/-275 um over a few mm (issue 35)
    src = tmp_path / "axis.csv"
    rows = [HEADER]
    for run, d in ((1, 1), (2, -1), (3, 1), (4, -1)):
        for x in ([0.0, 1.0, 2.0, 3.0, 4.0] if d > 0 else [4.0, 3.0, 2.0, 1.0, 0.0]):
            rows.append(f"1,{run},{d},{x},{-275.0 + 137.5 * x + 2.0 * d:g},20.0,20.0\n")
    src.write_text("".join(rows))
    out = tmp_path / "axis.h5"
    assert main(["import", str(src), "--legs", "1", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "field error_um = 277: 277 um is beyond 100 um" in printed and "targets span 4 mm" in printed
    errors = read_session(out).points["error_um"]
    assert float(errors.min()) == -277.0 and float(errors.max()) == 277.0


def test_an_error_larger_than_the_travel_is_refused_unless_accepted(tmp_path, capsys):
    # 0.6 mm of error on targets 0.4 mm apart (within the 1 mm sanity limit of procedures/io/ranges.py)
    src = tmp_path / "in.csv"
    src.write_text(HEADER + "".join(f"1,{r},{d},{x},{600.0 if x > 0 else 1.0},20,20\n" for r, d in ((1, 1), (2, -1))
                                    for x in ((0.0, 0.2, 0.4) if d > 0 else (0.4, 0.2, 0.0))))
    out = tmp_path / "s.h5"
    assert main(["import", str(src), "--legs", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "an error of 0.6 mm is larger than the 0.4 mm the targets span" in err[0], err
    assert "add --accept-implausible if the values are right; nothing was written" in err[0]
    assert not out.exists()


def test_accept_implausible_keeps_the_values_and_warns(tmp_path, capsys):
    src = _csv(tmp_path / "in.csv", material_c=68.0)
    out = tmp_path / "s.h5"
    assert main(["import", str(src), "--legs", "1", "--out", str(out), "--accept-implausible"]) == 0
    printed = capsys.readouterr().out
    assert f"warning: {src}, line 4, field material_temp_c = 68: 68 degC is above 40 degC" in printed
    assert float(read_session(out).points["material_temp_c"][2]) == 68.0


def test_plausible_values_pass_without_a_word(tmp_path, capsys):
    src = _csv(tmp_path / "in.csv", material_c=39.0)
    assert main(["import", str(src), "--legs", "1", "--out", str(tmp_path / "s.h5")]) == 0
    assert "warning" not in capsys.readouterr().out


def test_a_semicolon_csv_points_to_map(tmp_path, capsys):
    src = tmp_path / "semi.csv"
    src.write_text("leg;run;direction;target_mm;error_um\n1;1;1;0;1,5\n")
    assert main(["import", str(src), "--out", str(tmp_path / "s.h5")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f"station import: error: {src}: line 1: the file is semicolon-separated")
    assert "--map MAP.toml" in err[0] and 'delimiter = ";"' in err[0] and err[0].endswith("nothing was written")


def test_a_table_correcting_more_than_the_error_is_refused_unless_accepted(tmp_path, capsys):
    """A model whose recorded error span is said to be tiny: its table would correct far more."""
    model = tmp_path / "model.json"
    assert main(["fit", str(SAMPLE), "--legs", "1", "--out", str(model)]) == 0
    doc = json.loads(model.read_text())
    leg = doc["legs"]["1"] if "legs" in doc and "1" in doc["legs"] else None
    assert leg is not None, list(doc)
    leg["stats"]["range_before_um"] = 0.01  # as if made from another, almost straight, leg
    doc.pop("integrity")  # written by hand: no record (read as unverified) rather than an edited one (refused)
    model.write_text(json.dumps(doc))
    capsys.readouterr()
    out = tmp_path / "t.csv"
    assert main(["table", str(model), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("station table: error: leg 1: correction span (um) = "), err
    assert "larger than the error it corrects (0.010 um peak to peak in " in err[0] and not out.exists()
    assert main(["table", str(model), "--out", str(out), "--accept-implausible"]) == 0
    assert "warning: leg 1: correction span (um)" in capsys.readouterr().out and out.exists()


def test_a_push_of_corrections_that_look_like_nm_is_refused_before_the_drive(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    table = tmp_path / "table.csv"
    rows = "".join(f"1,{x:g},{150.0 + x / 100:g},{148.0:g}\n" for x in range(-90, 91, 10))
    table.write_text("leg,position_mm,error_fwd_um,error_rev_um\n" + rows)
    assert main(["push", str(table), "--leg", "1", "--sim", "--yes"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"station push: error: {table}, leg 1, row 2 (-90.0000 mm), field error_fwd_um = 149.1: looks like nm in "
                   "an um field (149.1 nm = 0.1491 um; a ball-screw leg is off by micrometres to tens of micrometres, "
                   "not 100 um and more); correct it, or add --accept-implausible if the values are right. Nothing "
                   "was written to the drive."]
    assert not (tmp_path / "runs" / "sim-drive-nv.json").exists()  # the drive was never opened
    assert main(["push", str(table), "--leg", "1", "--sim", "--yes", "--accept-implausible"]) == 0
    out = capsys.readouterr().out
    assert "warning: " in out and "(kept: --accept-implausible)" in out and "pushed: leg 1" in out
