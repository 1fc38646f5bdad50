"""Every command that writes checks its output before it connects, moves or computes for long:
into a folder that cannot be written each ends with one line, exit 2, nothing written (issue 22,
item 4). And one overwrite rule for all of them: an existing output is refused, naming it,
unless --force."""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
from pathlib import Path

import pytest

from station.cli import main

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "recordings" / "calibration-6legs.h5"


def _writable(folder: Path) -> bool:
    try:
        (folder / ".probe").write_text("")
    except OSError:
        return False
    (folder / ".probe").unlink()
    return True


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """A model, a table and an interchange CSV made from the sample recording (written where allowed)."""
    d = tmp_path_factory.mktemp("inputs")
    assert main(["fit", str(SAMPLE), "--out", str(d / "model.json"), "--legs", "1"]) == 0
    assert main(["table", str(d / "model.json"), "--out", str(d / "table.csv")]) == 0
    assert main(["export", str(SAMPLE), "--out", str(d / "points.csv")]) == 0
    shutil.copy(SAMPLE, d / "partial.h5")
    return d


@pytest.fixture
def read_only(tmp_path):
    """A folder nobody may write to: mode 0555, and for root (whom modes do not stop) immutable."""
    folder = tmp_path / "read-only"
    folder.mkdir()
    folder.chmod(stat.S_IRUSR | stat.S_IXUSR | stat.S_IRGRP | stat.S_IXGRP | stat.S_IROTH | stat.S_IXOTH)
    immutable = False
    if _writable(folder) and shutil.which("chattr"):
        immutable = subprocess.run(["chattr", "+i", str(folder)], capture_output=True).returncode == 0
    if _writable(folder):
        folder.chmod(0o755)
        pytest.skip("cannot make a read-only folder here: running as root and `chattr +i` is not permitted "
                    "(no CAP_LINUX_IMMUTABLE or a file system without it)")
    yield folder
    if immutable:
        subprocess.run(["chattr", "-i", str(folder)], check=True)
    folder.chmod(0o755)


def _commands(ro: Path, d: Path) -> dict[str, list[str]]:
    s = str(SAMPLE)
    return {
        "sweep": ["sweep", "--sim", "--out", str(ro / "s.h5")],
        "verify": ["verify", "--leg", "1", "--sim", "--out", str(ro / "v.h5")],
        "verify --json": ["verify", "--leg", "1", "--sim", "--out", str(d / "never.h5"), "--json", str(ro / "v.json")],
        "run": ["run", "--out", str(ro / "r.h5")],
        "fit": ["fit", s, "--out", str(ro / "m.json")],
        "table": ["table", str(d / "model.json"), "--out", str(ro / "t.csv")],
        "table --format linuxcnc": ["table", str(d / "model.json"), "--format", "linuxcnc", "--out", str(ro / "comp")],
        "report": ["report", s, "--out", str(ro / "report")],
        "platform": ["platform", s, "--out", str(ro / "platform")],
        "export": ["export", s, "--out", str(ro / "e.csv")],
        "import": ["import", str(d / "points.csv"), "--legs", "1-6", "--out", str(ro / "i.h5")],
        "iso230 --json": ["iso230", s, "--json", str(ro / "iso.json")],
        "diagnose --json": ["diagnose", s, "--json", str(ro / "d.json")],
        "recorrect": ["recorrect", s, "--out", str(ro / "rc.h5")],
        "replay": ["replay", s, "--out", str(ro / "rp.h5")],
    }


COMMANDS = list(_commands(Path("ro"), Path("d")))


@pytest.mark.parametrize("name", COMMANDS)
def test_every_command_that_writes_refuses_a_read_only_folder_first(name, read_only, inputs, tmp_path, capsys,
                                                                    monkeypatch):
    monkeypatch.chdir(tmp_path)  # the simulated drive's memory (runs/) may go here, never into the folder
    argv = _commands(read_only, inputs)[name]
    assert main(argv) == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in captured.err, err
    assert "cannot be written" in err[0] and str(read_only) in err[0], err[0]
    assert "rig:" not in captured.out  # refused before anything connected (nothing moved)
    assert list(read_only.iterdir()) == []
    assert not (inputs / "never.h5").exists()


def test_resume_of_a_session_that_cannot_be_written_is_refused_before_connecting(inputs, tmp_path, capsys):
    target = tmp_path / "partial.h5"
    shutil.copy(inputs / "partial.h5", target)
    target.chmod(0o444)
    immutable = False
    try:
        open(target, "r+b").close()
        immutable = shutil.which("chattr") is not None and subprocess.run(
            ["chattr", "+i", str(target)], capture_output=True).returncode == 0
        if not immutable:
            pytest.skip("cannot make a read-only file here: running as root and `chattr +i` is not permitted")
    except OSError:
        pass
    try:
        before = target.read_bytes()
        assert main(["sweep", "--sim", "--resume", str(target)]) == 2
        captured = capsys.readouterr()
        err = captured.err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"station sweep: error: --resume {target}: cannot be written ("), err
        assert "rig:" not in captured.out and target.read_bytes() == before
    finally:
        if immutable:
            subprocess.run(["chattr", "-i", str(target)], check=True)


@pytest.mark.parametrize("name", ["fit", "table", "export", "iso230 --json", "diagnose --json", "report", "platform"])
def test_an_existing_output_is_refused_unless_force(name, inputs, tmp_path, capsys):
    argv = _commands(tmp_path, inputs)[name]
    target = Path(argv[argv.index("--json" if "--json" in argv else "--out") + 1])
    if name in ("report", "platform"):
        target.mkdir()
        (target / "keep.txt").write_text("mine")
    else:
        target.write_text("mine")
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{target}: exists; add --force" in err[0], err
    if target.is_dir():
        assert [p.name for p in target.iterdir()] == ["keep.txt"]
    else:
        assert target.read_text() == "mine"
    if name in ("fit", "table", "iso230 --json"):  # the quick ones: --force replaces it
        assert main([*argv, "--force"]) == 0
        assert target.read_text() != "mine"


def test_a_sweep_into_a_file_that_is_not_hdf5_is_refused(tmp_path, capsys):
    assert main(["sweep", "--sim", "--out", str(tmp_path / "x.txt")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"station sweep: error: --out {tmp_path / 'x.txt'}: must end in .h5 (the file is written as HDF5, a session file); nothing was written"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("value", ["-1", "nan", "inf"])
@pytest.mark.parametrize("command", ["sweep", "ui"])
def test_a_negative_time_scale_is_one_line(command, value, tmp_path, capsys):
    argv = ["sweep", "--sim", "--time-scale", value, "--out", str(tmp_path / "s.h5")] if command == "sweep" else \
        ["ui", "--time-scale", value]  # refused before the terminal UI starts
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    why = "is outside 0 .. 1000" if value == "-1" else "is not a number"
    assert len(err) == 1 and err[0].startswith(f"station {command}: error: argument --time-scale: '{value}' {why}; "
                                                "give a time scale as a number (0 .. 1000)"), err
    assert list(tmp_path.iterdir()) == []


def test_the_resume_hint_quotes_a_path_with_spaces():
    from station.commands.sweep import resume_command
    from station.services.config import StationConfig

    hint = resume_command(Path("my runs/cal 1.h5"), StationConfig(), "bench config.toml")
    assert hint == "resume with: station sweep --resume 'my runs/cal 1.h5' --config 'bench config.toml'"
    assert resume_command(Path("runs/cal.h5"), StationConfig(), None) == "resume with: station sweep --resume runs/cal.h5 --sim"


def test_nothing_is_left_behind_by_the_check_itself(tmp_path):
    from procedures.vocabulary import InputError
    from procedures.io.outputs import check_output_file, check_output_folder

    check_output_file(tmp_path / "a.json")
    check_output_folder(tmp_path / "report")
    with pytest.raises(InputError, match="the folder .*new does not exist; create it first"):
        check_output_folder(tmp_path / "new" / "report")  # a folder output's parents are never made
    assert list(tmp_path.iterdir()) == [] and os.access(tmp_path, os.W_OK)
