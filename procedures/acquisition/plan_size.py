"""How big a plan is, before anything is built or connected: points, rig time, file size.

`plan_size(spec)` counts from a `PlanSpec` by arithmetic (no list of targets or points is
made, so a step of 0.0001 mm costs nothing to size); `check_plan_size(spec, limits)` refuses a
plan beyond `PlanLimits` (the config's [limits]) with a PlanError naming the figures and the
step that would fit. `station sweep` and the UI's Sweep page both call it before they build the
plan, so a plan that cannot finish is refused (or, in the UI, asked about) in well under a second.

The file size is the session writer's: a fixed part (root attributes, meta, the faults dataset)
plus one POINT_DTYPE row per point plus the plan's JSON (one number per target), measured from
files the writer made (tests/procedures/acquisition/test_plan_size.py checks it against a recording).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from procedures.vocabulary import PlanError
from procedures.acquisition.plan_spec import DEFAULT_CYCLES, ONTHEFLY_KINDS, PlanSpec, probe_count
from procedures.acquisition.plans import (
    ONTHEFLY_OVERRUN_MM,
    ONTHEFLY_SPEEDS_MM_S,
    PAPER_HALF_STROKE_MM,
    PAPER_STEP_MM,
    PROBE_MIN_PAIRS,
    SweepPlan,
    estimate_duration_s,
    targets_from_file,
)
from procedures.io.recording.schema import POINT_DTYPE

FILE_FIXED_BYTES = 24_000
"""A session file's size without points: the root attributes, /meta (config, devices), /faults."""
PLAN_JSON_BYTES_PER_TARGET = 24
"""The plan's JSON in /meta holds every target as text: about this many bytes each."""
STOP_AND_GO_SPEED_MM_S = 10.0
"""The move speed the rig-time estimate of a stop-and-go plan assumes: the drive profiles'
power-on profile velocity (drivers/modbus/profiles/*.toml)."""


@dataclass
class PlanLimits:
    """The largest plan a front end starts without being told otherwise ([limits] in the config).
    The defaults pass every standard plan (six legs of the paper's plan: 26 k points, about 8 h)
    with a wide margin, and stop a typing slip (a step of 0.0001 mm: 18 M points, years)."""

    max_points: int = 500_000
    max_rig_hours: float = 72.0

    def check(self, spec: PlanSpec) -> PlanSize:
        """`check_plan_size(spec, self)`: what `plan_from_spec` calls, so the plan's builder
        needs no import of its sizing (this module imports plan_spec)."""
        return check_plan_size(spec, self)


@dataclass(frozen=True)
class PlanSize:
    """`points` to measure, `targets` per pass, `rig_s` the estimated time on the rig (s),
    `file_bytes` the session file's estimated size. `probe_pairs`: the reversal probe pairs per leg
    counted; with an adaptive count (`probes_adaptive`) the most, so points, rig time and size are
    upper bounds (the sweep stops a leg's probes once its reversal is known; as the adaptive plan's
    passes are counted at the plan's most cycles)."""

    points: int
    targets: int
    rig_s: float
    file_bytes: int
    probe_pairs: int = 0
    probes_adaptive: bool = False

    @property
    def rig_hours(self) -> float:
        return self.rig_s / 3600.0

    def describe(self) -> str:
        """e.g. "18 000 010 points, about 5 500 h on the rig, a 2.1 GB session file"."""
        most = "at most " if self.probes_adaptive else ""
        return (f"{most}{_group(self.points)} points, {most or 'about '}{fmt_hours(self.rig_hours)} on the rig, "
                f"a {fmt_bytes(self.file_bytes)} session file")


def _group(n: int) -> str:
    return f"{n:,}".replace(",", " ")


def fmt_hours(hours: float) -> str:
    if hours < 1.0:
        return f"{hours * 60:.0f} min"
    if hours < 48.0:
        return f"{hours:.1f} h"
    return f"{_group(round(hours))} h ({hours / 24:,.0f} days)".replace(",", " ")


def fmt_bytes(n: float) -> str:
    for unit, size in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.1f} {unit}"
    return f"{n:.0f} B"


def _uniform_count(min_mm: float, max_mm: float, step_mm: float) -> int:
    """How many targets `uniform_targets(min_mm, max_mm, step_mm)` makes (PlanError as it does)."""
    if not math.isfinite(step_mm) or step_mm <= 0:
        raise PlanError(f"step must be > 0 mm, got {step_mm}")
    if not (math.isfinite(min_mm) and math.isfinite(max_mm)) or max_mm <= min_mm:
        raise PlanError(f"target range is empty: {min_mm} .. {max_mm} mm")
    return int(math.floor((max_mm - min_mm) / step_mm + 1e-9)) + 1


def _targets(spec: PlanSpec) -> tuple[int, float]:
    """(targets per pass, the span they cover, mm) of `spec`, without building them."""
    if spec.kind == "paper":
        return _uniform(-PAPER_HALF_STROKE_MM, PAPER_HALF_STROKE_MM, PAPER_STEP_MM)
    if spec.kind in ONTHEFLY_KINDS:
        return _uniform(spec.min_mm, spec.max_mm, spec.step_mm or PAPER_STEP_MM)
    if spec.targets_file is not None:  # a file is as big as it is: read it
        targets = targets_from_file(spec.targets_file)
        return len(targets), targets[-1] - targets[0]
    if spec.step_mm is not None:
        return _uniform(spec.min_mm, spec.max_mm, spec.step_mm)
    length_m = (spec.max_mm - spec.min_mm) / 1000.0
    minimum = max(5, int(math.ceil(5 * length_m)) + 1) if math.isfinite(length_m) else 5
    return (spec.n_targets or max(minimum, 11)), spec.max_mm - spec.min_mm  # irregular: the ends kept


def _uniform(min_mm: float, max_mm: float, step_mm: float) -> tuple[int, float]:
    n = _uniform_count(min_mm, max_mm, step_mm)
    return n, (n - 1) * step_mm


def plan_size(spec: PlanSpec) -> PlanSize:
    """The size of the plan `spec` asks for (PlanError for a step, range or count that no plan has)."""
    n, span_mm = _targets(spec)
    cycles = DEFAULT_CYCLES[spec.kind] if spec.cycles is None else spec.cycles
    if cycles < 1:
        raise PlanError(f"cycles must be >= 1, got {cycles}")
    onthefly = spec.kind in ONTHEFLY_KINDS
    per_pass = n + (1 if onthefly else 0)  # on the fly: each pass's anchor
    probes, target_um = probe_count(spec.kind) if onthefly else (0, 0.0)  # adaptive: the most pairs
    points = len(spec.legs) * (cycles * 2 * per_pass + 2 * probes)
    overrun = max(spec.overrun_mm, ONTHEFLY_OVERRUN_MM) if onthefly else spec.overrun_mm
    rig_s = estimate_duration_s(span_mm + 2 * overrun, n, cycles, len(spec.legs), spec.dwell_s,
                                1.0 if onthefly else spec.averaging_s,
                                ONTHEFLY_SPEEDS_MM_S if onthefly else (), STOP_AND_GO_SPEED_MM_S, probes,
                                min(PROBE_MIN_PAIRS, probes) if target_um > 0 else 0)
    file_bytes = FILE_FIXED_BYTES + POINT_DTYPE.itemsize * points + PLAN_JSON_BYTES_PER_TARGET * n
    return PlanSize(points, n, rig_s, file_bytes, probes, target_um > 0)


def check_plan_size(spec: PlanSpec, limits: PlanLimits) -> PlanSize:
    """`plan_size(spec)` when within `limits`; else PlanError with the figures, the limit passed
    and the step that would fit (or what else to change), and the config key that sets the limit."""
    size = plan_size(spec)
    over = []
    if size.points > limits.max_points:
        over.append(f"more than [limits] max_points = {_group(limits.max_points)}")
    if size.rig_hours > limits.max_rig_hours:
        over.append(f"longer than [limits] max_rig_hours = {limits.max_rig_hours:g}")
    if not over:
        return size
    hint = _what_fits(spec, limits, size)
    raise PlanError(f"the plan has {size.describe()}: {' and '.join(over)}; {hint} (or raise the limit in the "
                    "config's [limits] section)")


def _what_fits(spec: PlanSpec, limits: PlanLimits, size: PlanSize) -> str:
    """The sentence saying what to change: the finest step that fits, else fewer cycles or legs."""
    if spec.kind != "paper" and spec.targets_file is None and (spec.step_mm is not None or spec.kind in ONTHEFLY_KINDS):
        step = _finest_fitting_step(spec, limits)
        if step is not None:
            return f"a step of {step:g} mm or more fits"
    return "use fewer targets, cycles or legs"


def _finest_fitting_step(spec: PlanSpec, limits: PlanLimits) -> float | None:
    """The finest round step (1, 2, 5 × 10^k mm) whose plan fits `limits`; None if none does."""
    from dataclasses import replace

    for exponent in range(-4, 3):
        for mantissa in (1, 2, 5):
            step = mantissa * 10.0 ** exponent
            if step >= spec.max_mm - spec.min_mm:
                return None
            size = plan_size(replace(spec, step_mm=float(f"{step:g}")))
            if size.points <= limits.max_points and size.rig_hours <= limits.max_rig_hours:
                return float(f"{step:g}")
    return None


def build_abortable(spec: PlanSpec, control) -> SweepPlan | None:
    """`plan_from_spec(spec)` built on a thread of its own while the caller waits for it or for
    an abort of `control` (a RunControl), whichever comes first: None when aborted, at once,
    even while a huge plan is still being built (its thread finishes and the plan is dropped)."""
    import threading

    from procedures.acquisition.plan_spec import plan_from_spec

    box: dict = {}

    def build() -> None:
        try:
            box["plan"] = plan_from_spec(spec)
        except BaseException as exc:  # handed to the caller
            box["error"] = exc

    builder = threading.Thread(target=build, name="plan-builder", daemon=True)
    builder.start()
    while builder.is_alive():
        if control.wait_aborted(0.05):
            return None
    if "error" in box:
        raise box["error"]
    return None if control.aborted else box["plan"]
