"""What a technician runs into on a fresh bench, from the command line: a config that names no
device, absurd config values, an output folder that is not there, a resume of a finished or
imported session, and Ctrl-C at any moment. Each ends in one line naming what was wrong and
what to do, exit code 2 (130 for Ctrl-C), and nothing written.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from procedures.acquisition.plans import iso230_plan
from station.cli import main
from station.services.config import StationConfig
from station.services.jobs import run_sweep
from station.services.wiring import open_rig

REPO = Path(__file__).resolve().parents[2]
STATION = Path(sys.executable).with_name("station")


@pytest.fixture(autouse=True)
def _in_tmp(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)


def _one_line_error(capsys, code: int, *words: str) -> str:
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, err
    return err


def _table(path: Path) -> Path:
    rows = [f"3,{-90 + 30 * i:.6f},0.5000,-0.5000" for i in range(7)]
    path.write_text("leg,position_mm,error_fwd_um,error_rev_um\n" + "\n".join(rows) + "\n")
    return path


@pytest.mark.parametrize("argv", [
    ["push", "table.csv", "--leg", "3", "--config", "empty.toml", "--yes"],
    ["rollback", "--leg", "3", "--config", "empty.toml", "--yes"],
    ["sweep", "--config", "empty.toml", "--legs", "1", "--out", "s.h5"],
    ["verify", "--leg", "3", "--config", "empty.toml", "--out", "v.h5"],
])
def test_a_config_that_names_no_device_is_refused_and_nothing_moves(argv, capsys):
    Path("empty.toml").write_text("[station]\noperator = \"jdoe\"\n")
    _table(Path("table.csv"))
    _one_line_error(capsys, main(argv), "empty.toml: names no [drive] url", "\"sim\" for the simulated rig")
    assert not Path("runs").exists() and not Path("s.h5").exists() and not Path("v.h5").exists()


def test_a_push_says_which_drive_it_writes_to(capsys):
    _table(Path("table.csv"))
    assert main(["push", "table.csv", "--leg", "3", "--sim", "--yes"]) == 0
    lines = capsys.readouterr().out.splitlines()
    if lines[0].startswith("warning: table.csv has no integrity record"):  # a table made by hand: said first
        lines = lines[1:]
    first = lines[0]
    assert first.startswith("drive: the SIMULATED drive") and "not a real drive" in first


def test_a_config_naming_only_the_drive_is_refused_for_a_sweep(capsys):
    Path("half.toml").write_text("[drive]\nurl = \"sim\"\n")
    _one_line_error(capsys, main(["sweep", "--config", "half.toml", "--legs", "1", "--out", "s.h5"]),
                    "half.toml: names no [interferometer] port")


@pytest.mark.parametrize("text, words", [
    ("[drive]\nurl = \"sim\"\ntimeout_s = -1\n", "[drive] timeout_s = -1: must be a number > 0"),
    ("[interferometer]\nport = \"sim\"\nbaudrate = 0\n", "[interferometer] baudrate = 0: must be a number > 0"),
    ("[sim]\ntime_scale = -0.5\n", "[sim] time_scale = -0.5: must be a number >= 0"),
])
def test_absurd_config_values_are_refused_naming_file_section_and_key(text, words, capsys):
    Path("bad.toml").write_text(text)
    err = _one_line_error(capsys, main(["push", "t.csv", "--leg", "1", "--config", "bad.toml", "--yes"]), words)
    assert "bad.toml" in err and "tcp://" not in err  # not the URL hint of an unreachable drive


def test_out_in_a_missing_folder_is_refused_and_no_folder_is_made(capsys):
    _one_line_error(capsys, main(["sweep", "--sim", "--legs", "1", "--out", "missing/dir/x.h5"]),
                    "the folder missing/dir does not exist")
    assert not Path("missing").exists()


def test_resume_of_a_complete_session_says_it_is_complete(capsys):
    out = Path("done.h5")
    cfg = StationConfig()
    with open_rig(cfg, legs=(1,), time_scale=0.0) as rig:
        assert run_sweep(rig, iso230_plan((1,), -40.0, 40.0, step_mm=40.0, cycles=1), out, cfg).outcome == "completed"
    size = out.stat().st_size
    _one_line_error(capsys, main(["sweep", "--sim", "--resume", str(out)]), "done.h5: already complete (6 of 6 points",
                    "nothing to resume")
    assert out.stat().st_size == size


def test_resume_of_an_imported_session_says_it_has_no_plan(capsys):
    csv = Path("points.csv")
    csv.write_text("leg,run,direction,target_mm,error_um\n" + "\n".join(
        f"1,{r},{d},{t:.3f},1.0" for r, d in ((1, 1), (2, -1), (3, 1), (4, -1)) for t in (-10.0, 10.0)[::d]) + "\n")
    assert main(["import", str(csv), "--out", "imported.h5"]) == 0, capsys.readouterr().err
    capsys.readouterr()
    _one_line_error(capsys, main(["sweep", "--sim", "--resume", "imported.h5"]), "imported.h5: holds no sweep plan")


@pytest.mark.parametrize("delay_s", [0.08, 0.15, 0.25, 0.4])
def test_ctrl_c_at_any_moment_gives_one_line_and_130(delay_s, tmp_path):
    """From the moment the `station` program's own code runs (Python's start-up itself, the first
    few hundredths of a second, is Python's) until the sweep has ended."""
    proc = subprocess.Popen([str(STATION), "sweep", "--sim", "--legs", "1-6", "--out", str(tmp_path / "c.h5")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path,
                            env={**os.environ, "PYTHONPATH": str(REPO)})
    time.sleep(delay_s)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert "Traceback" not in err, err
    if proc.returncode == 0:  # the sweep was already over: nothing to interrupt
        assert "completed" in out
    else:
        assert proc.returncode == 130, err
