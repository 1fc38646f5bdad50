"""A plan of millions of points on `station sweep`, its [limits] raised in the config so it
starts (issue 22, item 3): the first Ctrl-C stops it at once (the plan's points are never listed
first), the session is finished as aborted and the resume hint names that file. Real process,
simulated rig (Modbus TCP + pty)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from procedures.io.recording.reader import read_session
from procedures.vocabulary import Outcome

REPO = Path(__file__).resolve().parents[2]


def test_the_first_ctrl_c_stops_a_huge_sweep_at_once(tmp_path):
    config = tmp_path / "station.toml"
    config.write_text(f'[station]\nrecordings_dir = "{tmp_path / "runs"}"\n[drive]\nurl = "sim"\n'
                      '[interferometer]\nport = "sim"\n[limits]\nmax_points = 100000000\nmax_rig_hours = 1e9\n')
    out = tmp_path / "huge.h5"
    proc = subprocess.Popen([sys.executable, "-m", "station.cli", "sweep", "--config", str(config), "--step", "0.0001",
                             "--dwell", "0", "--time-scale", "0", "--out", str(out)],
                            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(REPO)})
    try:
        deadline = time.monotonic() + 120
        while not out.exists():  # created when the sweep starts: points are being measured
            assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
            time.sleep(0.05)
        time.sleep(1.0)
        t0 = time.monotonic()
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
        stopped_s = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
    print(f"first Ctrl-C to exit: {stopped_s:.2f} s")
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr and "Ctrl-C twice" not in stdout
    assert read_session(out).outcome == Outcome.ABORTED
    assert f"resume with: station sweep --resume {out}" in stdout
    assert stopped_s < 10.0, stopped_s  # seconds, not the minutes of listing 18 M points first
