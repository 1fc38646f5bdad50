"""Adaptive stopping of an on-the-fly calibration: measure passes, a direction pair at a time,
only while the leg's table is not yet known.

After each cycle (an up and a down pass at one speed; the speeds alternate cycle by cycle) from
`MIN_CYCLES` on (two cycles at each speed), the leg's points so far are normalised to 20 degC
(procedures.metrology.thermal, the leg's material), made static (procedures.fit.dynamic) and
fitted with the default model, as `station fit` does; the figure of merit is the
cross-validated held-out RMS (whole cycles held out, procedures.fit.crossval): what the table
would leave on a pass it has not seen.

The held-out RMS is taken about each held-out pass's mean (`heldout_shape_um`): a pass's offset
is its zero reference, which no table and no number of passes changes.

Rule: stop when both
- the table's shape has converged: the held-out RMS is within `NEAR_FLOOR` (1.05) times the
  within-pass scatter (the measurement noise: more passes can only bring the table nearer to a
  floor it has reached), or the last cycle improved it by less than `IMPROVEMENT` (5 %) of the
  one before, `h_k > (1 - IMPROVEMENT) * h_(k-1)`; and
- its reversal (mean down minus mean up, the constant per direction that pass offsets decide) is
  known to within `REVERSAL_SE` (0.7) times the within-pass scatter: the standard error of the
  reversal estimated across passes, from the scatter of the per-cycle reversals (each the down
  pass minus the up pass of one cycle: passes next to each other share the slow drift of the pass
  offsets, which are far larger than the within-pass scatter on the fly, so a pair, not a pass,
  is the unit) about the mean of the cycles at the same speed (`reversal_se_um`: a difference
  between the speeds is the dynamic model's, which more passes do not change). Half a reversal error shows in every verified point; a verification's floor
  is about 1.5 x the within-pass scatter (the pass offsets added), so this keeps the reversal's
  share of its residual to about a quarter of the floor. The within-pass scatter, not the noise
  floor, is the yardstick because it does not depend on the material: a wrong expansion
  coefficient or fixed point (a station config that does not describe the leg) inflates the pass
  offsets and so the noise floor, not the within-pass scatter;
else measure another cycle, up to the plan's cycles (`DEFAULT_CYCLES["onthefly-adaptive"]`, 5:
a leg whose reversal is not known after five is not better known at six or eight, measured on the
simulated rig: the verification ratios of seed 0's legs with tables from the first 2, 3, 4, 5, 6
and 8 cycles of one session scatter by as much as they change, and the legs of seed 1 that the
rule ran to six cycles verified as with the fixed six-cycle plan, failing legs included).

Why a cycle at a time, not a round (both speeds): a leg that is known after its fourth cycle
stops there, and one that is not gets one more pair, not two; the rig time goes where the
reversal is uncertain (docs/onthefly.md, "Adaptive stopping", for the measurement behind it).

Material: the leg's own (`AdaptiveRule.material`: its expansion coefficient and fixed point,
station.services.config.StationConfig.material_of, which the session records as
station_config.leg_materials), given by the job that composes the sweep (station/services/jobs.py
run_sweep, and the recorded ones on replay); none given = the default material (steel, fixed
at 0 mm), as `station fit` takes a session that recorded none.
Why 5 %: the held-out RMS of a model that has converged still wanders by a few percent from
cycle to cycle (it is itself an estimate from a few thousand points); a smaller threshold would
keep measuring on that wander.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from procedures.vocabulary import InputError

if TYPE_CHECKING:  # names for the annotations only (the figures load their modules when first used)
    from procedures.acquisition.plans import SweepPlan
    from procedures.metrology.thermal import Material

IMPROVEMENT = 0.05
NEAR_FLOOR = 1.05
REVERSAL_SE = 0.7
MIN_CYCLES = 4  # two pairs at each of the two speeds: the first with three degrees of freedom for the reversal's scatter
MIN_CYCLES_WITH_PROBES = 2  # one pair at each speed: the speed coefficients; the probes know the reversal


@dataclass
class AdaptiveRule:
    """The stopping rule for one leg; feed it the leg's points after each cycle (`after_cycle`)."""

    improvement: float = IMPROVEMENT
    near_floor: float = NEAR_FLOOR
    reversal_se: float | None = REVERSAL_SE  # None: the reversal is not the passes' to know (probes)
    min_cycles: int = MIN_CYCLES
    material: Material | None = None  # the leg's material; None = the default (steel, fixed at 0 mm)
    heldout_um: list[float] = field(default_factory=list)
    noise_floor_um: float | None = None

    @classmethod
    def for_plan(cls, plan: SweepPlan, material: Material | None = None) -> "AdaptiveRule":
        """The rule for a leg of `plan`: with reversal probes (SweepPlan.reversal_probes) the
        reversal is theirs to know (procedures/fit/reversal_probes.py), so the passes stop on
        their shape alone (`reversal_se` None) from the second cycle on (one at each speed)."""
        if plan.reversal_probes:
            return cls(material=material, reversal_se=None, min_cycles=MIN_CYCLES_WITH_PROBES)
        return cls(material=material)

    def after_cycle(self, points: np.ndarray, leg: int) -> str | None:
        """The reason to stop after this cycle (None: measure another). `points`: this leg's
        points so far (POINT_DTYPE), whole cycles; call it after every cycle."""
        f = leg_figures(points, leg, self.material)
        h = f.heldout_shape_um
        self.heldout_um.append(h)
        self.noise_floor_um = f.noise_floor_um
        k = len(self.heldout_um)
        if k < self.min_cycles:
            return None
        if not np.isfinite(h):
            return "no held-out figure (fewer than two cycles?); stopping"
        prev = self.heldout_um[-2]
        if f.within_pass_um and h <= self.near_floor * f.within_pass_um:
            shape = f"held-out RMS {h:.4f} um within {self.near_floor:g} x the within-pass scatter {f.within_pass_um:.4f} um"
        elif np.isfinite(prev) and h > (1.0 - self.improvement) * prev:
            shape = f"held-out RMS {h:.4f} um improved by less than {100 * self.improvement:g} % on {prev:.4f} um"
        else:
            return None
        if self.reversal_se is None:
            return f"after cycle {k}: {shape}; the reversal is left to the reversal probes"
        if f.reversal_se_um is None or not f.within_pass_um or f.reversal_se_um > self.reversal_se * f.within_pass_um:
            return None
        return (f"after cycle {k}: {shape}; reversal known to {f.reversal_se_um:.4f} um (standard error), within "
                f"{self.reversal_se:g} x the within-pass scatter")


@dataclass(frozen=True)
class LegFigures:
    """What the rule looks at, um: `heldout_shape_um` (held-out RMS about each held-out pass's
    mean), `within_pass_um` and `noise_floor_um` (procedures.fit.noise), `reversal_se_um` (the
    standard error of the leg's reversal across passes: `reversal_se_um()`)."""

    heldout_shape_um: float
    within_pass_um: float | None
    noise_floor_um: float | None
    reversal_se_um: float | None


def leg_figures(points: np.ndarray, leg: int, material: Material | None = None) -> LegFigures:
    """The rule's figures for `leg`'s points so far (module docstring).

    The points are taken as `station fit` takes them: normalised to 20 degC with the leg's
    `material` (None: the default, steel fixed at 0 mm), the speed-dependent
    part removed, the default model with its options; each cycle is predicted by the model fitted
    on the others (procedures.fit.crossval). Each held-out pass's mean residual is removed: a
    pass offset (re-zeroing, the warm-up of a leg that a fast pass heats in seconds) is the zero
    reference of that pass, the same for any table; what more passes do for the offsets is
    measured by the reversal's standard error instead (the table's one constant that the offsets
    of up and down passes decide)."""
    from procedures.fit.bidirectional import fit_bidirectional_leg
    from procedures.fit.crossval import cycle_folds
    from procedures.fit.data import split_legs
    from procedures.fit.dynamic import static_points
    from procedures.fit.noise import estimate_noise_floor
    from procedures.metrology.thermal import Material, normalise_points

    nothing = LegFigures(float("nan"), None, None, None)
    try:
        normalised = normalise_points(points, {leg: material if material is not None else Material()}).points
        static = static_points(normalised)
        data = split_legs(static, source=f"leg {leg} so far")[leg]
        folds = cycle_folds(data)
        if folds is None:
            return nothing
        _, resid, _ = fit_bidirectional_leg(data, folds, where=f"leg {leg}")
    except (InputError, KeyError):
        return nothing
    if resid is None:
        return nothing
    runs, ids = np.unique(data.run, return_inverse=True)
    means = np.bincount(ids, weights=resid) / np.bincount(ids)
    shape = resid - means[ids]
    nf = estimate_noise_floor(data)
    return LegFigures(float(np.sqrt(np.mean(shape ** 2))), nf.within_pass_um, nf.noise_floor_um,
                      reversal_se_um(data, static, leg))


def reversal_se_um(data, static: np.ndarray, leg: int) -> float | None:
    """The standard error of the leg's reversal estimated across passes, um: from the scatter of
    the per-cycle reversals (the down pass minus the up pass of a cycle, static) about the mean of
    the cycles at the same speed, pooled over the speeds, / sqrt(cycles). Not about the mean of
    all cycles: a difference between the speeds' reversals is the dynamic model's (the speed
    coefficient, procedures.fit.dynamic), the same after any number of passes, so it is no reason
    to measure more. None before two cycles at one speed."""
    mine = static[static["leg"] == leg]
    speed_of_run = {}
    for r in np.unique(mine["run"]):
        v = np.abs(mine["speed_mm_s"][mine["run"] == r])
        v = v[np.isfinite(v)]
        speed_of_run[int(r)] = round(float(np.mean(v)), 1) if v.size else 0.0  # 0: stop-and-go
    by_speed: dict[float, list[float]] = {}
    for c in np.unique(data.cycle):
        up = (data.cycle == c) & (data.direction > 0)
        down = (data.cycle == c) & (data.direction < 0)
        if np.any(up) and np.any(down):
            speed = speed_of_run.get(int(data.run[up][0]), 0.0)
            by_speed.setdefault(speed, []).append(float(np.mean(data.error_um[down]) - np.mean(data.error_um[up])))
    n = sum(len(v) for v in by_speed.values())
    dof = n - len(by_speed)
    if dof < 1:
        return None
    ss = sum(float(np.sum((np.array(v) - np.mean(v)) ** 2)) for v in by_speed.values())
    return float(np.sqrt(ss / dof / n))
