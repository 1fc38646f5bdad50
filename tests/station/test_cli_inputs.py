"""Issue 31's command-line reproductions, each as it behaves now: refused in one line with exit 2
(naming the option, the value, the bound or what to do, nothing written), or right; and the size
estimates of size-driven options checked against what a run takes."""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from pathlib import Path

import pytest

from station.cli import main
from tests.station.test_cli_contract import REPO, SAMPLE, run_station

MODEL_LEGS = "1"


@pytest.fixture
def shared():
    """A folder under /tmp any user can reach and write (pytest's own is root's only)."""
    root = Path(tempfile.mkdtemp(prefix="station-inputs-"))
    root.chmod(0o777)
    yield root
    for p in root.rglob("*"):
        if p.is_dir():
            p.chmod(0o777)
    shutil.rmtree(root, ignore_errors=True)


def one_line(capsys) -> tuple[str, str]:
    cap = capsys.readouterr()
    lines = [x for x in cap.err.splitlines() if x.strip()]
    assert len(lines) == 1, cap.err
    assert "Traceback" not in cap.err
    return lines[0], cap.out


@pytest.fixture(scope="module")
def model(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("model") / "model.json"
    assert main(["fit", str(SAMPLE), "--legs", MODEL_LEGS, "--out", str(path)]) == 0
    return path


@pytest.mark.parametrize("argv, words", [
    (["fit", str(SAMPLE), "--out", "{tmp}/m.json", "--params", "100000"],
     "--params 100000: the number of cosine terms applies to --method paper only"),
    (["fit", str(SAMPLE), "--out", "{tmp}/m.json", "--params", "200000"], "argument --params: '200000' is outside 1 .. 100000"),
    (["fit", str(SAMPLE), "--out", "{tmp}/m.json", "--lead-mm", "0"], "argument --lead-mm: '0' is outside >0 .. 100 mm"),
    (["fit", str(SAMPLE), "--out", "{tmp}/m.json", "--lead-mm", "-5"], "argument --lead-mm: '-5' is outside >0 .. 100 mm"),
    (["verify", "--leg", "1", "--sim", "--out", "{tmp}/v.h5", "--cycles", "0"], "argument --cycles: '0' is outside 1 .. 1000"),
    (["verify", "--leg", "1", "--sim", "--out", "{tmp}/v.h5", "--noise-seed", "-5"],
     "argument --noise-seed: '-5' is outside 0 .. 4294967295"),
    (["sim", "--port", "70000"], "argument --port: '70000' is outside 0 .. 65535"),
    (["web", "--port", "99999"], "argument --port: '99999' is outside 1 .. 65535"),
    (["web", "--port", "-1"], "argument --port: '-1' is outside 1 .. 65535"),
    (["sweep", "--sim", "--out", "{tmp}/s.h5", "--step", "1,5"], "'1,5': a comma is not a decimal separator here"),
    (["sweep", "--sim", "--out", "{tmp}/s.h5", "--min-mm", "nan"], "'nan' is not a number"),
    (["audit", "--action", "x"], "invalid choice: 'x' (choose from 'push', 'rollback', 'verify', 'approve')"),
    (["report", str(SAMPLE), "--out", "{tmp}/missing/sub"], "the folder {tmp}/missing does not exist; create it first"),
    (["legs", "--since", "03/04/2026"], "argument --since: '03/04/2026' is not a date; give it as YYYY-MM-DD"),
])
def test_refused_in_one_line_with_exit_2(argv, words, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv = [a.format(tmp=tmp_path) for a in argv]
    assert main(argv) == 2
    line, out = one_line(capsys)
    assert line.startswith(f"station {argv[0]}: error: ") and words.format(tmp=tmp_path) in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == [], "nothing is written by a refusal"


def test_fit_params_beyond_the_targets_is_refused_naming_the_most(tmp_path, capsys):
    assert main(["fit", str(SAMPLE), "--legs", "1", "--method", "paper", "--params", "100000",
                 "--out", str(tmp_path / "m.json")]) == 2
    line, _ = one_line(capsys)
    assert "leg 1 has 361 targets per pass, which give at most 180 cosine terms; give --params 1..180" in line
    assert not (tmp_path / "m.json").exists()
    assert main(["fit", str(SAMPLE), "--legs", "1", "--method", "paper", "--params", "180",
                 "--out", str(tmp_path / "m.json")]) == 0
    assert "(180 cosine terms)" in capsys.readouterr().out


def test_lead_none_is_the_word_for_no_lead():
    from station.cli import build_parser

    p = build_parser("fit")
    for given, meant in (("none", None), ("auto", "auto"), ("5", 5.0), ("NONE", None)):
        assert p.parse_args(["fit", str(SAMPLE), "--out", "y.json", "--lead-mm", given]).lead_mm == meant


def test_a_binary_targets_file_is_refused(tmp_path, capsys):
    (tmp_path / "t.bin").write_bytes(bytes(range(256)))
    assert main(["sweep", "--sim", "--targets", str(tmp_path / "t.bin"), "--out", str(tmp_path / "s.h5")]) == 2
    line, _ = one_line(capsys)
    assert "t.bin is a binary file, not text; give a targets file" in line


def test_two_legs_given_one_serial_are_refused_naming_both(tmp_path, capsys):
    (tmp_path / "serials.csv").write_text("leg,serial\n1,HX-0042\n2,HX-0042\n")
    assert main(["sweep", "--sim", "--legs", "1-2", "--serials", str(tmp_path / "serials.csv"),
                 "--out", str(tmp_path / "s.h5")]) == 2
    line, _ = one_line(capsys)
    assert "serial HX-0042 is given to both leg 1 and leg 2 (by the serials file" in line
    assert main(["sweep", "--sim", "--serial", "1=HX-7", "--serial", "3=HX-7", "--out", str(tmp_path / "s.h5")]) == 2
    assert "serial HX-7 is given to both leg 1 and leg 3 (by --serial)" in one_line(capsys)[0]
    assert not (tmp_path / "s.h5").exists()


def test_compare_refuses_an_existing_out_unless_force(tmp_path, capsys):
    out = tmp_path / "cmp"
    out.mkdir()
    (out / "compare.md").write_text("kept")
    sessions = [str(SAMPLE), str(REPO / "recordings" / "verification-6legs.h5")]
    assert main(["compare", *sessions, "--out", str(out)]) == 2
    assert "exists; add --force to replace what it holds" in one_line(capsys)[0]
    assert (out / "compare.md").read_text() == "kept"
    rc = main(["compare", *sessions, "--out", str(out), "--force"])
    assert rc == 2 or (rc in (0, 1) and (out / "compare.md").read_text() != "kept")  # the samples may lack a serial
    capsys.readouterr()


def test_unknown_serial_and_unknown_type_are_both_one_line_exit_2(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["history", "UNKNOWN"]) == 2
    assert "UNKNOWN: no records of a leg with this serial in the catalog" in one_line(capsys)[0]
    assert main(["legs", "--type", "NOPE"]) == 2
    assert "--type NOPE: no leg of this type in the catalog" in one_line(capsys)[0]
    assert main(["legs"]) == 0  # no filter: an empty catalog is an empty listing with its count
    assert "0 leg(s)" in capsys.readouterr().out


def test_a_table_given_as_a_model_is_named_a_table(model, tmp_path, capsys):
    table = tmp_path / "t.csv"
    assert main(["table", str(model), "--out", str(table)]) == 0
    capsys.readouterr()
    assert main(["table", str(table), "--out", str(tmp_path / "t2.csv")]) == 2
    assert "t.csv is a table CSV, not a model" in one_line(capsys)[0]


def test_platform_poses_are_sized_first(model, tmp_path, capsys):
    t0 = time.monotonic()
    assert main(["platform", str(model), "--poses", "100000000", "--out", str(tmp_path / "p")]) == 2
    line, _ = one_line(capsys)
    assert time.monotonic() - t0 < 5.0
    assert "--poses 100000000: 100000000 poses: about 500.1 GB of memory" in line and "give --poses 370000 or fewer" in line
    assert not (tmp_path / "p").exists()


def test_the_platform_estimate_is_not_below_what_a_run_takes(shared):
    """The estimate printed is an upper side: a real run's peak resident memory is below it."""
    from station.services.sizing import platform_estimate

    poses = 20_000
    place = shared
    rc, out, err, peak_kb = run_station(["platform", str(SAMPLE), "--poses", str(poses), "--out", str(place / "p")],
                                        place, place, timeout_s=600)
    assert rc == 0, err
    assert f"platform: {poses} poses: about" in out
    assert peak_kb * 1024 < platform_estimate(poses).memory_bytes, (peak_kb, platform_estimate(poses))


@pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("setpriv"), reason="needs root to become user nobody")
@pytest.mark.parametrize("argv", [["push", "{table}", "--leg", "1", "--sim", "--yes"], ["history", "HX-0042"],
                                  ["verify", "--leg", "1", "--sim", "--out", "v.h5"]])
def test_a_read_only_folder_as_an_unprivileged_user_is_named_with_what_to_do(argv, model, shared):
    ro = shared / "ro"
    ro.mkdir()
    table = shared / "t.csv"
    assert main(["table", str(model), "--out", str(table)]) == 0
    table.chmod(0o644)
    ro.chmod(0o555)
    rc, out, err, _ = run_station([a.format(table=table) for a in argv], ro, shared, timeout_s=600)
    lines = [x for x in err.splitlines() if x.strip()]
    assert rc == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert str(ro) in lines[0] and "permission denied" in lines[0]
    assert "a folder you can write" in lines[0]


def test_the_config_and_the_command_line_bound_a_value_alike(tmp_path, capsys):
    """[sim] seed and --seed, [metrology] co2_ppm and recorrect --co2-ppm: one kind each, one bound."""
    cfg = tmp_path / "c.toml"
    cfg.write_text('[drive]\nurl = "sim"\n[interferometer]\nport = "sim"\n[sim]\nseed = -5\n')
    assert main(["sweep", "--config", str(cfg), "--out", str(tmp_path / "s.h5")]) == 2
    assert f"{cfg}: [sim] seed: -5 is outside 0 .. 4294967295" in one_line(capsys)[0]
    assert main(["sweep", "--sim", "--seed", "-5", "--out", str(tmp_path / "s.h5")]) == 2
    assert "argument --seed: '-5' is outside 0 .. 4294967295" in one_line(capsys)[0]
    cfg.write_text('[metrology]\nco2_ppm = 9999.0\n')
    assert main(["iso230", str(SAMPLE), "--config", str(cfg)]) == 2
    assert "co2_ppm = 9999.0: must be within 0..5000" in one_line(capsys)[0]
    assert main(["recorrect", str(SAMPLE), "--out", str(tmp_path / "r.h5"), "--co2-ppm", "9999"]) == 2
    assert "argument --co2-ppm: '9999' is outside 0 .. 5000 ppm" in one_line(capsys)[0]
    assert not (tmp_path / "s.h5").exists() and not (tmp_path / "r.h5").exists()
