"""`station sweep` / `station run` build their plan through PlanSpec (procedures.acquisition.plan_spec)."""

from argparse import Namespace

import pytest

from procedures.acquisition.plan_spec import PlanSpec, plan_from_spec
from procedures.acquisition.plans import iso230_plan
from station.cli import build_parser, main
from station.commands import run as run_command
from station.commands.sweep import build_plan, plan_spec


def sweep_args(*argv: str) -> Namespace:
    return build_parser("sweep").parse_args(["sweep", "--sim", *argv])


def test_the_sweep_arguments_become_a_plan_spec(tmp_path):
    assert plan_spec(sweep_args()) == PlanSpec()
    targets = tmp_path / "t.txt"
    targets.write_text("-10\n0\n10\n")  # --targets names an existing text file (station/values.py)
    args = sweep_args("--legs", "1-3", "--plan", "iso230", "--cycles", "2", "--targets", str(targets),
                      "--dwell", "0.5", "--averaging", "0.2", "--overrun", "1")
    assert plan_spec(args) == PlanSpec(legs=(1, 2, 3), cycles=2, targets_file=targets, dwell_s=0.5,
                                       averaging_s=0.2, overrun_mm=1.0)
    args = sweep_args("--legs", "2", "--step", "7.5", "--min-mm", "-30", "--max-mm", "30", "--n-targets", "9")
    assert plan_spec(args) == PlanSpec(legs=(2,), step_mm=7.5, min_mm=-30.0, max_mm=30.0, n_targets=9)
    assert plan_spec(sweep_args("--plan", "paper", "--legs", "1-6")) == PlanSpec(legs=(1, 2, 3, 4, 5, 6), kind="paper")
    assert build_plan(args) == plan_from_spec(plan_spec(args))


@pytest.mark.parametrize("argv, message", [
    (["--plan", "paper", "--step", "1"], "plan paper has fixed targets (361 at 0.5 mm); drop the step/targets or use plan iso230"),
    (["--cycles", "0"], "argument --cycles: '0' is outside 1 .. 1000; give a number of cycles as a whole number "
                        "(1 .. 1000), e.g. 5; see `station sweep --help`"),
    (["--legs", "7"], "argument --legs: '7': leg numbers run from 1 to 6; give a leg number 1..6, a range (1-6), a "
                      "list (1,4); see `station sweep --help`"),
])
def test_a_bad_plan_is_one_line_and_exit_2_before_anything_is_written(argv, message, tmp_path, capsys):
    out = tmp_path / "o.h5"
    assert main(["sweep", "--sim", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err == f"station sweep: error: {message}\n"
    assert not out.exists()


def test_station_run_builds_the_iso230_plan_through_the_spec(monkeypatch):
    seen = {}

    def fake_open_rig(cfg, legs, time_scale):  # stop before the rig: only the plan is checked here
        seen["legs"] = legs
        raise RuntimeError("stop")

    # where `station run` imports them from when it runs (inside run(), so --help loads neither)
    monkeypatch.setattr("station.services.wiring.open_rig", fake_open_rig)
    monkeypatch.setattr("procedures.acquisition.plan_spec.plan_from_spec",
                        lambda spec, limits: seen.setdefault("plan", plan_from_spec(spec, limits)))
    with pytest.raises(RuntimeError, match="stop"):
        run_command.run(Namespace(legs="2,4", cycles=3, out=None, time_scale=0.0))
    assert seen["plan"] == iso230_plan((2, 4), cycles=3) and seen["legs"] == (2, 4)


def test_a_plan_that_cannot_finish_is_refused_before_connecting_naming_the_step_that_fits(tmp_path, capsys):
    """`station sweep --sim --step 0.0001`: 18 M points. Refused from its size alone (one line,
    exit 2), before the rig is opened ("rig:" is printed once it is) and before the file exists.
    Time and memory of the refusal: bench/bench_plan_refusal.py."""
    out = tmp_path / "huge.h5"
    assert main(["sweep", "--sim", "--step", "0.0001", "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert "rig:" not in captured.out and not out.exists()
    (line,) = captured.err.splitlines()
    assert "18 000 010 points" in line and "a step of 0.01 mm or more fits" in line and "[limits]" in line
    # the step it names passes
    assert main(["sweep", "--sim", "--step", "0.01", "--cycles", "1", "--legs", "1", "--min-mm", "0", "--max-mm",
                 "0.05", "--dwell", "0", "--out", str(out)]) == 0
