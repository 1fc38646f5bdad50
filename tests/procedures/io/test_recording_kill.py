"""Crash safety at the file level: SIGKILL mid-session, resume, crash during resume, live reader.

Child processes run the writer; they print a point's index only after `append_point` returned,
so every printed index must be in the file whatever the moment of the kill.
"""

from __future__ import annotations

import random
import signal
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from procedures.vocabulary import InputError
from procedures.io.recording.reader import LiveReader, file_sha256, read_session
from procedures.io.recording.writer import SessionWriter

TOTAL = 20000  # far more than a child can append between its printing and its kill (a pipe holds ~10 000 lines)

# value of every field is a function of the index, so the test can check content, not just count
CHILD = r"""
import os, signal, sys
from procedures.io.recording.writer import SessionWriter
path, mode, total = sys.argv[1], sys.argv[2], int(sys.argv[3])
def rec(i):
    return dict(index=i, leg=1 + i // 3400, run=1 + (i % 3400) // 10, direction=1 - 2 * (((i % 3400) // 10) % 2),
                target_mm=(i % 10) * 1.5, commanded_mm=(i % 10) * 1.5, error_um=i * 0.001, time_s=i * 2.0)
if mode == "new":
    w = SessionWriter.create(path, session_id="kill", operator="t", rig="sim", plan={"total": total},
                             station_config={}, devices={}, software_version="t")
else:
    w = SessionWriter.resume(path)
print("ready", w.points_written, flush=True)
done = w.indices_written()
for i in range(total):
    if i in done:
        continue
    w.append_point(rec(i))
    print(i, flush=True)
w.finish("completed")
print("finished", flush=True)
"""


def _expected(i: np.ndarray) -> np.ndarray:
    return i * 0.001


def _start(path: Path, mode: str) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-c", CHILD, str(path), mode, str(TOTAL)],
                            stdout=subprocess.PIPE, text=True)
    first = proc.stdout.readline().split()
    assert first[0] == "ready", first
    return proc


def _run_and_kill(path: Path, mode: str, n_before_kill: int) -> list[int]:
    """Run the child until it has acknowledged `n_before_kill` points, SIGKILL it, return them."""
    proc = _start(path, mode)
    acked = []
    try:
        while len(acked) < n_before_kill:
            line = proc.stdout.readline()
            assert line, "child ended early"
            acked.append(int(line))
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
        proc.stdout.close()
    return acked


def test_sigkill_at_random_points_then_resume_completes_without_gap_or_duplicate(tmp_path):
    seed = random.randrange(1 << 30)
    rnd = random.Random(seed)
    path = tmp_path / "s.h5"
    acked_all: set[int] = set()
    for attempt, mode in enumerate(("new", "resume", "resume")):
        acked = _run_and_kill(path, mode, rnd.randint(1, 120))
        acked_all.update(acked)
        s = read_session(path)  # opens the killed file
        idx = s.points["index"]
        assert acked_all <= set(idx.tolist()), f"seed {seed}: acknowledged point lost"
        assert len(idx) == len(set(idx.tolist())), f"seed {seed}: duplicate index"
        assert np.array_equal(s.points["error_um"], _expected(idx)), f"seed {seed}: row content"
        assert s.outcome == "incomplete"
        assert len(s.resumed_utc) == attempt
    proc = _start(path, "resume")
    assert proc.stdout.read().split()[-1] == "finished"
    assert proc.wait(timeout=30) == 0
    s = read_session(path)
    idx = s.points["index"]
    assert sorted(idx.tolist()) == list(range(TOTAL)), f"seed {seed}: missing or duplicate index"
    assert np.array_equal(s.points["error_um"], _expected(idx))
    assert s.outcome == "completed" and len(s.resumed_utc) == 3 and s.attrs["session_id"] == "kill"
    assert not list(tmp_path.glob(".*.tmp")), "temporary files left behind"


# the resume is killed (a real SIGKILL, not an exception) at its two dangerous moments
CRASHING_RESUME = r"""
import os, signal, sys
import procedures.io.recording.writer as wr
where = sys.argv[2]
def die(*a, **k):
    os.kill(os.getpid(), signal.SIGKILL)
if where == "before_rename":
    wr.os.replace = die  # temporary file complete, not yet renamed
else:
    real = wr._write_rows
    def half(ds, rows):
        real(ds, rows[: len(rows) // 2])
        die()
    wr._write_rows = half  # temporary file half written
wr.SessionWriter.resume(sys.argv[1])
"""


def test_a_crash_during_resume_leaves_the_original_intact(tmp_path):
    path = tmp_path / "s.h5"
    acked = _run_and_kill(path, "new", 50)
    before = file_sha256(path)
    n_before = len(read_session(path).points)
    for where in ("before_rename", "mid_copy"):
        proc = subprocess.run([sys.executable, "-c", CRASHING_RESUME, str(path), where], timeout=60)
        assert proc.returncode == -signal.SIGKILL
        assert file_sha256(path) == before, where
    assert len(read_session(path).points) == n_before and set(acked) <= read_session(path).indices
    with SessionWriter.resume(path) as w:  # and a later resume still works, cleaning up
        assert w.indices_written() == read_session(path).indices
        w.append_point(dict(index=TOTAL + 1, leg=1, run=1, direction=1, target_mm=0.0))
        w.finish("completed")
    assert not list(tmp_path.glob(".*.tmp"))
    assert len(read_session(path).points) == n_before + 1


CTRL_C_WRITER = r"""
import sys
from procedures.io.recording.writer import SessionWriter
with SessionWriter.create(sys.argv[1], session_id="c", operator="t", rig="sim", plan={}, station_config={},
                          devices={}, software_version="t") as w:
    print("ready", flush=True)
    for i in range(10**7):
        w.append_point(dict(index=i, leg=1, run=1, direction=1, target_mm=float(i % 180) - 90.0))  # within the stroke
        print(i, flush=True)
"""


def test_ctrl_c_leaves_a_finished_aborted_file_that_resumes(tmp_path):
    path = tmp_path / "s.h5"
    proc = subprocess.Popen([sys.executable, "-c", CTRL_C_WRITER, str(path)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "ready"
    acked = [int(proc.stdout.readline()) for _ in range(30)]
    proc.send_signal(signal.SIGINT)  # KeyboardInterrupt: the with-block finishes the file as aborted
    # Python drops a KeyboardInterrupt that lands in a weakref callback ("Exception ignored"):
    # if the child is still appending long after the signal, press Ctrl-C again, as a user would.
    since_signal = 0
    for _line in proc.stdout:
        since_signal += 1
        if since_signal % 5000 == 0:
            proc.send_signal(signal.SIGINT)
    proc.wait(timeout=30)
    s = read_session(path)
    assert s.outcome == "aborted" and set(acked) <= s.indices and s.unwritten_rows == 0
    with h5py.File(path, "r") as h:  # closed cleanly: no SWMR flag left, no unwritten row
        assert (h["points"]["index"][...] >= 0).all()
    with SessionWriter.resume(path) as w:
        assert w.indices_written() == s.indices
        w.finish("completed")
    assert read_session(path).outcome == "completed"


LIVE_WRITER = r"""
import sys
from procedures.io.recording.writer import SessionWriter
w = SessionWriter.create(sys.argv[1], session_id="live", operator="t", rig="sim", plan={}, station_config={},
                         devices={}, software_version="t")
print("ready", flush=True)
for line in sys.stdin:  # one point per line from the parent, acknowledged after it is on disk
    i = int(line)
    w.append_point(dict(index=i, leg=1, run=1, direction=1, target_mm=float(i % 180) - 90.0, error_um=i / 10))
    print(i, flush=True)
w.finish("completed")
print("finished", flush=True)
"""


def test_second_process_reads_points_while_the_file_grows(tmp_path):
    path = tmp_path / "live.h5"
    proc = subprocess.Popen([sys.executable, "-c", LIVE_WRITER, str(path)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        with LiveReader(path) as live:
            assert len(live.poll()) == 0
            for i in range(25):
                proc.stdin.write(f"{i}\n")
                proc.stdin.flush()
                assert int(proc.stdout.readline()) == i
                new = live.poll()  # acknowledged, so visible now: no waiting
                assert new["index"].tolist() == [i] and new["error_um"][0] == i / 10
            mid = read_session(path)  # a full read of a file still being written works too
            assert len(mid.points) == 25 and mid.outcome == "incomplete"
            proc.stdin.write("25\n")
            proc.stdin.close()  # the writer finishes while the live reader still has the file open
            assert int(proc.stdout.readline()) == 25
            assert proc.stdout.readline().strip() == "finished"
            assert live.poll()["index"].tolist() == [25]
    finally:
        proc.kill() if proc.poll() is None else None
        proc.wait(timeout=30)
    assert read_session(path).outcome == "completed"


def test_resume_is_refused_while_another_process_is_still_writing(tmp_path):
    path = tmp_path / "live.h5"
    proc = subprocess.Popen([sys.executable, "-c", LIVE_WRITER, str(path)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        proc.stdin.write("0\n")
        proc.stdin.flush()
        assert int(proc.stdout.readline()) == 0
        before = file_sha256(path)
        with pytest.raises(InputError, match=rf"another station process \(pid {proc.pid}\) is writing"):
            SessionWriter.resume(path)
        with pytest.raises(InputError, match="another station process"):  # even with overwrite
            SessionWriter.create(path, session_id="x", operator="", rig="sim", plan={}, station_config={},
                                 devices={}, software_version="t", overwrite=True)
        assert file_sha256(path) == before
        proc.stdin.write("1\n")  # the first writer carries on undisturbed
        proc.stdin.close()
        assert int(proc.stdout.readline()) == 1 and proc.stdout.readline().strip() == "finished"
    finally:
        proc.kill() if proc.poll() is None else None
        proc.wait(timeout=30)
    assert read_session(path).indices == {0, 1}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["live.h5"]  # lock file gone


def test_points_acknowledged_after_the_last_batch_survive_a_kill_in_the_journal(tmp_path):
    """/points grows in batches; a point acknowledged since the last one is in the journal only,
    and every reader of the killed file (read_session, LiveReader, resume) has it."""
    from procedures.io.recording.journal import journal_path
    from procedures.io.recording.writer import FLUSH_ROWS

    path = tmp_path / "s.h5"
    n = FLUSH_ROWS + FLUSH_ROWS // 2  # one batch in /points, the rest journalled (fast: < FLUSH_S)
    proc = subprocess.Popen([sys.executable, "-c", CHILD.replace("w.finish(", "time.sleep(60); w.finish(")
                             .replace("import os,", "import time, os,"), str(path), "new", str(n)],
                            stdout=subprocess.PIPE, text=True)
    try:
        lines = [proc.stdout.readline() for _ in range(n + 1)]
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
        proc.stdout.close()
    acked = [int(x) for x in lines[1:]]
    assert len(acked) == n and journal_path(path).exists()
    with h5py.File(path, "r", swmr=True) as h:  # a plain HDF5 reader: the batches only
        in_h5 = {int(i) for i in h["points"]["index"][...] if i >= 0}
    assert set(acked) - in_h5, "no point was in the journal only: the test did not test it"
    s = read_session(path)
    assert set(acked) <= s.indices and np.array_equal(s.points["error_um"], _expected(s.points["index"]))
    with LiveReader(path) as live:
        assert set(acked) <= set(live.poll()["index"].tolist())
    with SessionWriter.resume(path) as w:
        assert set(acked) <= w.indices_written()
        w.finish("completed")
    with h5py.File(path, "r") as h:  # all in the HDF5 file now, the journal gone
        assert set(acked) <= set(h["points"]["index"][...].tolist())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.h5"]


def test_a_journal_row_cut_short_or_of_another_session_is_not_read(tmp_path):
    from procedures.io.recording.journal import journal_path

    path = tmp_path / "s.h5"
    acked = _run_and_kill(path, "new", 5)
    j = journal_path(path)
    data = j.read_bytes()
    whole = read_session(path).indices
    assert set(acked) <= whole
    j.write_bytes(data + data[-50:])  # a kill mid-write of one more row
    assert read_session(path).indices == whole
    j.write_bytes(data.replace(b'"kill"', b'"kilX"', 1))  # another session's journal beside it
    with h5py.File(path, "r", swmr=True) as h:
        in_h5 = {int(i) for i in h["points"]["index"][...] if i >= 0}
    assert read_session(path).indices == in_h5  # only what /points holds: the journal is not this session's
