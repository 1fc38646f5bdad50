"""The command line: discovery, clear one-line errors, no traceback."""

import subprocess
import sys
from pathlib import Path

import pytest

from station.cli import build_parser, main

REPO = Path(__file__).resolve().parents[2]


def test_every_command_module_builds_its_parser():
    parser = build_parser(None)
    names = set(parser._subparsers._group_actions[0].choices)  # type: ignore[union-attr]
    assert {"sweep", "sim", "run"} <= names


def test_plain_commands_do_not_import_the_heavy_stacks():
    code2 = ("import sys\nfrom station.cli import build_parser\nbuild_parser('sweep')\n"
             "print(sorted(m for m in ('textual', 'matplotlib', 'scipy') if m in sys.modules))")
    r = subprocess.run([sys.executable, "-c", code2], capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"


def test_sweep_target_beyond_soft_limits_is_refused_before_motion(capsys, tmp_path):
    out = tmp_path / "x.h5"
    rc = main(["sweep", "--sim", "--min-mm", "-120", "--max-mm", "90", "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2
    assert "below the soft limit" in err and "Traceback" not in err
    assert not out.exists(), "nothing is recorded when the plan is refused"


def test_sweep_needs_out_and_refuses_to_overwrite(capsys, tmp_path):
    assert main(["sweep", "--sim"]) == 2
    assert "--out FILE.h5 is required" in capsys.readouterr().err
    existing = tmp_path / "e.h5"
    existing.write_bytes(b"x")
    assert main(["sweep", "--sim", "--out", str(existing)]) == 2
    assert "exists" in capsys.readouterr().err


def test_unreachable_drive_is_a_clear_error_within_the_timeout(tmp_path):
    import socket
    import time

    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()  # nothing listens there now
    cfg = tmp_path / "station.toml"
    cfg.write_text(f'[drive]\nurl = "tcp://127.0.0.1:{port}"\ntimeout_s = 0.5\n[interferometer]\nport = "/dev/null-not-there"\n')
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-m", "station.cli", "sweep", "--config", str(cfg), "--out", str(tmp_path / "o.h5")],
                       capture_output=True, text=True, cwd=REPO, timeout=60)
    elapsed = time.monotonic() - t0
    assert r.returncode == 2
    assert f"127.0.0.1:{port}" in r.stderr and "Traceback" not in r.stderr
    assert elapsed < 10


def test_bad_config_names_file_and_key(capsys, tmp_path):
    cfg = tmp_path / "station.toml"
    cfg.write_text('[drive]\ntimeout_s = "soon"\n')
    assert main(["sweep", "--config", str(cfg), "--out", str(tmp_path / "o.h5")]) == 2
    err = capsys.readouterr().err
    assert "[drive] timeout_s: expected a float" in err and str(cfg) in err


def test_sweep_runs_end_to_end_from_the_command_line(capsys, tmp_path):
    out = tmp_path / "cli.h5"
    rc = main(["sweep", "--sim", "--legs", "2", "--cycles", "1", "--n-targets", "5", "--out", str(out)])
    text = capsys.readouterr()
    assert rc == 0, text.err
    assert f"session: {out} (completed, 10 of 10 points)" in text.out
    assert "sweep completed: 10 points" in text.err


def test_a_missing_input_file_is_named_plainly(capsys, tmp_path):
    missing = tmp_path / "targets.txt"
    assert main(["sweep", "--sim", "--targets", str(missing), "--out", str(tmp_path / "o.h5")]) == 2
    err = capsys.readouterr().err
    assert f"{missing}: no such file or directory" in err and "Errno" not in err
