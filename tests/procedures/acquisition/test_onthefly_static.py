"""Static from dynamic (docs/onthefly.md): the table made from on-the-fly passes equals the
stop-and-go table of the same simulated leg within the noise floor; the speed-dependent error is
found per direction; adaptive stopping stops a leg and says why. Sweeps run over the real
protocols (Modbus TCP on 127.0.0.1, the interferometer on a pty)."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from drivers.interferometer.client import SerialInterferometer
from drivers.modbus.client import connect_axes
from drivers.plant.leg import default_leg_configs
from drivers.sim.rig import SimRig
from procedures.engine import events as ev
from procedures.vocabulary import InputError, PlanError
from procedures.acquisition.adaptive import MIN_CYCLES
from procedures.fit import fit
from procedures.fit.dynamic import speed_coefficients, static_points
from procedures.fit.noise import noise_floor
from procedures.acquisition.plans import SweepPlan, onthefly_plan, paper_plan
from procedures.io.recording.schema import FLAG_ANCHOR
from procedures.io.recording.writer import point_row
from procedures.acquisition.sweep import sweep
from procedures.compensation.table import make_table

logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def run(plan: SweepPlan, seed: int, legs: int = 1):
    """(points, events, rig time s, plant configs) of `plan` on a fresh simulated rig."""
    cfgs = [c.with_leg_motion() for c in default_leg_configs(seed, legs)]
    with SimRig(time_scale=0.0, seed=seed, legs=legs, configs=cfgs) as rig:
        axes = connect_axes(rig.drive_url, list(plan.legs), clock=rig.clock)
        laser = SerialInterferometer(rig.laser_port)
        try:
            t0 = rig.clock.now()
            events = list(sweep(plan, axes, laser, rig.clock))
            rig_s = rig.clock.now() - t0
        finally:
            laser.close()
            for a in axes.values():
                a.close()
    rows = [point_row(e.record) for e in events if isinstance(e, ev.PointMeasured)]
    return np.concatenate(rows), events, rig_s, cfgs


@pytest.mark.parametrize("seed", [0, 4])
def test_onthefly_table_equals_the_stop_and_go_table_within_the_noise_floor(seed):
    paper, _, paper_s, cfgs = run(paper_plan((1,), cycles=4), seed)
    otf, _, otf_s, _ = run(onthefly_plan((1,), cycles=4), seed)
    assert otf_s < paper_s / 15  # minutes, not hours
    floor = noise_floor(paper["target_mm"], paper["direction"], paper["run"], paper["error_um"]).noise_floor_um
    t_otf = make_table(fit(otf), step_mm=1.0).legs[1]
    t_sg = make_table(fit(paper), step_mm=1.0).legs[1]
    diff = np.r_[np.subtract(t_otf.error_fwd_um, t_sg.error_fwd_um), np.subtract(t_otf.error_rev_um, t_sg.error_rev_um)]
    # about the mean: a table's constant is the zero reference (verify judges the residual about its mean)
    assert float(np.sqrt(np.mean((diff - diff.mean()) ** 2))) <= floor
    # the dynamic part is large against that: a table from the raw on-the-fly readings differs by more
    raw = otf[(otf["flags"] & FLAG_ANCHOR) == 0].copy()
    raw["speed_mm_s"] = np.nan  # taken as stop-and-go readings: nothing removed
    t_raw = make_table(fit(raw), step_mm=1.0).legs[1]
    raw_rev = np.subtract(t_raw.error_rev_um, t_raw.error_fwd_um) - np.subtract(t_sg.error_rev_um, t_sg.error_fwd_um)
    assert abs(float(np.mean(raw_rev))) > 3 * floor


def test_speed_coefficients_are_found_per_direction_and_one_speed_is_refused():
    otf, _, _, cfgs = run(onthefly_plan((1,), cycles=4, step_mm=2.0), seed=2)
    k = speed_coefficients(otf)
    cfg = cfgs[0]
    # the leg end lags the encoder: -lag * v * 1000 um per mm/s, per direction
    assert k[(1, 1)].um_per_mm_s == pytest.approx(-cfg.dynamic_lag_up_s * 1000.0, rel=0.03)
    assert k[(1, -1)].um_per_mm_s == pytest.approx(-cfg.dynamic_lag_down_s * 1000.0, rel=0.03)
    assert k[(1, 1)].anchored and k[(1, -1)].anchored  # from the anchors, free of pass offsets
    fixed = static_points(otf)
    moving = otf[(otf["flags"] & FLAG_ANCHOR) == 0]  # the anchors are used, then dropped
    assert np.all(fixed["error_um"] != moving["error_um"]) and np.array_equal(fixed["target_mm"], moving["target_mm"])
    # without anchors (data from elsewhere) pass means are used, and still find it roughly
    k2 = speed_coefficients(moving)
    assert not k2[(1, 1)].anchored
    assert k2[(1, 1)].um_per_mm_s == pytest.approx(-cfg.dynamic_lag_up_s * 1000.0, rel=0.25)
    one_speed = moving[np.abs(np.abs(moving["speed_mm_s"]) - 10.0) < 1.0]
    with pytest.raises(InputError, match="one speed only"):
        speed_coefficients(one_speed, source="s.h5")


def test_adaptive_plan_stops_a_leg_and_says_why():
    plan = onthefly_plan((1,), cycles=12, step_mm=1.0, adaptive=True)
    points, events, _, _ = run(plan, seed=1)
    stops = [e for e in events if isinstance(e, ev.PassesStopped)]
    assert len(stops) == 1 and stops[0].leg == 1
    s = stops[0]
    assert len(s.heldout_um) == s.cycles and s.reason  # the rule looked after every cycle
    assert "held-out RMS" in s.reason or "most cycles" in s.reason
    # what was measured and what was skipped add up to the plan
    assert len(points) + s.skipped_points == plan.total_points
    assert s.cycles * 2 * plan.points_per_pass == len(points)
    if s.skipped_points:
        # a direction pair at a time, never before two pairs at each speed
        assert MIN_CYCLES <= s.cycles < plan.cycles
    done = [e for e in events if isinstance(e, ev.SweepFinished)][0]
    assert done.outcome == "completed" and done.points == len(points)


def test_onthefly_plan_checks_and_round_trip():
    plan = onthefly_plan((1, 2), cycles=4, adaptive=True)
    again = SweepPlan.from_dict(plan.to_dict())
    assert again == plan and again.onthefly and again.adaptive
    assert [plan.speed_of_run(r) for r in range(1, 9)] == [10, 10, 20, 20, 20, 20, 10, 10]
    assert "speeds_mm_s" not in paper_plan((1,)).to_dict()  # stop-and-go plans stored as before
    with pytest.raises(PlanError, match="two different speeds"):
        onthefly_plan((1,), speeds_mm_s=(10.0, 10.0))
    with pytest.raises(PlanError, match="evenly spaced"):
        SweepPlan("onthefly", (0.0, 1.0, 3.0), 2, speeds_mm_s=(5.0, 10.0))
    with pytest.raises(PlanError, match="on-the-fly"):
        SweepPlan("iso230-2", (0.0, 1.0), 2, adaptive=True)


def test_an_onthefly_verification_is_judged_on_its_static_points():
    """A verification measured on the fly carries the speed-dependent error (tens of um) that no
    static table removes: `station verify` takes its points static, as `station fit` does, and
    drops the anchors; its noise floor is then the one of a stop-and-go judgement."""
    from procedures.compensation.verify import verify
    from procedures.fit.dynamic import static_points

    points, _, _, _ = run(onthefly_plan((1,), cycles=4, step_mm=2.0), seed=2)
    judged = verify(points)[1].after
    anchors = int(np.count_nonzero(points["flags"] & FLAG_ANCHOR))
    assert anchors and judged.n_points == len(static_points(points, "the test")) == len(points) - anchors
    # the same points taken as if at rest (no speed recorded): the floor holds the speed-dependent
    # error (passes at two speeds differ at every target by the lag's difference), which would
    # hide a table's residual under it
    at_rest = points[(points["flags"] & FLAG_ANCHOR) == 0].copy()
    at_rest["speed_mm_s"] = np.nan
    raw_floor = verify(at_rest)[1].after.noise_floor_um
    assert judged.noise_floor_um < 0.5 * raw_floor, (judged.noise_floor_um, raw_floor)

