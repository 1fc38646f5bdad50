"""The one shape of a rig job (station/services/job.py, issue 32 part 1): a request's prepare makes
its refusals with nothing written, connected or moved; the JobRunner runs one rig job at a time,
asks a job's question before it runs, and its abort stops a running sweep on the simulated rig (a
real Modbus server on loopback, the laser behind a pty), leaving a valid, resumable recording."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from procedures.vocabulary import InputError
from procedures.io.recording.reader import read_session
from station.services.config import StationConfig
from station.services.job import JobOutcome, JobRunner, NotConfirmed, RigBusy
from station.services.push_jobs import PreparedRefusal, PushRequest, prepare_push
from station.services.sweep_job import OutputExists, SweepRequest, prepare_sweep

pytestmark = pytest.mark.timeout(60)


def _cfg(tmp_path: Path) -> StationConfig:
    cfg = StationConfig(operator="test")
    cfg.recordings_dir = str(tmp_path / "runs")
    return cfg


def _listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def test_prepare_refuses_with_nothing_written_connected_or_moved(tmp_path):
    cfg = _cfg(tmp_path)
    kept = tmp_path / "kept.h5"
    kept.write_bytes(b"a session")
    before = _listing(tmp_path)
    refusals = [
        (SweepRequest(out=kept), OutputExists, "exists already"),
        (SweepRequest(out=tmp_path / "new.h5", min_mm=10.0, max_mm=-10.0), InputError, ""),
        (SweepRequest(out=tmp_path / "no-folder" / "s.h5"), InputError, "does not exist"),
        (SweepRequest(out=tmp_path / "s.txt"), InputError, "must end in .h5"),
        (SweepRequest(out=tmp_path / "s.h5", time_scale=-1.0), InputError, "--time-scale must be a number >= 0"),
        (SweepRequest(out=kept, resume=True), InputError, str(kept)),  # not a session: nothing to resume
        (SweepRequest(out=tmp_path / "huge.h5", step_mm=0.0001, legs="1-6"), InputError, "max_points"),
    ]
    for request, kind, words in refusals:
        with pytest.raises(kind, match=None) as info:
            prepare_sweep(request, cfg)
        assert words in str(info.value), (request, str(info.value))
        assert _listing(tmp_path) == before, request  # not even the recordings folder
    assert kept.read_bytes() == b"a session"
    # a push whose values look like nm: refused before any drive is opened; its run logs the refusal only
    table = tmp_path / "t.csv"
    table.write_text("leg,position_mm,error_fwd_um,error_rev_um\n"
                     + "".join(f"1,{-90 + 15 * i},{250.0 + i},{-240.0 - i}\n" for i in range(13)))
    cfg.drive.url = "sim"
    job = prepare_push(PushRequest(legs="1", table=table, audit=tmp_path / "audit.jsonl"), cfg)
    assert isinstance(job, PreparedRefusal) and job.implausible and not job.needs_rig
    assert not (tmp_path / "audit.jsonl").exists()  # prepared: nothing written yet
    ended = JobRunner().run(job)
    assert ended.status == "refused" and ended.implausible and not ended.ok
    assert "--accept-implausible" in ended.finished.message


class _Job:
    """A rig job without hardware: its run waits for `go` (or its abort)."""

    needs_rig = True
    lines: list[str] = []

    def __init__(self, question: str | None = None) -> None:
        self.question = question
        self.declined = "not swept: the question was answered no; nothing moved"
        self.started = threading.Event()
        self.go = threading.Event()
        self.ran = False

    def run(self, sinks=(), control=None) -> JobOutcome:
        self.ran = True
        self.started.set()
        while not self.go.wait(0.01):
            if control.aborted:
                return JobOutcome("aborted")
        return JobOutcome("completed")


def test_the_runner_runs_one_rig_job_at_a_time_and_asks_its_question_first():
    runner = JobRunner()
    first, second = _Job(), _Job()
    ended: list[JobOutcome] = []
    worker = threading.Thread(target=lambda: ended.append(runner.run(first)))
    worker.start()
    assert first.started.wait(5)
    assert runner.busy
    with pytest.raises(RigBusy, match="busy"):
        runner.run(second)
    with pytest.raises(RigBusy):
        runner.claim()
    assert not second.ran
    # a job that does not touch the rig runs beside it
    beside = _Job()
    beside.needs_rig = False
    beside.go.set()
    assert runner.run(beside).status == "completed"
    first.go.set()
    worker.join(5)
    assert ended[0].status == "completed" and not runner.busy
    # the question: refused unless confirmed, before the job runs
    asked = _Job("Sweep the compensated leg?")
    with pytest.raises(NotConfirmed, match="answered no; nothing moved"):
        runner.run(asked)
    with pytest.raises(NotConfirmed):
        runner.run(asked, confirm=lambda question: False)
    assert not asked.ran and not runner.busy
    asked.go.set()
    questions: list[str] = []
    assert runner.run(asked, confirm=lambda q: questions.append(q) or True).status == "completed"
    assert questions == ["Sweep the compensated leg?"]


def test_abort_stops_a_sweep_on_the_simulated_rig(tmp_path):
    cfg = _cfg(tmp_path)
    Path(cfg.recordings_dir).mkdir()
    out = Path(cfg.recordings_dir) / "s.h5"
    job = prepare_sweep(SweepRequest(out=out, legs=(1,), n_targets=6, min_mm=-20.0, max_mm=20.0, cycles=2,
                                     dwell_s=0.2, time_scale=0.05), cfg)
    assert job.total_points == 24 and not out.exists()
    runner = JobRunner()
    points: list[int] = []

    class Count:
        critical = False

        def handle(self, event) -> None:
            if type(event).__name__ == "PointMeasured":
                points.append(event.done)

        def close(self, outcome: str) -> None:
            pass

    ended: list[JobOutcome] = []
    with job.connect(sim_memory=False) as rig:
        worker = threading.Thread(target=lambda: ended.append(runner.run(job, [Count()])))
        worker.start()
        deadline = time.monotonic() + 20
        while len(points) < 3 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert len(points) >= 3, "the sweep did not start"
        t0 = time.monotonic()
        assert runner.abort()
        worker.join(10)
        assert not worker.is_alive()
        assert time.monotonic() - t0 < 5
        # the drive stands still: its position does not change any more
        here = rig.axes[1].status().position_mm
        time.sleep(0.3)
        assert rig.axes[1].status().position_mm == pytest.approx(here, abs=1e-6)
    assert ended[0].status == "aborted" and ended[0].points < job.total_points
    assert not runner.busy and runner.abort() is False
    session = read_session(out)
    assert session.outcome == "aborted" and len(session.points) == ended[0].points
