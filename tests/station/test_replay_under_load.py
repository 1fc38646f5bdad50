"""A replay runs on the recording's clock only: the replayed session is identical to the recording
however busy the machine is (every time_s equal), because no wall-clock timeout can fire on a
request the replay devices answer, and a query answered again does not move the replay clock.

The samples are replayed as `station replay` does (station.services.wiring.open_replay_rig, the replay job
station.services.jobs.replay_sweep, procedures.acquisition.replay_compare.compare_sessions), over the real Modbus TCP
and serial pty clients. The CPU-load test is statistical (it cannot fail on a correct replay, and
a wall-clock leak makes it fail sometimes); the late-reply test makes the devices answer late on
purpose, so it fails every time a timeout would fire on a replay."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from procedures.engine import events as ev
from procedures.acquisition.plans import iso230_plan
from procedures.io.recording.reader import read_session
from procedures.acquisition.replay_compare import compare_sessions
from procedures.engine.runner import CallbackSink
from station.services.samples import FILES, open_sample_rig
from station.services.config import StationConfig
from station.services.jobs import replay_sweep, run_sweep
from station.services.wiring import REPLAY_LASER_TIMEOUT_S, open_replay_rig

RECORDINGS = Path(__file__).resolve().parents[2] / "recordings"
CFG = StationConfig(operator="test")
BURN_LIMIT_S = 60.0  # a burner ends by itself after this, even if the test process dies
STALL_S = 0.8  # longer than the old replay timeouts (0.3 s per position query, 0.5 s per Modbus attempt)


def replay_and_compare(source: Path, out: Path, prepare=None):
    """Replay `source` as `station replay` does; returns (result, comparison, original, replayed, rig)."""
    session = read_session(source)
    with open_replay_rig(source, None, CFG) as rig:
        if prepare is not None:
            prepare(rig.sim)
        result = replay_sweep(rig, session, out, CFG)
        assert rig.sim.mismatch is None, rig.sim.mismatch
    replayed = read_session(out)
    return result, compare_sessions(session, replayed), session, replayed, rig


def assert_same_times(original, replayed) -> None:
    o = original.points[np.argsort(original.points["index"], kind="stable")]
    r = replayed.points[np.argsort(replayed.points["index"], kind="stable")]
    assert np.array_equal(o["index"], r["index"])
    assert o["time_s"].tobytes() == r["time_s"].tobytes(), "every replayed time_s is the recorded one, bit for bit"
    assert original.faults["time_s"].tobytes() == replayed.faults["time_s"].tobytes()


@pytest.fixture
def cpu_load():
    """Busy loops in other processes on every core (at least two), for the test's duration."""
    code = f"import time\nend = time.monotonic() + {BURN_LIMIT_S}\nwhile time.monotonic() < end:\n    pass\n"
    burners = [subprocess.Popen([sys.executable, "-c", code]) for _ in range(max(2, os.cpu_count() or 2))]
    try:
        time.sleep(0.2)  # let them get going
        assert all(b.poll() is None for b in burners)
        yield len(burners)
    finally:
        for b in burners:
            b.kill()
        for b in burners:
            b.wait(timeout=10)


@pytest.mark.parametrize("sample", ["fault", "verification"])
def test_replay_is_identical_to_the_recording_under_cpu_load(cpu_load, sample, tmp_path):
    source = RECORDINGS / FILES[sample]
    result, cmp, original, replayed, _ = replay_and_compare(source, tmp_path / "r.h5")
    assert cmp.identical, cmp.differences
    assert result.outcome == original.outcome
    assert_same_times(original, replayed)


def stall(plant, method: str, when) -> list[float]:
    """Make the replay devices answer late, once: `plant.<method>` (called by a server thread,
    under the rig lock) sleeps STALL_S first the first time `when(plant)` holds, as a server
    thread kept off the CPU would. Returns the stalls made (their start times)."""
    made: list[float] = []
    original = getattr(plant, method)

    def late(*args, **kwargs):
        if not made and when(plant):
            made.append(time.monotonic())
            time.sleep(STALL_S)
        return original(*args, **kwargs)

    setattr(plant, method, late)
    return made


def test_late_replies_are_waited_for_not_asked_again(tmp_path):
    """A reply held up longer than a short timeout (a reading, a recorded beam break, a move)
    is waited for: asked again, the reading would come back with a later time, the beam break
    would take the next recorded attempt's, and a move would become a time-out fault."""
    source = RECORDINGS / FILES["fault"]
    fault = read_session(source).faults[0]
    fault_index, fault_leg = int(fault["index"]), int(fault["leg"])
    stalls: list[list[float]] = []

    def prepare(rig):
        p1, p2 = rig.plants[1], rig.plants[fault_leg]
        at = lambda index: lambda p: p.current is not None and p.current.index == index  # noqa: E731
        arrivals = iter(range(1, 10**6))
        stalls.append(stall(p1, "reading", at(26)))  # a reading
        stalls.append(stall(p2, "reading", at(fault_index)))  # the first recorded beam break
        stalls.append(stall(p1, "arrived", lambda p: next(arrivals) == 40))  # a move

    result, cmp, original, replayed, rig = replay_and_compare(source, tmp_path / "r.h5", prepare)
    assert [len(s) for s in stalls] == [1, 1, 1], "each stall happened once"
    assert cmp.identical, cmp.differences
    assert_same_times(original, replayed)
    assert rig.laser.retried == 0 and rig.laser.timeout_s == REPLAY_LASER_TIMEOUT_S > STALL_S


def test_recorded_time_outs_and_line_noise_come_back_at_their_recorded_times_at_once(tmp_path):
    """With an averaging time, the client's retries into a replayed silence or garbled replies
    do not move the replay clock, and a replayed silence costs no timeout."""
    original = tmp_path / "o.h5"
    plan = iso230_plan((1,), n_targets=6, cycles=1)
    assert plan.averaging_s > 0

    def inject(rig, e):
        if isinstance(e, ev.PointMeasured) and e.record["index"] == 3:
            rig.sim.laser_server.set_silent(True)
        elif isinstance(e, ev.PointMeasured) and e.record["index"] == 8:
            rig.sim.laser_server.inject_garbage(3)
        elif isinstance(e, ev.Fault) and e.kind == "timeout":
            rig.sim.laser_server.set_silent(False)

    with open_sample_rig() as rig:
        run_sweep(rig, plan, original, CFG, sinks=[CallbackSink(lambda e: inject(rig, e))])
    recorded = read_session(original)
    assert [k.decode() for k in recorded.faults["kind"]] == ["timeout", "framing"]
    t0 = time.monotonic()
    result, cmp, original_s, replayed, rig = replay_and_compare(original, tmp_path / "r.h5")
    assert cmp.identical, cmp.differences
    assert_same_times(original_s, replayed)
    attempts = rig.laser.retries + 1
    assert rig.sim.timeout_clock.silences == attempts
    assert time.monotonic() - t0 < REPLAY_LASER_TIMEOUT_S, "a replayed silence does not wait for the timeout"
