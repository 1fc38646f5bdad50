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


def _start_sweep(out: Path) -> subprocess.Popen:
    # time scale 0: the simulated moves take no real time (no timeouts on a loaded machine);
    # 630 points take a few seconds, with a progress line every 10 %
    return subprocess.Popen(
        [sys.executable, "-m", "station.cli", "sweep", "--sim", "--legs", "1-3", "--cycles", "5", "--n-targets", "21",
         "--time-scale", "0", "--out", str(out)],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)})


class _Stderr(threading.Thread):
    """Collects the sweep's stderr; `progress` is set at its first progress line ("63/630 points
    (10%) ..."): points are on disk. (Polling the file instead could hold its HDF5 lock just when
    the writer opens it.)"""

    def __init__(self, proc: subprocess.Popen):
        super().__init__(daemon=True)
        self.proc, self.lines, self.progress = proc, [], threading.Event()

    def run(self):
        for line in self.proc.stderr:
            self.lines.append(line)
            if "/630 points (" in line:
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
    assert 63 <= len(s.points) < 630
    leftovers = sorted(p.name for p in tmp_path.iterdir() if p.name != out.name)
    assert leftovers == [], f"left beside the session: {leftovers}"  # e.g. .cc.h5.lock
