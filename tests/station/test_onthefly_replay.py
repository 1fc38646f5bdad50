"""Record -> replay of an on-the-fly session (docs/onthefly.md): the replay drives' position
compare triggers the replay interferometer's capture, over the same Modbus server and pty, and
the replayed file is identical to the recording, field by field."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from procedures.acquisition.plans import onthefly_plan
from procedures.io.recording.reader import read_session
from procedures.io.recording.schema import FLAG_ANCHOR, FLAG_PROBE, FLAG_REPLAYED
from station.services.samples import open_sample_rig
from procedures.acquisition.replay_compare import compare_sessions
from station.services.jobs import replay_sweep
from station.services.config import StationConfig
from station.services.jobs import run_sweep
from station.services.wiring import open_replay_rig

CFG = StationConfig(operator="test")


def test_onthefly_session_replays_identically(tmp_path: Path):
    original = tmp_path / "otf.h5"
    plan = onthefly_plan((1, 2), cycles=2, step_mm=2.5, reversal_probes=3)
    with open_sample_rig() as rig:
        result = run_sweep(rig, plan, original, CFG)
    assert result.outcome == "completed"
    live = read_session(original)
    # 2 legs x (2 cycles x 2 directions x (73 captured targets + the pass's anchor at rest) + 3 probe pairs)
    assert len(live.points) == plan.total_points == 2 * (2 * 2 * (73 + 1) + 3 * 2)
    anchors = (live.points["flags"] & FLAG_ANCHOR) != 0
    assert np.count_nonzero(anchors) == 8 and np.all(np.isnan(live.points["speed_mm_s"][anchors]))
    assert set(np.abs(live.points["target_mm"][anchors])) == {94.0}
    probes = (live.points["flags"] & FLAG_PROBE) != 0
    assert np.count_nonzero(probes) == 12 and np.all(np.isnan(live.points["speed_mm_s"][probes]))
    v = live.points["speed_mm_s"][~anchors & ~probes]
    # every sample carries its speed: +/-10 and +/-20 mm/s, signed with the direction
    assert np.all(np.sign(v) == live.points["direction"][~anchors & ~probes])
    assert sorted({round(abs(x)) for x in v}) == [10, 20]
    out = tmp_path / "replayed.h5"
    with open_replay_rig(original, None, CFG) as rig:
        replayed = replay_sweep(rig, live, out, CFG)
        assert rig.sim.mismatch is None
    assert replayed.outcome == "completed"
    rep = read_session(out)
    assert compare_sessions(live, rep).identical
    for name in live.points.dtype.names:
        if name != "flags":
            assert live.points[name].tobytes() == rep.points[name].tobytes(), name
    assert np.all(rep.points["flags"] == live.points["flags"] | FLAG_REPLAYED)


def test_an_aborted_onthefly_session_resumes_to_every_point_once(tmp_path: Path):
    from procedures.engine import events as ev
    from procedures.engine.control import RunControl
    from procedures.engine.runner import CallbackSink
    from station.services.jobs import resumable_plan

    out = tmp_path / "otf.h5"
    plan = onthefly_plan((1,), cycles=2, step_mm=5.0, reversal_probes=4)
    control = RunControl()

    def abort_mid_pass(e):
        if isinstance(e, ev.PointMeasured) and e.done in (50, 156):  # in the second pass; then among the probes
            control.abort("test")

    with open_sample_rig() as rig:
        first = run_sweep(rig, plan, out, CFG, sinks=[CallbackSink(abort_mid_pass)], control=control)
    assert first.outcome == "aborted"
    partial = read_session(out)
    assert 0 < len(partial.points) < plan.total_points
    assert resumable_plan(out) == plan
    with open_sample_rig() as rig:  # the passes, then the first probes (4 x 38 points before them)
        control = RunControl()
        second = run_sweep(rig, plan, out, CFG, resume=True, sinks=[CallbackSink(abort_mid_pass)], control=control)
    assert second.outcome == "aborted"
    assert 152 < len(read_session(out).points) < plan.total_points
    with open_sample_rig() as rig:
        second = run_sweep(rig, plan, out, CFG, resume=True)
    assert second.outcome == "completed"
    done = read_session(out)
    assert sorted(done.points["index"].tolist()) == list(range(plan.total_points))  # none twice, none missing


def test_an_adaptive_probe_count_replays_to_the_same_count(tmp_path: Path, capsys):
    """The adaptive probe count (procedures/acquisition/probe_rule.py) decides on the recorded
    readings: a replay takes the same pairs on every leg and stops where the recording did; `station
    fit` says on its probe line why they stopped."""
    from procedures.acquisition.probe_rule import PROBE_TARGET_UM
    from procedures.engine import events as ev
    from procedures.engine.runner import CallbackSink

    original = tmp_path / "otf-probes.h5"
    plan = onthefly_plan((1, 2), cycles=2, step_mm=2.5, reversal_probes=30, probe_target_um=PROBE_TARGET_UM)
    stops: list[list] = [[], []]
    with open_sample_rig() as rig:
        result = run_sweep(rig, plan, original, CFG, sinks=[CallbackSink(
            lambda e: isinstance(e, ev.ProbesStopped) and stops[0].append((e.leg, e.pairs, e.reason)))])
    assert result.outcome == "completed"
    live = read_session(original)
    assert [leg for leg, _, _ in stops[0]] == [1, 2]
    assert len(live.points) < plan.total_points  # some pairs were not needed (the sample legs are quiet)
    out = tmp_path / "replayed.h5"
    with open_replay_rig(original, None, CFG) as rig:
        replayed = replay_sweep(rig, live, out, CFG, sinks=[CallbackSink(
            lambda e: isinstance(e, ev.ProbesStopped) and stops[1].append((e.leg, e.pairs, e.reason)))])
        assert rig.sim.mismatch is None
    assert replayed.outcome == "completed" and stops[1] == stops[0]
    rep = read_session(out)
    assert compare_sessions(live, rep).identical
    assert live.points["error_um"].tobytes() == rep.points["error_um"].tobytes()
    from station.cli import main

    capsys.readouterr()
    assert main(["fit", str(original), "--out", str(tmp_path / "model.json")]) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if "probe pairs" in line]
    assert len(lines) == 2
    for (leg, pairs, reason), line in zip(stops[0], lines):
        assert f"reversal from {pairs} probe pairs" in line and "; probes stopped: " in line, line
        assert line.split("; probes stopped: ")[1].split(" um")[0] == reason.split(" um")[0], (line, reason)
