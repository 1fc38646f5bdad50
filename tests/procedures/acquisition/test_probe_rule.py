"""The adaptive reversal probe count (procedures/acquisition/probe_rule.py, docs/onthefly.md
"Reversal probes"): the stopping rule (its minimum, maximum and target, deterministic), the
plan's layout of the pairs in blocks, and on the simulated rig (real Modbus TCP and pty) a leg
with larger pass offsets taking more pairs than a quiet one."""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np
import pytest

from drivers.interferometer.client import SerialInterferometer
from drivers.modbus.client import connect_axes
from drivers.plant.leg import default_leg_configs
from drivers.sim.rig import SimRig
from procedures.acquisition.plan_size import plan_size
from procedures.acquisition.plan_spec import PlanSpec, plan_from_spec
from procedures.acquisition.plans import PROBE_MIN_PAIRS, SweepPlan, onthefly_plan
from procedures.acquisition.probe_rule import (
    PROBE_MAX_PAIRS,
    PROBE_TARGET_UM,
    ProbeRule,
    recorded_stop,
    stop_reason,
)
from procedures.acquisition.sweep import sweep
from procedures.engine import events as ev
from procedures.vocabulary import PlanError
from procedures.fit import fit
from procedures.fit.reversal_probes import is_probe
from procedures.io.recording.schema import POINT_DTYPE
from procedures.io.recording.writer import point_row
from procedures.metrology.thermal import Material, normalise_points

logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


# -- the rule --------------------------------------------------------------------------------

def test_stop_reason_keeps_the_minimum_the_target_and_the_maximum():
    assert stop_reason(11, 0.001, 0.015, 12, 48) is None  # below the minimum: however small its error
    assert stop_reason(12, None, 0.015, 12, 48) is None  # no standard error yet
    assert stop_reason(12, 0.0151, 0.015, 12, 48) is None  # above the target
    reason = stop_reason(12, 0.0149, 0.015, 12, 48)
    assert reason is not None and "0.0149" in reason and "target 0.015" in reason and "12 pairs" in reason
    most = stop_reason(48, 0.03, 0.015, 12, 48)  # the most: stops above the target, and says so
    assert most is not None and "most pairs (48)" in most and "0.0300" in most


class _Flat:
    """A leg fit predicting 0 um everywhere: the probes' readings are their residuals."""

    def predict_um(self, x, d):
        return np.zeros(np.shape(x))


def _probes(diffs_um: np.ndarray) -> np.ndarray:
    """Probe points whose pairs (up at 0 um, down at `diffs_um`) differ by `diffs_um`."""
    n = diffs_um.size
    p = np.zeros(2 * n, dtype=POINT_DTYPE)
    p["leg"], p["run"] = 1, 5 + np.arange(2 * n)
    p["direction"] = np.tile([1, -1], n)
    p["target_mm"] = np.repeat(np.linspace(-80, 80, n), 2) - np.tile([0.0, 1.0], n)
    p["error_um"][1::2] = diffs_um
    p["material_temp_c"] = 20.0
    return p


def _count(diffs_um: np.ndarray, target_um: float = PROBE_TARGET_UM) -> tuple[int, str, float | None]:
    """Pairs after which the rule stops on these pair differences, its reason and standard error."""
    empty = np.zeros(0, dtype=POINT_DTYPE)
    rule = ProbeRule(target_um, max_pairs=PROBE_MAX_PAIRS, fit=_Flat(), passes=empty)
    for k in range(1, diffs_um.size + 1):
        reason = rule.after_pair(_probes(diffs_um[:k]), 1)
        if reason is not None:
            return k, reason, rule.stderr_um
    raise AssertionError("the rule never stopped")


def test_the_rule_takes_pairs_until_the_standard_error_reaches_the_target():
    rng = np.random.default_rng(3)
    quiet, usual, loud = (rng.normal(0.5, s, PROBE_MAX_PAIRS) for s in (0.02, 0.06, 0.2))
    n_quiet, reason, se = _count(quiet)
    assert n_quiet == PROBE_MIN_PAIRS and se <= PROBE_TARGET_UM and "within the target" in reason
    n_usual, reason, se = _count(usual)
    assert PROBE_MIN_PAIRS < n_usual < PROBE_MAX_PAIRS and se <= PROBE_TARGET_UM
    # the standard error just before the stop was above the target: the first pair that reaches it
    k = n_usual - 1
    assert np.std(usual[:k], ddof=1) / np.sqrt(k) > PROBE_TARGET_UM
    n_loud, reason, se = _count(loud)
    assert n_loud == PROBE_MAX_PAIRS and se > PROBE_TARGET_UM and "most pairs" in reason
    assert _count(usual)[0] == n_usual  # a fresh rule on the same readings: the same count


def test_without_the_passes_fit_every_pair_is_taken():
    """A sweep resumed among a leg's probes has no passes to take the residuals against."""
    rule = ProbeRule(PROBE_TARGET_UM, max_pairs=20)
    rule.shape(None, 1)
    diffs = np.full(20, 0.5)
    assert all(rule.after_pair(_probes(diffs[:k]), 1) is None for k in range(1, 20))
    assert "most pairs (20)" in rule.after_pair(_probes(diffs), 1)


def test_recorded_stop_reads_the_session_plan():
    plan = onthefly_plan((1,), cycles=2, reversal_probes=48, probe_target_um=0.015).to_dict()
    assert "within the target" in recorded_stop(plan, 14, 0.0142)
    assert "most pairs (48)" in recorded_stop(plan, 48, 0.02)
    assert "short of the target" in recorded_stop(plan, 13, 0.02)  # an interrupted session
    assert recorded_stop(onthefly_plan((1,), cycles=2, reversal_probes=24).to_dict(), 24, 0.01) is None


# -- the plan ------------------------------------------------------------------------------

def _arrivals(plan: SweepPlan) -> list[tuple[float, int, int]]:
    """(target, direction arrived in, probe direction) of each probe of one leg, following the
    sweep's moves (onthefly._probe): from the reading before, via `probe_via_mm` if any."""
    out = []
    here = plan.anchor_mm(-1)
    for run in range(2 * plan.cycles + 1, 2 * plan.cycles + 2 * plan.reversal_probes + 1):
        k, down = divmod(run - 2 * plan.cycles - 1, 2)
        target = plan.probe_up_mm(k) - (plan.probe_gap_mm if down else 0.0)
        assert plan.before_probe_mm(run) == pytest.approx(here)
        via = plan.probe_via_mm(run)
        if via is not None:
            here = via
        out.append((target, int(np.sign(target - here)), -1 if down else 1))
        here = target
    return out


def test_an_adaptive_count_lays_its_pairs_in_blocks_over_the_whole_stroke():
    plan = plan_from_spec(PlanSpec(legs=(1,), kind="onthefly-adaptive"))
    assert (plan.reversal_probes, plan.probe_target_um, plan.probe_block) == (PROBE_MAX_PAIRS, PROBE_TARGET_UM,
                                                                            PROBE_MIN_PAIRS)
    ups = np.array([plan.probe_up_mm(k) for k in range(plan.reversal_probes)])
    lo, hi = plan.targets_mm[0] + plan.probe_gap_mm, plan.targets_mm[-1]
    assert np.all((ups >= lo) & (ups <= hi)) and np.unique(np.round(ups, 6)).size == ups.size
    for b in range(plan.reversal_probes // PROBE_MIN_PAIRS):  # each block spans the stroke, climbing or descending
        block = ups[b * PROBE_MIN_PAIRS:(b + 1) * PROBE_MIN_PAIRS]
        assert np.ptp(block) > 0.8 * (hi - lo)
        assert np.all(np.diff(block) > 0) if b % 2 == 0 else np.all(np.diff(block) < 0)
    # every probe is reached in its own direction, after a reversal (the reading before it on its far side)
    assert all(arrived == d for _, arrived, d in _arrivals(plan))
    assert SweepPlan.from_dict(plan.to_dict()) == plan


def test_a_fixed_count_keeps_its_one_climb_and_its_stored_form():
    plan = plan_from_spec(PlanSpec(legs=(1,), kind="onthefly"))
    assert plan.probe_target_um == 0 and plan.probe_block == plan.reversal_probes == 24
    assert "probe_target_um" not in plan.to_dict()
    n = plan.reversal_probes
    lo, hi = plan.targets_mm[0] + plan.probe_gap_mm, plan.targets_mm[-1]
    assert [plan.probe_up_mm(k) for k in range(n)] == pytest.approx([lo + (hi - lo) * (k + 0.5) / n for k in range(n)])
    assert all(plan.probe_via_mm(r) is None for r in range(2 * plan.cycles + 1, 2 * plan.cycles + 2 * n + 1))
    with pytest.raises(PlanError, match="standard error"):
        replace(plan, probe_target_um=-0.01)


def test_the_plan_size_says_it_counts_the_most_pairs():
    adaptive = plan_size(PlanSpec(legs=(1,), kind="onthefly-adaptive"))
    fixed = plan_size(PlanSpec(legs=(1,), kind="onthefly"))
    assert adaptive.probes_adaptive and adaptive.probe_pairs == PROBE_MAX_PAIRS
    assert adaptive.describe().startswith("at most ") and fixed.describe()[0].isdigit()
    plan = plan_from_spec(PlanSpec(legs=(1,), kind="onthefly-adaptive"))
    assert adaptive.points == plan.total_points


# -- on the simulated rig --------------------------------------------------------------------

OFFSETS_UM = {1: 0.01, 2: 0.08}
"""Leg 1 quiet, leg 2 with twice the simulated legs' usual pass offsets (0.04 um)."""


@pytest.fixture(scope="module")
def two_legs():
    """Two cycles and up to 48 probe pairs on a quiet and a loud leg (real Modbus TCP and pty)."""
    plan = onthefly_plan((1, 2), cycles=2, step_mm=2.0, reversal_probes=PROBE_MAX_PAIRS,
                         probe_target_um=PROBE_TARGET_UM)
    cfgs = [replace(c.with_leg_motion(), run_offset_um=OFFSETS_UM.get(i + 1, 0.04))
            for i, c in enumerate(default_leg_configs(2, 2))]
    mats = {leg: Material(cfgs[leg - 1].expansion_ppm_per_k, 1.0, cfgs[leg - 1].bearing_mm) for leg in (1, 2)}
    with SimRig(time_scale=0.0, seed=2, legs=2, configs=cfgs) as rig:
        axes = connect_axes(rig.drive_url, [1, 2], clock=rig.clock)
        laser = SerialInterferometer(rig.laser_port)
        try:
            events = list(sweep(plan, axes, laser, rig.clock, materials=mats))
        finally:
            laser.close()
            for a in axes.values():
                a.close()
    points = np.concatenate([point_row(e.record) for e in events if isinstance(e, ev.PointMeasured)])
    return plan, points, events, mats


def test_a_leg_with_larger_pass_offsets_takes_more_probe_pairs(two_legs):
    plan, points, events, mats = two_legs
    stops = {e.leg: e for e in events if isinstance(e, ev.ProbesStopped)}
    assert sorted(stops) == [1, 2]
    quiet, loud = stops[1], stops[2]
    assert PROBE_MIN_PAIRS <= quiet.pairs < loud.pairs <= PROBE_MAX_PAIRS, (quiet, loud)
    assert quiet.stderr_um <= PROBE_TARGET_UM
    for s in (quiet, loud):  # what was recorded is what the event says; the rest was not measured
        mine = points[(points["leg"] == s.leg) & is_probe(points)]
        assert mine.size == 2 * s.pairs and s.skipped_points == 2 * (PROBE_MAX_PAIRS - s.pairs)
    finished = [e for e in events if isinstance(e, ev.SweepFinished)][-1]
    assert finished.points == points.size == plan.total_points - quiet.skipped_points - loud.skipped_points
    # `station fit` finds the standard error the sweep stopped on (the same residuals)
    model = fit(normalise_points(points, mats).points)
    for s in (quiet, loud):
        got = model.legs[s.leg].selection["reversal_probes"]
        assert got["pairs"] == s.pairs
        assert got["stderr_um"] == pytest.approx(s.stderr_um, rel=0.05), (got, s)
