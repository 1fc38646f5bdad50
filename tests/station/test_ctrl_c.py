"""Ctrl-C on `station sweep`, through a real process: once or twice, the session file is finished
("aborted"), readable, and no lock file is left beside it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from procedures.io.recording.reader import read_session
from procedures.vocabulary import Outcome

REPO = Path(__file__).resolve().parents[2]
TOTAL = 6 * 10 * 41 * 2  # legs x cycles x targets x directions


def _start_sweep(out: Path) -> subprocess.Popen:
    # time scale 0: the simulated moves take no real time (no timeouts on a loaded machine);
    # a progress line every 10 % (the first once points are on disk). The sweep's other 90 % must
    # outlast the test's reaction to that line: 630 points (a second or two) did not, on a loaded
    # machine, so 4920 points (about 6 s after the first line here)
    return subprocess.Popen(
        [sys.executable, "-m", "station.cli", "sweep", "--sim", "--legs", "1-6", "--cycles", "10", "--n-targets", "41",
         "--time-scale", "0", "--out", str(out)],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)})


class _Stderr(threading.Thread):
    """Collects the sweep's stderr; `progress` is set at its first progress line ("492/4920 points
    (10%) ..."): points are on disk. (Polling the file instead could hold its HDF5 lock just when
    the writer opens it.)"""

    def __init__(self, proc: subprocess.Popen):
        super().__init__(daemon=True)
        self.proc, self.lines, self.progress = proc, [], threading.Event()

    def run(self):
        for line in self.proc.stderr:
            self.lines.append(line)
            if f"/{TOTAL} points (" in line:
                self.progress.set()

    @property
    def text(self) -> str:
        return "".join(self.lines)


@pytest.mark.parametrize("gap_s", [0.0005, 0.002, 0.005, 0.02, 0.1])
def test_ctrl_c_twice_during_a_sweep_leaves_a_finished_file_and_no_lock(tmp_path, gap_s):
    out = tmp_path / "cc.h5"
    proc = _start_sweep(out)
    err = _Stderr(proc)
    err.start()
    assert err.progress.wait(60) and proc.poll() is None, "the sweep ended before Ctrl-C: " + err.text
    proc.send_signal(signal.SIGINT)
    time.sleep(gap_s)
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    stdout = proc.stdout.read()
    proc.wait(timeout=60)
    err.join(10)
    stderr = err.text
    # 130: a Ctrl-C ended the sweep (the first cleanly, or the second forced it); -SIGINT: the second came
    # while Python was already shutting down (the file was finished before)
    assert proc.returncode in (130, -signal.SIGINT), stderr
    assert "Traceback" not in stderr, stderr
    assert "Ctrl-C" in stdout + stderr
    s = read_session(out)  # readable: the file was closed
    assert s.outcome == Outcome.ABORTED, (s.outcome, stdout, stderr)
    assert TOTAL // 10 <= len(s.points) < TOTAL
    leftovers = sorted(p.name for p in tmp_path.iterdir() if p.name != out.name)
    assert leftovers == [], f"left beside the session: {leftovers}"  # e.g. .cc.h5.lock
