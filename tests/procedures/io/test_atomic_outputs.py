"""procedures.io.atomic_outputs: files and folders appear whole or not at all, honour the umask, and a place
that cannot be written gives one WriteError (an InputError) naming it, leaving nothing behind."""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from procedures.io.atomic_outputs import (WriteError, atomic_folder, atomic_path, write_bytes_atomic,
                                         write_files_atomic, write_text_atomic)
from procedures.vocabulary import InputError

ROOT = os.geteuid() == 0
REPO = Path(__file__).resolve().parents[3]


@pytest.fixture
def umask():
    old = os.umask(0o022)

    def set_(mask: int) -> None:
        os.umask(mask)

    yield set_
    os.umask(old)


def mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.mark.parametrize("mask, file_mode, folder_mode", [(0o022, 0o644, 0o755), (0o077, 0o600, 0o700),
                                                          (0o002, 0o664, 0o775)])
def test_files_and_folders_honour_the_umask(tmp_path, umask, mask, file_mode, folder_mode):
    umask(mask)
    a = write_text_atomic(tmp_path / "a.json", "{}\n")
    b = write_bytes_atomic(tmp_path / "b.bin", b"\x00\x01")
    with atomic_path(tmp_path / "c.png", ".png") as tmp:
        assert tmp.suffix == ".png" and tmp.parent == tmp_path
        tmp.write_bytes(b"png")
    with atomic_folder(tmp_path / "report") as work:
        write_text_atomic(work / "summary.md", "# r\n")
    assert [mode(p) for p in (a, b, tmp_path / "c.png", tmp_path / "report" / "summary.md")] == [file_mode] * 4
    assert mode(tmp_path / "report") == folder_mode
    assert a.read_text() == "{}\n" and b.read_bytes() == b"\x00\x01"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json", "b.bin", "c.png", "report"]


def test_replacing_keeps_the_old_file_until_the_new_one_is_complete(tmp_path):
    target = tmp_path / "model.json"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("killed mid-write")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["model.json"]
    write_text_atomic(target, "new")
    assert target.read_text() == "new"


READ_ONLY_CHECK = """
import sys
from pathlib import Path
from procedures.io.atomic_outputs import WriteError, atomic_folder, write_files_atomic, write_text_atomic
from procedures.vocabulary import InputError

folder = Path(sys.argv[1])
for attempt in (lambda: write_text_atomic(folder / "table.csv", "x"),
                lambda: write_files_atomic({folder / "a": "1", folder / "b": "2"}),
                lambda: atomic_folder(folder / "report").__enter__()):
    try:
        attempt()
    except WriteError as exc:
        assert isinstance(exc, InputError)
        print(exc)
    else:
        raise SystemExit("written into a read-only folder")
"""


def test_a_read_only_folder_gives_one_write_error_and_leaves_nothing(tmp_path):
    """Run as an unprivileged user (as root, in a child process as nobody: root writes anywhere)."""
    folder = tmp_path / "ro"
    folder.mkdir()
    (folder / "keep.csv").write_text("kept")
    folder.chmod(0o555)
    python, user = sys.executable, None
    if ROOT:  # the venv's interpreter may sit under /root; the check needs only the standard library
        python, user = shutil.which("python3", path="/usr/local/bin:/usr/bin:/bin"), 65534
        tmp_path.chmod(0o755)
        for parent in tmp_path.parents[:2]:
            parent.chmod(parent.stat().st_mode | 0o005)
    try:
        run = subprocess.run([python, "-c", READ_ONLY_CHECK, str(folder)], cwd=REPO, user=user,
                             env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
                             capture_output=True, text=True, timeout=60)
        assert run.returncode == 0, run.stderr
        lines = run.stdout.splitlines()
        assert len(lines) == 3
        assert all(str(folder) in line and "choose a writable folder" in line for line in lines), lines
        assert sorted(p.name for p in folder.iterdir()) == ["keep.csv"]
    finally:
        folder.chmod(0o755)


def test_all_files_or_none(tmp_path):
    (tmp_path / "sub").mkdir()
    with pytest.raises(WriteError, match="does not exist"):
        write_files_atomic({tmp_path / "sub" / "a.comp": "1", tmp_path / "missing" / "b.comp": "2"})
    assert list((tmp_path / "sub").iterdir()) == []


def test_a_folder_interrupted_inside_leaves_nothing(tmp_path):
    for exc in (RuntimeError("figure failed"), KeyboardInterrupt()):
        with pytest.raises(type(exc)):
            with atomic_folder(tmp_path / "report") as work:
                write_text_atomic(work / "errors.png", "png")
                raise exc
    assert list(tmp_path.iterdir()) == []


def test_a_folder_into_an_existing_one_keeps_the_other_files(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "mine.txt").write_text("user's")
    (out / "summary.md").write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_folder(out) as work:
            write_text_atomic(work / "summary.md", "half")
            raise RuntimeError
    assert (out / "summary.md").read_text() == "old"
    with atomic_folder(out) as work:
        write_text_atomic(work / "summary.md", "new")
    assert (out / "summary.md").read_text() == "new" and (out / "mine.txt").read_text() == "user's"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_a_file_in_the_way_of_a_folder(tmp_path):
    (tmp_path / "report").write_text("x")
    with pytest.raises(WriteError, match="not a folder"):
        with atomic_folder(tmp_path / "report"):
            pass
