"""The README's calibration, run as written, passes its own acceptance on the simulated rig: every
leg verifies at or below 1.1 x its noise floor (issue 22, item 7).

The commands are read from README.md's calibration block (the fenced block after "A whole
calibration from the command line"), so the test fails when the README drifts from a path that
passes. Each line runs in a shell, as a technician types it, with `station` from this venv; the
push's question is answered "y" at a terminal (a pty), as a technician would.
"""

from __future__ import annotations

import os
import pty
import re
import subprocess
import sys
from pathlib import Path

import pytest

from procedures.compensation.verify import ACCEPT_RATIO

REPO = Path(__file__).resolve().parents[2]
BLOCK_TITLE = "A whole calibration from the command line"

pytestmark = pytest.mark.timeout(900)


def readme_commands() -> list[str]:
    """The calibration block's command lines, comments stripped."""
    text = (REPO / "README.md").read_text()
    start = text.index(BLOCK_TITLE)
    block = re.search(r"```\n(.*?)```", text[start:], re.S)
    assert block, "README.md: no fenced block after the calibration title"
    lines = [line.split("#", 1)[0].strip() for line in block.group(1).splitlines()]
    return [line for line in lines if line]


def test_the_readme_block_is_a_calibration_of_every_leg():
    commands = readme_commands()
    verbs = [c.split()[1] for c in commands if c.startswith("station ")]
    assert verbs[:6] == ["sweep", "iso230", "fit", "table", "push", "verify"], verbs
    push = next(c for c in commands if c.startswith("station push"))
    verify = next(c for c in commands if c.startswith("station verify"))
    assert "--leg all" in push and "--leg all" in verify  # every leg is pushed and verified


def test_the_readme_calibration_verifies_every_leg(tmp_path):
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
           "STATION_LOCK_DIR": str(tmp_path / "locks"),
           # the verification's noise seed pinned, so the test repeats exactly; unpinned, the ratios of
           # the six legs vary by a few per cent around 0.96 from seed to seed (docs/compensation.md)
           "STATION_SIM_NOISE_SEED": "1"}
    outputs: dict[str, str] = {}
    for command in readme_commands():
        master, slave = pty.openpty()  # a terminal for the push's question
        try:
            os.write(master, b"y\n")
            r = subprocess.run(command, shell=True, cwd=tmp_path, env=env, stdin=slave, capture_output=True,
                               text=True, timeout=600)
        finally:
            os.close(slave)
            os.close(master)
        assert r.returncode == 0, f"README command failed ({r.returncode}): {command}\n{r.stdout[-2000:]}\n{r.stderr}"
        assert "Traceback" not in r.stderr
        outputs[command] = r.stdout
    verify = next(out for cmd, out in outputs.items() if cmd.startswith("station verify"))
    ratios = {int(leg): float(value) for leg, value in re.findall(
        r"Leg (\d): compensated error.*?verification ratio \(residual RMS / noise floor\): ([0-9.]+) -> PASS",
        verify, re.S)}
    assert sorted(ratios) == [1, 2, 3, 4, 5, 6], verify
    assert all(0.5 < v <= ACCEPT_RATIO for v in ratios.values()), ratios
    assert "ABOVE" not in verify


def test_a_noise_seed_from_the_environment_must_be_a_number(tmp_path, monkeypatch, capsys):
    from station.cli import main

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("STATION_SIM_NOISE_SEED", "one")
    assert main(["verify", "--leg", "1", "--sim", "--out", str(tmp_path / "v.h5")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["station verify: error: $STATION_SIM_NOISE_SEED = 'one': give a whole number (or unset it for a "
                   "new seed)"]
    assert not (tmp_path / "v.h5").exists()
