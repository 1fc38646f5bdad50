"""What a front end asks for, as a typed value: `PlanSpec`, and the one place that turns it
into a `SweepPlan` (`plan_from_spec`).

`station sweep` / `station run` fill a PlanSpec from their arguments, the terminal UI from its
form; both get the same plan, the same checks and the same messages (PlanError). Reading the
text of a field (legs '1-6', a number) stays with the front end; `parse_legs` is shared.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from procedures.vocabulary import PlanError
from procedures.acquisition.plans import (
    ONTHEFLY_OVERRUN_MM,
    PAPER_STEP_MM,
    SweepPlan,
    iso230_plan,
    onthefly_plan,
    paper_plan,
    targets_from_file,
)

PlanKind = Literal["iso230", "paper", "onthefly", "onthefly-adaptive"]
PLAN_KINDS: tuple[PlanKind, ...] = ("iso230", "paper", "onthefly", "onthefly-adaptive")
DEFAULT_CYCLES: dict[str, int] = {"iso230": 5, "paper": 6, "onthefly": 6, "onthefly-adaptive": 5}
"""ISO 230-2: 5 approaches; the paper: 6 sets; on the fly: 3 rounds of both speeds; adaptive: at
most 5 cycles (10, 20, 20, 10, 10 mm/s), 2 once the table's shape is known (its reversal: the
reversal probes; procedures/acquisition/adaptive.py, docs/onthefly.md)."""
ONTHEFLY_KINDS = ("onthefly", "onthefly-adaptive")
REVERSAL_PROBES = 24
"""Reversal probe pairs after each leg's on-the-fly passes (SweepPlan.reversal_probes): the
table's reversal to about 0.012 um (one standard error) on the simulated legs, whose passes
scatter by 0.04 um (docs/onthefly.md, "Reversal probes"); about 1.4 min per leg."""
ADAPTIVE_PROBE_COUNT = True
"""Plan onthefly-adaptive takes probe pairs until the reversal's standard error reaches
probe_rule.PROBE_TARGET_UM (12 to 48 pairs; procedures/acquisition/probe_rule.py); False: the fixed
REVERSAL_PROBES. Plan onthefly always takes the fixed count."""


def probe_count(kind: str) -> tuple[int, float]:
    """(reversal probe pairs, standard error target um) of an on-the-fly plan `kind`: with a target
    (> 0), the pairs are the most (SweepPlan.probe_target_um)."""
    if kind == "onthefly-adaptive" and ADAPTIVE_PROBE_COUNT:
        from procedures.acquisition.probe_rule import PROBE_MAX_PAIRS, PROBE_TARGET_UM

        return PROBE_MAX_PAIRS, PROBE_TARGET_UM
    return REVERSAL_PROBES, 0.0


@dataclass(frozen=True)
class PlanSpec:
    """A sweep plan as asked for.

    `kind`: "iso230" (the ISO 230-2 test cycle; with `targets_file`, the file's targets) or
    "paper" (361 fixed targets, -90..+90 mm at 0.5 mm). `cycles`: bidirectional cycles, None for
    the kind's standard (DEFAULT_CYCLES). "onthefly" / "onthefly-adaptive": passes at constant
    speed (10 and 20 mm/s) captured at every `step_mm` (default 0.5 mm) between `min_mm` and
    `max_mm`, with at least a 4 mm run-up (`overrun_mm`); the adaptive one stops a leg once its
    table stops improving, `cycles` being the most (docs/onthefly.md). Spacing of the iso230 targets: `step_mm` (uniform),
    `targets_file` (one number in mm per line, or a target_mm column), or neither: `n_targets`
    irregularly spaced targets (None: the ISO 230-2 minimum, at least 11) between `min_mm` and
    `max_mm`. The paper plan ignores the target fields and refuses a step or targets file.
    """

    legs: tuple[int, ...] = (1,)
    kind: PlanKind = "iso230"
    cycles: int | None = None
    n_targets: int | None = None
    step_mm: float | None = None
    targets_file: Path | None = None
    min_mm: float = -90.0
    max_mm: float = 90.0
    overrun_mm: float = 2.0
    dwell_s: float = 1.0
    averaging_s: float = 0.1

    def __post_init__(self) -> None:
        if self.kind not in PLAN_KINDS:
            raise PlanError(f"plan {self.kind!r}: choose one of {', '.join(PLAN_KINDS)}")
        if self.step_mm is not None and self.targets_file is not None:
            raise PlanError("give a uniform step or a targets file, not both")
        if self.kind == "paper" and (self.step_mm is not None or self.targets_file is not None):
            raise PlanError("plan paper has fixed targets (361 at 0.5 mm); drop the step/targets or use plan iso230")
        if self.kind in ONTHEFLY_KINDS and (self.targets_file is not None or self.n_targets is not None):
            raise PlanError(f"plan {self.kind} captures at evenly spaced positions: give a step (--step) rather than "
                            "a targets file or a number of targets")


def plan_from_spec(spec: PlanSpec, limits=None) -> SweepPlan:
    """The sweep plan `spec` asks for (PlanError with what to change when it is not a valid one).
    `limits` (a plan_size.PlanLimits, e.g. the config's [limits]; its `check(spec)`): the plan is sized first and
    refused beyond them, before anything is built (procedures/acquisition/plan_size.py)."""
    if limits is not None:
        limits.check(spec)
    cycles = DEFAULT_CYCLES[spec.kind] if spec.cycles is None else spec.cycles
    if spec.kind in ONTHEFLY_KINDS:
        pairs, target_um = probe_count(spec.kind)
        return onthefly_plan(spec.legs, cycles=cycles, step_mm=spec.step_mm or PAPER_STEP_MM, min_mm=spec.min_mm,
                             max_mm=spec.max_mm, overrun_mm=max(spec.overrun_mm, ONTHEFLY_OVERRUN_MM),
                             adaptive=spec.kind == "onthefly-adaptive", dwell_s=spec.dwell_s,
                             reversal_probes=pairs, probe_target_um=target_um)
    if spec.kind == "paper":
        return paper_plan(spec.legs, cycles=cycles, overrun_mm=spec.overrun_mm, dwell_s=spec.dwell_s,
                          averaging_s=spec.averaging_s)
    if spec.targets_file is not None:
        targets = targets_from_file(spec.targets_file)
        return SweepPlan("custom", targets, cycles, spec.legs, spec.overrun_mm, spec.dwell_s, spec.averaging_s)
    return iso230_plan(spec.legs, spec.min_mm, spec.max_mm, n_targets=spec.n_targets, step_mm=spec.step_mm,
                       cycles=cycles, overrun_mm=spec.overrun_mm, dwell_s=spec.dwell_s, averaging_s=spec.averaging_s)
