"""Sizing a plan before it is built (procedures/acquisition/plan_size.py): the counts agree with the plans
the builders make, and a plan beyond the limits is refused with the step that fits, without building
anything. (The file size against files a sweep on the simulated rig writes, and the limits of the
station config: tests/station/services/.)"""

from __future__ import annotations

import time
import tracemalloc
from dataclasses import replace

import pytest

from procedures.vocabulary import PlanError
from procedures.acquisition.plan_size import PlanLimits, check_plan_size, plan_size
from procedures.acquisition.plan_spec import PlanSpec, plan_from_spec

SPECS = [
    PlanSpec(),
    PlanSpec(legs=(1, 2, 3, 4, 5, 6), kind="paper"),
    PlanSpec(legs=(2, 3), step_mm=7.5, cycles=2, min_mm=-40.0, max_mm=60.0),
    PlanSpec(n_targets=23, cycles=3),
    PlanSpec(legs=(1, 4), kind="onthefly", step_mm=2.0),
    PlanSpec(kind="onthefly-adaptive", cycles=4, min_mm=-20.0, max_mm=20.0, step_mm=0.25),
]


@pytest.mark.parametrize("spec", SPECS, ids=lambda s: f"{s.kind}-{s.step_mm}-{len(s.legs)}legs")
def test_the_size_is_the_built_plans_points_and_duration(spec):
    size = plan_size(spec)
    plan = plan_from_spec(spec)
    assert size.points == plan.total_points == len(plan.points())
    assert size.targets == len(plan.targets_mm)
    assert size.rig_s == pytest.approx(plan.estimated_duration_s(10.0), rel=1e-9)


def test_every_standard_plan_passes_the_default_limits():
    for kind in ("iso230", "paper", "onthefly", "onthefly-adaptive"):
        check_plan_size(PlanSpec(legs=(1, 2, 3, 4, 5, 6), kind=kind), PlanLimits())


def test_a_huge_step_is_refused_with_the_figures_and_a_step_that_fits_without_building_it():
    spec = PlanSpec(step_mm=0.0001)
    tracemalloc.start()
    t0 = time.perf_counter()
    with pytest.raises(PlanError) as err:
        plan_from_spec(spec, PlanLimits())
    elapsed = time.perf_counter() - t0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    text = str(err.value)
    assert "18 000 010 points" in text and "max_points" in text and "GB session file" in text
    assert elapsed < 0.5 and peak < 5e6, (elapsed, peak)  # nothing listed: no 1.8 M targets in memory
    step = float(text.split("a step of ")[1].split(" mm")[0])
    fits = replace(spec, step_mm=step)
    check_plan_size(fits, PlanLimits())
    finer = replace(spec, step_mm=step / 2)
    with pytest.raises(PlanError):
        check_plan_size(finer, PlanLimits())


def test_an_abort_ends_the_building_of_a_huge_plan_at_once():
    """build_abortable: the plan of 18 M points is being built (on its own thread) when the
    abort comes; the caller has None within a tenth of a second, not the plan seconds later."""
    import threading

    from procedures.engine.control import RunControl
    from procedures.acquisition.plan_size import build_abortable

    spec = PlanSpec(step_mm=0.0001)
    control = RunControl()
    threading.Timer(0.02, control.abort).start()
    t0 = time.perf_counter()
    assert build_abortable(spec, control) is None
    assert time.perf_counter() - t0 < 0.2
    built = build_abortable(PlanSpec(step_mm=10.0), RunControl())
    assert built == plan_from_spec(PlanSpec(step_mm=10.0))
