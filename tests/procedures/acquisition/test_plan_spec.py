"""PlanSpec -> SweepPlan: the one conversion both front ends use, with its checks and messages."""

from dataclasses import FrozenInstanceError
from pathlib import Path

import pytest

from procedures.vocabulary import PlanError
from procedures.acquisition.plan_spec import DEFAULT_CYCLES, PLAN_KINDS, PlanSpec, plan_from_spec
from procedures.acquisition.plans import SweepPlan, iso230_plan, paper_plan


def test_the_default_spec_is_the_standard_iso230_test_cycle_on_leg_1():
    plan = plan_from_spec(PlanSpec())
    assert plan == iso230_plan((1,))
    assert plan.kind == "iso230-2" and plan.cycles == DEFAULT_CYCLES["iso230"] == 5
    assert len(plan.targets_mm) == 11 and plan.targets_mm[0] == -90.0 and plan.targets_mm[-1] == 90.0


def test_every_field_reaches_the_iso230_plan():
    spec = PlanSpec(legs=(2, 4), cycles=3, n_targets=7, min_mm=-40.0, max_mm=60.0, overrun_mm=1.5,
                    dwell_s=0.25, averaging_s=0.05)
    assert plan_from_spec(spec) == iso230_plan((2, 4), -40.0, 60.0, n_targets=7, cycles=3, overrun_mm=1.5,
                                               dwell_s=0.25, averaging_s=0.05)


def test_a_uniform_step_gives_uniform_targets_and_the_lead_note():
    plan = plan_from_spec(PlanSpec(step_mm=10.0))
    assert plan.targets_mm == tuple(float(x) for x in range(-90, 91, 10))
    assert any("multiple of the 5 mm screw lead" in n for n in plan.notes)


def test_the_paper_plan_has_its_fixed_targets_and_six_cycles():
    plan = plan_from_spec(PlanSpec(legs=(1, 2, 3, 4, 5, 6), kind="paper"))
    assert plan == paper_plan()
    assert plan_from_spec(PlanSpec(kind="paper", cycles=2, n_targets=5, min_mm=-10.0)).cycles == 2  # ISO fields ignored


def test_targets_from_a_file_make_a_custom_plan(tmp_path):
    f = tmp_path / "t.txt"
    f.write_text("10\n-10\n0\n")
    plan = plan_from_spec(PlanSpec(legs=(3,), targets_file=f, dwell_s=0.5))
    assert plan == SweepPlan("custom", (-10.0, 0.0, 10.0), 5, (3,), 2.0, 0.5, 0.1)


def test_a_missing_targets_file_is_named(tmp_path):
    with pytest.raises(FileNotFoundError):
        plan_from_spec(PlanSpec(targets_file=Path(tmp_path / "none.txt")))


@pytest.mark.parametrize("spec, message", [
    (dict(kind="paper", step_mm=1.0), "plan paper has fixed targets (361 at 0.5 mm); drop the step/targets or use plan iso230"),
    (dict(kind="paper", targets_file=Path("t.txt")), "plan paper has fixed targets"),
    (dict(step_mm=1.0, targets_file=Path("t.txt")), "give a uniform step or a targets file, not both"),
    (dict(kind="zigzag"), "plan 'zigzag': choose one of iso230, paper"),
])
def test_contradictory_specs_are_refused_when_made(spec, message):
    with pytest.raises(PlanError) as info:
        PlanSpec(**spec)
    assert message in str(info.value)


@pytest.mark.parametrize("spec, message", [
    (dict(cycles=0), "cycles must be >= 1, got 0"),  # 0 is not "the default": only None is
    (dict(kind="paper", cycles=0), "cycles must be >= 1, got 0"),
    (dict(step_mm=0.0), "step must be > 0 mm, got 0.0"),
    (dict(step_mm=5.0, min_mm=10.0, max_mm=-10.0), "target range is empty: 10.0 .. -10.0 mm"),
    (dict(legs=(1, 1)), "legs must be distinct numbers >= 1, got [1, 1]"),
    (dict(dwell_s=-1.0), "overrun_mm, dwell_s and averaging_s must be >= 0"),
])
def test_invalid_plans_are_refused_with_what_to_change(spec, message):
    with pytest.raises(PlanError) as info:
        plan_from_spec(PlanSpec(**spec))
    assert message in str(info.value)


def test_a_spec_is_a_frozen_value():
    spec = PlanSpec()
    with pytest.raises(FrozenInstanceError):
        spec.cycles = 3  # type: ignore[misc]
    assert spec == PlanSpec(legs=(1,), kind="iso230") and hash(spec) == hash(PlanSpec())
    assert set(PLAN_KINDS) == set(DEFAULT_CYCLES)
