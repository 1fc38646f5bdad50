"""`station platform` through station.cli.main: report files, figures, model input, bad input."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from procedures.io.recording.reader import file_sha256
from station.cli import main
from tests.tooling import default_legs_points, write_points_session

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def write_session(path, legs=range(1, 7), cycles=3, step_mm=3.0, seed=0):
    points = default_legs_points(legs, cycles, step_mm, seed)
    write_points_session(path, points)
    return points


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    path = tmp_path_factory.mktemp("rec") / "six-legs.h5"
    points = write_session(path)
    return path, points


def test_platform_writes_table_json_and_histograms(session, tmp_path, capsys):
    path, _ = session
    out = tmp_path / "report"
    rc = main(["platform", str(path), "--poses", "400", "--seed", "7", "--out", str(out)])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "| Range reduction (%) |" in printed and "x (um)" in printed and "rx (arcsec)" in printed
    for name in ("pose_position_hist.png", "pose_orientation_hist.png", "leg_error_hist.png"):
        data = (out / name).read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 5000
    summary = json.loads((out / "platform_summary.json").read_text())
    assert summary["poses"] == 400 and summary["seed"] == 7
    assert summary["inputs"]["recording"]["sha256"] == file_sha256(path)
    for name, st in summary["pose"].items():
        assert st["range_reduction_pct"] == pytest.approx(100 * (1 - st["range_compensated"] / st["range_original"]))
        assert st["max_original"] >= st["min_original"]
    assert summary["sensitivity_home"]["dominant"][2]["legs"] == [1, 2, 3, 4, 5, 6]
    report = (out / "platform_report.md").read_text()
    assert "the paper's Table 2" in report and "Which leg dominates" in report and str(path) in report


def test_platform_with_a_model_uses_its_recording(session, tmp_path, capsys):
    from procedures.fit import fit, save_model

    path, points = session
    model = fit(points, method="paper")
    model_path = save_model(model, tmp_path / "model.json", source_path=str(path), source_sha256=file_sha256(path))
    out = tmp_path / "m"
    assert main(["platform", str(model_path), "--measured", "mean", "--poses", "300", "--out", str(out)]) == 0
    summary = json.loads((out / "platform_summary.json").read_text())
    assert summary["inputs"]["model"]["method"] == "paper"
    assert summary["inputs"]["recording_is_the_models_own"] is True
    assert "model" in summary["source"] and "mean of all passes" in summary["source"]
    # another recording as measurement is allowed explicitly (a held-out session)
    other = tmp_path / "other.h5"
    write_session(other, seed=1)
    out3 = tmp_path / "m3"
    assert main(["platform", str(model_path), "--recording", str(other), "--poses", "200", "--out", str(out3)]) == 0
    assert json.loads((out3 / "platform_summary.json").read_text())["inputs"]["recording_is_the_models_own"] is False


def test_platform_refuses_bad_input_with_one_line(tmp_path, capsys):
    part = tmp_path / "two-legs.h5"
    write_session(part, legs=(1, 2), cycles=2, step_mm=10.0)
    rc = main(["platform", str(part), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "leg 3" in err and "record every leg" in err and "Traceback" not in err
    assert err.count("\n") == 1

    rc = main(["platform", str(tmp_path / "missing.h5"), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "missing.h5" in err

    rc = main(["platform", str(part), "--measured", "mean", "--out", str(tmp_path / "o")])
    assert rc == 2 and "MODEL.json" in capsys.readouterr().err

    rc = main(["platform", str(part), "--poses", "0", "--out", str(tmp_path / "o")])
    assert rc == 2 and "--poses" in capsys.readouterr().err

    bad_geo = tmp_path / "g.toml"
    bad_geo.write_text('format = "station.platform.geometry/1"\n[legs]\n')
    rc = main(["platform", str(part), "--geometry", str(bad_geo), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "g.toml" in err and "legs.mid_stroke_mm" in err


SAMPLE = Path(__file__).resolve().parents[2] / "recordings" / "calibration-6legs.h5"


def test_platform_with_a_table_reports_both_measurements(session, tmp_path, capsys):
    path, _ = session
    model_path = tmp_path / "model.json"
    table_path = tmp_path / "table.csv"
    assert main(["fit", str(path), "--out", str(model_path)]) == 0
    assert main(["table", str(model_path), "--out", str(table_path)]) == 0
    capsys.readouterr()
    out = tmp_path / "t"
    assert main(["platform", str(table_path), "--recording", str(path), "--poses", "300", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "range reduction, systematic error" in printed and "range reduction, one recorded pass" in printed
    summary = json.loads((out / "platform_summary.json").read_text())
    assert summary["measured"] == "mean" and summary["inputs"]["measured"] == "mean"
    assert summary["inputs"]["table"]["sha256"] == file_sha256(table_path)
    assert "with table" in summary["source"] and "as the drive does" in summary["source"]
    other = summary["other_measurement"]
    assert other["measured"] == "pass" and set(other["acceptance"]) == set(summary["acceptance"])
    # one pass adds the scatter no table removes: the legs shrink less than in the systematic measure
    assert other["leg_range_reduction_pct"] < summary["legs"]["all"]["range_reduction_pct"]
    # --measured pass swaps them: the same poses, so the same figures in the other place
    out2 = tmp_path / "t2"
    assert main(["platform", str(table_path), "--recording", str(path), "--measured", "pass", "--poses", "300",
                 "--out", str(out2)]) == 0
    swapped = json.loads((out2 / "platform_summary.json").read_text())
    assert swapped["measured"] == "pass" and swapped["other_measurement"]["measured"] == "mean"
    assert swapped["legs"]["all"]["range_reduction_pct"] == pytest.approx(other["leg_range_reduction_pct"])
    assert swapped["other_measurement"]["acceptance"] == summary["acceptance"]
    # a session alone has only the one-pass measure
    out3 = tmp_path / "s"
    assert main(["platform", str(path), "--poses", "200", "--out", str(out3)]) == 0
    alone = json.loads((out3 / "platform_summary.json").read_text())
    assert alone["measured"] == "pass" and "other_measurement" not in alone
    assert not list(out.glob("*.tmp"))


def test_platform_refuses_a_table_without_its_recording_or_for_other_legs(session, tmp_path, capsys):
    path, _ = session
    table = tmp_path / "table.csv"
    assert main(["fit", str(path), "--out", str(tmp_path / "m.json")]) == 0
    assert main(["table", str(tmp_path / "m.json"), "--out", str(table)]) == 0
    capsys.readouterr()
    rc = main(["platform", str(table), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "--recording" in err and err.count("\n") == 1
    lines = table.read_text().splitlines()
    short = tmp_path / "short.csv"
    short.write_text("\n".join(line for line in lines if not line.startswith(("4,", "5,", "6,"))) + "\n")
    rc = main(["platform", str(short), "--recording", str(path), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err  # legs cut out of a station's table: its integrity record tells
    assert rc == 2 and "short.csv: does not match its integrity record" in err and "row(s) missing" in err
    short.write_text("\n".join(line for line in lines[1:] if not line.startswith(("4,", "5,", "6,"))) + "\n")
    rc = main(["platform", str(short), "--recording", str(path), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err  # the same made by hand, without the record: a table for another leg count
    assert rc == 2 and "short.csv" in err and "leg count" in err and "Traceback" not in err
    rc = main(["platform", str(path), "--recording", str(path), "--out", str(tmp_path / "o")])
    assert rc == 2 and "--recording goes with" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_the_sample_sessions_pose_errors_shrink_at_least_as_much_as_its_legs(tmp_path, capsys):
    """Issue 8's acceptance on the committed sample of the simulated rig: the default model
    fitted to it, tabulated for the drive, applied to the paper's experiment (the recording's
    systematic error as the measured leg error, as in the paper)."""
    model, table, out = tmp_path / "m.json", tmp_path / "t.csv", tmp_path / "p"
    assert main(["fit", str(SAMPLE), "--out", str(model)]) == 0
    assert main(["table", str(model), "--out", str(table)]) == 0
    assert main(["platform", str(table), "--recording", str(SAMPLE), "--out", str(out)]) == 0
    summary = json.loads((out / "platform_summary.json").read_text())
    legs = summary["legs"]["all"]["range_reduction_pct"]
    assert legs > 80.0
    shortfalls = {k: a["range_reduction_pct"] for k, a in summary["acceptance"].items() if not a["at_least_leg_reduction"]}
    assert not shortfalls, f"legs {legs:.2f} %, pose components below: {shortfalls}"
    assert "6 of 6 components at least as much as the legs" in capsys.readouterr().out


def test_platform_applies_a_model_to_the_recordings_error_on_the_models_basis(tmp_path, capsys):
    """The model `station fit` makes by default is of the error normalised to 20 degC: the
    platform experiment measures the recording's normalised error against it (and says so); a
    model fitted with --raw is measured against the raw error; --raw with a normalised model is
    refused. The figures are those of the experiment run directly on that basis's points, and
    the two bases give different leg errors (the sample was not recorded at 20 degC)."""
    from procedures.fit import load_model
    from procedures.metrology.thermal import normalise_session
    from procedures.platform.experiment import RecordedLegErrors, Workspace, run_measurements
    from procedures.platform.geometry import default_geometry
    from procedures.io.recording.reader import read_session

    session = read_session(SAMPLE)
    legs_all = {}
    for basis, extra in (("normalised", []), ("raw", ["--raw"])):
        model_path, out = tmp_path / f"{basis}.json", tmp_path / basis
        assert main(["fit", str(SAMPLE), "--out", str(model_path), *extra]) == 0
        capsys.readouterr()
        assert main(["platform", str(model_path), "--poses", "300", "--seed", "3", "--out", str(out)]) == 0
        printed = capsys.readouterr().out.splitlines()
        assert printed[0] == "platform: 300 poses: about 152 MB of memory and 2 s"  # the size, before the work
        first = printed[1]
        summary = json.loads((out / "platform_summary.json").read_text())
        assert summary["inputs"]["error_basis"]["basis"] == basis
        assert first == summary["inputs"]["error_basis"]["lines"][0]
        assert first.startswith("error: normalised to 20 degC" if basis == "normalised" else "error: raw, not normalised")
        assert f"Error basis: {basis}" in (out / "platform_report.md").read_text()
        points = normalise_session(session.points, session.station_config).points if basis == "normalised" \
            else session.points
        model = load_model(model_path)
        direct = RecordedLegErrors(points, predicted_um=model.predict_um, source="direct", measurement="mean")
        _, expected = run_measurements(default_geometry(), direct, poses=300, seed=3, workspace=Workspace())
        for k in ("range_original", "range_compensated"):
            assert summary["legs"]["all"][k] == pytest.approx(expected["legs"]["all"][k], rel=1e-12, abs=1e-12), k
        legs_all[basis] = summary["legs"]["all"]["range_original"]
    # the sample's legs sat at 19.9 .. 20.3 degC (corrections up to +-0.35 um): the bases still differ by far
    # more than the 1e-12 above
    assert abs(legs_all["normalised"] - legs_all["raw"]) > 0.05
    rc = main(["platform", str(tmp_path / "normalised.json"), "--raw", "--out", str(tmp_path / "refused")])
    err = capsys.readouterr().err
    assert rc == 2 and "normalised.json was fitted to the error normalised to 20 degC" in err and "--raw" in err
    assert not (tmp_path / "refused").exists()
