"""A session interrupted among its reversal probes and resumed (docs/onthefly.md, "Reversal
probes"): every probe, the first after the resume too, is read right after a reversal, over the
same travel, with the probe averaging, as in an uninterrupted run; the resumed file's reversal
from the probes agrees with an uninterrupted run's. The station's simulated rig (real Modbus TCP
and pty), the services' resume path (`run_sweep(..., resume=True)`, what `station sweep
--resume` and the Sweep page run); the drive-side sequence is logged by wrapping the axis's
`move_to` (the commanded targets), the laser's `set_averaging` and the clock's `sleep`."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from procedures.acquisition.plans import onthefly_plan
from procedures.engine import events as ev
from procedures.engine.control import RunControl
from procedures.engine.runner import CallbackSink
from procedures.fit import fit
from procedures.fit.reversal_probes import is_probe
from procedures.io.recording.reader import read_session
from procedures.metrology.thermal import normalise_points, recorded_materials
from station.services.config import StationConfig
from station.services.jobs import run_sweep
from station.services.wiring import open_rig

FIXED = onthefly_plan((1,), cycles=2, step_mm=5.0, reversal_probes=6)
ADAPTIVE = onthefly_plan((1,), cycles=2, step_mm=5.0, reversal_probes=30, probe_target_um=1e-4)
"""An adaptive count (procedures/acquisition/probe_rule.py) with a target no leg reaches: every pair,
in blocks of 12 climbing and descending the stroke (a descending block's upward readings are
approached from below, SweepPlan.probe_via_mm); a resumed sweep, without its passes' fit, takes every
pair too, so both runs read the same probes."""
FIRST_PROBE = 2 * FIXED.cycles * FIXED.points_per_pass  # plan index of the first probe
# the resume begins with an upward probe: after the second pair's downward reading; with the
# adaptive count after the 14th's, in the descending second block
CASES = {"fixed": (FIXED, FIRST_PROBE + 3), "adaptive": (ADAPTIVE, FIRST_PROBE + 2 * 14 - 1)}
RUNS = (("fixed", 0), ("fixed", 4), ("adaptive", 0))


def _logged(rig, log: list) -> None:
    """Log the commanded moves, averaging settings and sleeps of `rig` into `log`, in order."""
    axis, laser, clock = rig.axes[1], rig.laser, rig.clock
    move_to, set_averaging, sleep = axis.move_to, laser.set_averaging, clock.sleep

    depth = [0]  # a move at a speed of its own calls move_to again: log the outer call only

    def logged_move(target_mm, *a, **kw):
        if not depth[0]:
            log.append(("move", float(target_mm)))
        depth[0] += 1
        try:
            return move_to(target_mm, *a, **kw)
        finally:
            depth[0] -= 1

    def logged_averaging(averaging_s):
        log.append(("averaging", float(averaging_s)))
        return set_averaging(averaging_s)

    def logged_sleep(dt_s):
        log.append(("sleep", float(dt_s)))
        return sleep(dt_s)

    axis.move_to, laser.set_averaging, clock.sleep = logged_move, logged_averaging, logged_sleep


def _session(tmp_path: Path, case: str, seed: int, stop_after: int | None) -> tuple[Path, list, list]:
    """Record the `case`'s plan on the station's simulated rig (plant seed `seed`); with `stop_after`, abort
    once that plan index is recorded and resume on the same rig (the leg keeps its state, as a
    real one does while the station restarts). (file, log of the first run, log of the resumed one)."""
    cfg = StationConfig(operator="test")
    cfg = replace(cfg, sim=replace(cfg.sim, seed=seed))
    plan = CASES[case][0]
    out = tmp_path / f"otf-{case}-{seed}-{'resumed' if stop_after is not None else 'whole'}.h5"
    logs: list[list] = [[], []]
    with open_rig(cfg, legs=(1,), time_scale=0.0) as rig:
        control = RunControl()

        def on_event(e: ev.Event) -> None:
            if isinstance(e, ev.PointMeasured):
                logs[current].append(("point", e.record))
                if stop_after is not None and int(e.record["index"]) == stop_after:
                    control.abort("test: interrupted among the probes")

        current = 0
        _logged(rig, logs[0])
        first = run_sweep(rig, plan, out, cfg, sinks=[CallbackSink(on_event)], control=control, index=False)
        if stop_after is not None:
            assert first.outcome == "aborted"
            current = 1
            _logged(rig, logs[1])
            second = run_sweep(rig, plan, out, cfg, resume=True, sinks=[CallbackSink(on_event)], index=False)
            assert second.outcome == "completed"
        else:
            assert first.outcome == "completed"
    return out, logs[0], logs[1]


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    """(case, seed) -> ((uninterrupted: file, log, []), (resumed: file, log before, log after))."""
    tmp = tmp_path_factory.mktemp("probe-resume")
    return {(case, seed): (_session(tmp, case, seed, None), _session(tmp, case, seed, CASES[case][1]))
            for case, seed in RUNS}


def _probe_approaches(log: list, plan) -> dict[int, tuple[float, float, float, list]]:
    """Plan index of each probe read in `log` -> (the three last commanded targets before it:
    two moves back, one back, the probe's own; what happened after its move)."""
    out = {}
    moves: list[float] = []
    since: list = []
    for kind, value in log:
        if kind == "move":
            moves.append(value)
            since = []
        elif kind == "point":
            if plan.is_probe_run(int(value["run"])):
                assert len(moves) >= 3, "a probe read before three moves of its leg"
                out[int(value["index"])] = (moves[-3], moves[-2], moves[-1], since)
        else:
            since.append((kind, value))
    return out


def _averaging_at(log: list) -> dict[int, float | None]:
    """Plan index of each point -> the laser averaging last set before it in `log`."""
    out, now = {}, None
    for kind, value in log:
        if kind == "averaging":
            now = value
        elif kind == "point":
            out[int(value["index"])] = now
    return out


@pytest.mark.parametrize("case,seed", RUNS)
def test_every_probe_follows_a_reversal_the_resumed_ones_too(sessions, case, seed):
    (_, whole, _), (_, before, after) = sessions[(case, seed)]
    PLAN, stop_after = CASES[case]
    probes = {p.index: p for p in PLAN.points() if PLAN.is_probe_run(p.run)}
    in_whole = _probe_approaches(whole, PLAN)
    resumed = {**_probe_approaches(before, PLAN), **_probe_approaches(after, PLAN)}
    assert sorted(in_whole) == sorted(resumed) == sorted(probes)
    assert min(_probe_approaches(after, PLAN)) == stop_after + 1  # the resume began among the probes
    if case == "adaptive":  # it began with an upward probe below the pair before: approached from below
        assert PLAN.probe_via_mm(probes[stop_after + 1].run) is not None
    for index, p in probes.items():
        for log in (in_whole, resumed):
            m2, m1, target, since = log[index]
            assert target == pytest.approx(p.target_mm)
            # approached in the probe's direction, from a move the other way: right after a reversal
            assert np.sign(target - m1) == p.direction and np.sign(m1 - m2) == -p.direction, (index, m2, m1, target)
            assert ("sleep", PLAN.dwell_s) in since  # the plan's dwell before the reading
        # from where the uninterrupted run left the axis: the same travel since the reversal
        assert resumed[index][1] == pytest.approx(in_whole[index][1]), index
    for log in (whole, before, after):
        averaging = _averaging_at(log)
        for index in probes:
            if index in averaging:
                assert averaging[index] == PLAN.probe_averaging_s, index


@pytest.mark.parametrize("case,seed", RUNS)
def test_the_resumed_sessions_probe_reversal_agrees_with_an_uninterrupted_runs(sessions, case, seed):
    (whole, _, _), (resumed, _, _) = sessions[(case, seed)]
    PLAN = CASES[case][0]
    got = []
    for path in (whole, resumed):
        session = read_session(path)
        pts = session.points
        assert sorted(pts["index"].tolist()) == list(range(PLAN.total_points))  # none twice, none missing
        assert np.count_nonzero(is_probe(pts)) == 2 * PLAN.reversal_probes
        _, materials = recorded_materials(session.station_config)  # as `station fit` normalises
        model = fit(normalise_points(pts, materials).points)
        got.append(model.legs[1].selection["reversal_probes"])
    (a, b) = got
    assert a["pairs"] == b["pairs"] == PLAN.reversal_probes
    # the probes read before the interruption are the same readings; the rest are new draws of the
    # pass offsets and noise (the resume re-zeroes the laser and draws offsets of its own): within
    # twice the two runs' stated standard errors combined (measured: seed 0 0.008 um apart, seed 4
    # 0.022 um, each standard error 0.021-0.027 um)
    tol = 2.0 * float(np.hypot(a["stderr_um"], b["stderr_um"]))
    assert abs(a["after_um"] - b["after_um"]) <= tol, (a, b)
