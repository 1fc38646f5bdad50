import numpy as np
import pytest

from procedures.vocabulary import PlanError
from procedures.acquisition.plans import (
    SweepPlan, iso230_plan, paper_plan, parse_legs, targets_from_file, uniform_targets,
)


def test_paper_plan_has_361_targets_six_cycles_both_directions():
    plan = paper_plan()
    assert len(plan.targets_mm) == 361
    assert plan.targets_mm[0] == -90.0 and plan.targets_mm[-1] == 90.0
    assert np.allclose(np.diff(plan.targets_mm), 0.5)
    assert plan.total_points == 6 * 361 * 12 == 25992
    pts = plan.points()
    assert [p.index for p in pts] == list(range(len(pts)))


def test_points_alternate_direction_per_run_and_cover_every_target():
    plan = SweepPlan("custom", (-10.0, 0.0, 10.0), cycles=2, legs=(2, 5))
    pts = plan.points()
    for leg in (2, 5):
        lp = [p for p in pts if p.leg == leg]
        assert [p.run for p in lp] == [1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4]
        assert [p.direction for p in lp][:6] == [1, 1, 1, -1, -1, -1]
        assert [p.target_mm for p in lp][:6] == [-10, 0, 10, 10, 0, -10]
    # approach positions lie beyond the pass start, on the pass's side
    p_up, p_down = pts[0], pts[3]
    assert p_up.approach_mm(2.0) == -12.0 and p_down.approach_mm(2.0) == 12.0


def test_plan_refused_beyond_soft_limits_with_the_offending_position():
    plan = SweepPlan("custom", (-90.0, 90.0), cycles=1, overrun_mm=2.0)
    plan.validate_limits(-95, 95)
    with pytest.raises(PlanError, match=r"92\.000 mm .*above the soft limit 91\.000"):
        plan.validate_limits(-95, 91)
    with pytest.raises(PlanError, match="below the soft limit"):
        plan.validate_limits(-91, 95, leg=3)


def test_iso230_plan_irregular_spacing_and_minimums():
    plan = iso230_plan(legs=(1,), n_targets=11, seed=3)
    d = np.diff(plan.targets_mm)
    assert len(plan.targets_mm) == 11 and np.all(d > 0)
    assert d.std() > 0.05 * d.mean()  # really irregular
    assert plan.targets_mm[0] == -90 and plan.targets_mm[-1] == 90
    assert plan.cycles == 5
    few = iso230_plan(n_targets=3, cycles=2)
    assert any("at least" in n for n in few.notes) and any("5 approaches" in n for n in few.notes)


def test_uniform_spacing_at_multiple_of_lead_is_warned():
    plan = iso230_plan(step_mm=10.0, lead_mm=5.0)
    assert any("multiple of the 5 mm screw lead" in n for n in plan.notes)
    assert not iso230_plan(step_mm=7.3, lead_mm=5.0).notes


def test_plan_round_trips_through_dict():
    plan = iso230_plan(legs=(1, 3), n_targets=7, cycles=3)
    assert SweepPlan.from_dict(plan.to_dict()) == plan
    with pytest.raises(PlanError, match="malformed"):
        SweepPlan.from_dict({"kind": "x"})


def test_bad_plans_refused():
    with pytest.raises(PlanError, match="strictly increasing"):
        SweepPlan("custom", (0.0, 0.0, 1.0), 1)
    with pytest.raises(PlanError, match="cycles"):
        SweepPlan("custom", (0.0, 1.0), 0)
    with pytest.raises(PlanError, match="step"):
        uniform_targets(0, 1, 0)


def test_parse_legs():
    assert parse_legs("1-6") == (1, 2, 3, 4, 5, 6)
    assert parse_legs("1,3, 5") == (1, 3, 5)
    with pytest.raises(PlanError, match="1 to 6"):
        parse_legs("0-7")
    with pytest.raises(PlanError, match="range like"):
        parse_legs("a")


def test_targets_from_file(tmp_path):
    f = tmp_path / "t.txt"
    f.write_text("# targets\n10\n-5.5\n\n0\n")
    assert targets_from_file(f) == (-5.5, 0.0, 10.0)
    c = tmp_path / "t.csv"
    c.write_text("name,target_mm\na,1\nb,2\n")
    assert targets_from_file(c) == (1.0, 2.0)
    bad = tmp_path / "bad.txt"
    bad.write_text("1\nabc\n")
    with pytest.raises(PlanError, match=r"line 2: target 'abc'"):
        targets_from_file(bad)
