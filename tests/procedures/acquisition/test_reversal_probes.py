"""Reversal probes (docs/onthefly.md, "Reversal probes"): stop-and-go readings right after a
reversal, after an on-the-fly leg's passes, fix its table's reversal. The plan, the sweep over
the real protocols (Modbus TCP on 127.0.0.1, the interferometer on a pty) and the fit."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from drivers.interferometer.client import SerialInterferometer
from drivers.modbus.client import connect_axes
from drivers.plant.leg import default_leg_configs
from drivers.sim.rig import SimRig
from procedures.acquisition.adaptive import MIN_CYCLES_WITH_PROBES
from procedures.acquisition.plans import SweepPlan, onthefly_plan
from procedures.acquisition.sweep import sweep
from procedures.engine import events as ev
from procedures.vocabulary import PlanError
from procedures.fit import fit
from procedures.fit.dynamic import static_points
from procedures.fit.reversal_probes import apply_probes, is_probe
from procedures.io.recording.schema import FLAG_PROBE
from procedures.io.recording.writer import point_row
from procedures.metrology.thermal import Material, normalise_points

logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def run(plan: SweepPlan, seed: int, legs: int, without: tuple[str, ...] = (), laser_class=SerialInterferometer):
    """(points, events, plant configs) of `plan` on a fresh simulated rig with jerk-limited legs."""
    cfgs = [c.with_leg_motion().without(*without) for c in default_leg_configs(seed, legs)]
    with SimRig(time_scale=0.0, seed=seed, legs=legs, configs=cfgs) as rig:
        axes = connect_axes(rig.drive_url, list(plan.legs), clock=rig.clock)
        laser = laser_class(rig.laser_port)
        try:
            events = list(sweep(plan, axes, laser, rig.clock))
        finally:
            laser.close()
            for a in axes.values():
                a.close()
    return np.concatenate([point_row(e.record) for e in events if isinstance(e, ev.PointMeasured)]), events, cfgs


def test_probe_points_follow_the_passes_each_after_a_reversal():
    plan = onthefly_plan((1, 2), cycles=2, step_mm=2.0, reversal_probes=5)
    pts = plan.points()
    assert len(pts) == plan.total_points == 2 * (2 * 2 * plan.points_per_pass + 10)
    for leg in (1, 2):
        mine = [p for p in pts if p.leg == leg]
        probes = [p for p in mine if plan.is_probe_run(p.run)]
        assert len(probes) == 10 and mine[-10:] == probes  # after the leg's passes
        assert [p.run for p in probes] == list(range(5, 15))  # a run each: each its own pass offset
        assert [p.direction for p in probes] == [1, -1] * 5  # the last pass went down: every probe reverses
        ups = np.array([p.target_mm for p in probes[::2]])
        downs = np.array([p.target_mm for p in probes[1::2]])
        assert np.allclose(ups - downs, plan.probe_gap_mm)
        assert np.all(np.diff(ups) > 0)  # up the stroke, inside it
        assert downs.min() >= plan.targets_mm[0] and ups.max() <= plan.targets_mm[-1]
    again = SweepPlan.from_dict(plan.to_dict())
    assert again == plan and again.reversal_probes == 5
    assert "reversal_probes" not in onthefly_plan((1,), cycles=2).to_dict()  # stored as before probes
    with pytest.raises(PlanError, match="on-the-fly"):
        SweepPlan("iso230-2", (0.0, 1.0), 2, reversal_probes=3)
    with pytest.raises(PlanError, match="gap"):
        SweepPlan("onthefly", tuple(np.arange(0.0, 10.5, 0.5)), 2, speeds_mm_s=(10.0, 20.0), reversal_probes=3,
            probe_gap_mm=20.0)


@pytest.fixture(scope="module")
def clean():
    """Two legs without noise, pass offsets or drift: what the probes measure is the plant's reversal."""
    plan = onthefly_plan((1, 2), cycles=2, step_mm=1.0, reversal_probes=6)
    return run(plan, seed=3, legs=2, without=("noise", "run_offset", "drift"))


def test_probes_are_read_at_rest_and_recorded_flagged(clean):
    points, _, _ = clean
    probes = points[is_probe(points)]
    assert len(probes) == 2 * 12
    assert np.all(probes["flags"] & FLAG_PROBE) and np.all(np.isnan(probes["speed_mm_s"]))
    # at rest at the target (the drive's position actual there), a run each
    assert np.allclose(probes["drive_position_mm"], probes["target_mm"], atol=1e-3)
    assert len(np.unique(probes["run"][probes["leg"] == 1])) == 12
    # dropped from what the fit, the noise floor and ISO 230-2 see
    assert not np.any(is_probe(static_points(points)))


def test_without_pass_offsets_the_probes_give_the_plants_reversal(clean):
    points, _, cfgs = clean
    model = fit(points)
    for leg in (1, 2):
        f = model.legs[leg]
        got = f.selection["reversal_probes"]
        assert got["pairs"] == 6
        # sign: the reversal is down minus up, as the plant's reversal_um
        assert f.reversal_um == pytest.approx(cfgs[leg - 1].reversal_um, abs=0.003)
        assert got["after_um"] == pytest.approx(f.reversal_um)


@pytest.fixture(scope="module")
def noisy():
    """Three legs with the plant's pass offsets (0.04 um a reversal) and noise, two cycles each
    (adaptive: stopped on the shape, the reversal left to the probes), 24 probe pairs; the points
    normalised to 20 degC with each simulated leg's material, as `station fit` does."""
    plan = onthefly_plan((1, 2, 3), cycles=5, step_mm=1.0, reversal_probes=24, adaptive=True)
    points, events, cfgs = run(plan, seed=5, legs=3)
    mats = {leg: Material(cfgs[leg - 1].expansion_ppm_per_k, 1.0, cfgs[leg - 1].bearing_mm) for leg in (1, 2, 3)}
    return plan, normalise_points(points, mats).points, events, cfgs


def test_with_pass_offsets_the_probes_know_the_reversal_better_than_the_passes(noisy):
    plan, points, events, cfgs = noisy
    stops = [e for e in events if isinstance(e, ev.PassesStopped)]
    assert len(stops) == 3
    for s in stops:  # the rule stops on the shape from the second cycle on; the probes still run
        assert MIN_CYCLES_WITH_PROBES <= s.cycles <= plan.cycles
        assert "reversal probes" in s.reason or "most cycles" in s.reason
    assert np.count_nonzero(is_probe(points)) == 3 * 48
    model = fit(points)
    errors, stderrs = [], []
    for leg in (1, 2, 3):
        got = model.legs[leg].selection["reversal_probes"]
        errors.append(model.legs[leg].reversal_um - cfgs[leg - 1].reversal_um)
        stderrs.append(got["stderr_um"])
        # its own standard error says how well it is known: 24 pairs of 0.04 um offsets and noise
        assert 0.006 < got["stderr_um"] < 0.02, got
    # within 4 standard errors of the plant's reversal, leg by leg
    assert np.all(np.abs(errors) <= 4 * np.array(stderrs)), (errors, stderrs)


def test_apply_probes_moves_only_the_reversal_constant(clean):
    points, _, _ = clean
    model = fit(points[~is_probe(points)])
    f = model.legs[1]
    x = np.linspace(-80, 80, 9)
    up0, down0 = f.predict_um(x, 1), f.predict_um(x, -1)
    probes = points[is_probe(points) & (points["leg"] == 1)].copy()
    probes["error_um"][probes["direction"] < 0] += 0.05  # the probes see 0.05 um more reversal
    r = apply_probes(f, probes)
    assert r is not None and r.pairs == 6
    up1, down1 = f.predict_um(x, 1), f.predict_um(x, -1)
    # moved by half each way, the mean (the zero reference) and the shape untouched
    assert np.allclose(down1 - up1 - (down0 - up0), r.shift_um) and np.allclose(up1 + down1, up0 + down0)
    assert r.after_um - r.before_um == pytest.approx(r.shift_um)
    assert apply_probes(f, probes[probes["direction"] > 0]) is None  # one direction: nothing to tell


def test_a_beam_break_at_a_probe_is_retried_and_the_probe_flagged():
    from procedures.io.recording.schema import FLAG_ANCHOR, FLAG_RETRIED_BEAM

    plan = onthefly_plan((1,), cycles=2, step_mm=5.0, reversal_probes=3)
    cfgs = [c.with_leg_motion() for c in default_leg_configs(0, 1)]
    with SimRig(time_scale=0.0, seed=0, legs=1, configs=cfgs) as rig:
        axes = connect_axes(rig.drive_url, [1], clock=rig.clock)
        laser = SerialInterferometer(rig.laser_port)
        events = []
        try:
            for e in sweep(plan, axes, laser, rig.clock):
                events.append(e)
                if isinstance(e, ev.PointMeasured) and e.record["flags"] & FLAG_ANCHOR and e.record["run"] == 4:
                    rig.laser_server.set_beam_break(1, True)  # the beam goes as the probes begin
                elif isinstance(e, ev.Fault):
                    rig.laser_server.set_beam_break(1, False)  # and comes back while the sweep waits
        finally:
            laser.close()
            axes[1].close()
    faults = [e for e in events if isinstance(e, ev.Fault)]
    assert len(faults) == 1 and "reversal probe" in faults[0].message and not faults[0].gave_up
    points = np.concatenate([point_row(e.record) for e in events if isinstance(e, ev.PointMeasured)])
    probes = points[is_probe(points)]
    assert len(probes) == 6 and len(points) == plan.total_points  # nothing lost, nothing twice
    assert probes["flags"][0] & FLAG_RETRIED_BEAM and not np.any(probes["flags"][1:] & FLAG_RETRIED_BEAM)
    assert np.isfinite(probes["error_um"]).all()
    assert [e for e in events if isinstance(e, ev.SweepFinished)][0].outcome == "completed"


def test_diagnosis_sets_the_anchors_and_probes_aside_and_finds_the_speed_effect():
    """A recorded on-the-fly session diagnosed whole: its anchors and probes are readings beside
    the passes, not passes (as passes of one reading they were outliers, and their NaN speed hid
    the passes' speeds, so the leg-end lag was taken for backlash)."""
    from procedures.diagnosis import diagnose

    plan = onthefly_plan((1,), cycles=3, step_mm=2.0, reversal_probes=4)
    points, _, cfgs = run(plan, seed=0, legs=1)
    report = diagnose(points)
    assert any("14 on-the-fly anchor and reversal probe reading(s) set aside" in n for n in report["notes"])
    leg = report["legs"]["1"]
    assert leg["points"] == 3 * 2 * 91 and leg["passes"] == 6
    speed = [f for f in report["findings"] if f["effect"] == "speed"]
    assert speed, [f["effect"] for f in report["findings"]]
    # the leg end lags the encoder moving up by the plant's lag (0.12 ms)
    assert speed[0]["parameters"]["lag_up_ms"] == pytest.approx(cfgs[0].dynamic_lag_up_s * 1000, abs=0.03)


def test_the_probes_averaging_is_set_once_per_leg_and_the_anchors_get_theirs_back():
    """Each leg's probes read with the probe averaging, set once before its first probe; the next
    leg's passes (their anchors) read with the plan's again."""
    calls: list[float] = []

    class Logged(SerialInterferometer):
        def set_averaging(self, averaging_s: float) -> None:
            calls.append(averaging_s)
            super().set_averaging(averaging_s)

    plan = onthefly_plan((1, 2), cycles=2, step_mm=5.0, reversal_probes=3)
    _, events, _ = run(plan, seed=0, legs=2, laser_class=Logged)
    assert [e for e in events if isinstance(e, ev.SweepFinished)][0].outcome == "completed"
    a, p = plan.averaging_s, plan.probe_averaging_s
    assert calls == [a, p, a, p]


DIAGNOSED_SEEDS = (0, 1)
LAG_TOLERANCE_SE = 4.0  # seeds 0-3 measured: within 1.7 standard errors but seed 2's lags, 3.7 and 2.8


@pytest.fixture(scope="module")
def diagnosed():
    """seed -> (report, plant config): a bounded on-the-fly session (one leg, four cycles at 10 and
    20 mm/s, a capture every 1 mm, 12 probe pairs) on the simulated leg, diagnosed whole."""
    from procedures.diagnosis import diagnose

    plan = onthefly_plan((1,), cycles=4, step_mm=1.0, reversal_probes=12)
    out = {}
    for seed in DIAGNOSED_SEEDS:
        points, _, cfgs = run(plan, seed=seed, legs=1)
        out[seed] = diagnose(points), cfgs[0]
    return out


@pytest.mark.parametrize("seed", DIAGNOSED_SEEDS)
def test_diagnosis_fixes_the_reversal_from_the_probes_and_finds_the_plants_lags(diagnosed, seed):
    """With passes only, a constant reversal and the leg-end lag are nearly collinear (on this
    plan the passes alone gave no speed effect and a 3.9 um reversal on seed 0); the probes pin
    the reversal, and the lags come out within their stated standard errors of the plant's."""
    report, cfg = diagnosed[seed]
    found = {f["effect"]: f for f in report["findings"]}
    backlash, speed = found["backlash"], found["speed"]
    assert backlash["source"] == "reversal probes" and backlash["probe_pairs"] == 12
    assert any(n.startswith("leg 1: reversal") and "12 reversal probe pairs" in n for n in report["notes"])
    se = backlash["uncertainty"]["reversal_um"]
    assert 0.005 < se < 0.05
    assert abs(backlash["parameters"]["reversal_um"] - cfg.reversal_um) <= LAG_TOLERANCE_SE * se
    assert "backlash" in speed["added_to"]
    for key, true_s in (("lag_up_ms", cfg.dynamic_lag_up_s), ("lag_down_ms", cfg.dynamic_lag_down_s)):
        got, se = speed["parameters"][key], speed["uncertainty"][key]
        assert 0 < se < 0.01, (key, se)
        assert abs(got - true_s * 1000) <= LAG_TOLERANCE_SE * se, (key, got, se, true_s * 1000)
    cand = {c["effect"]: c for c in report["legs"]["1"]["candidates"]}
    assert cand["backlash"]["status"] == "named" and "probe" in cand["backlash"]["reason"]
