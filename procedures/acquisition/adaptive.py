"""Adaptive stopping of an on-the-fly calibration: measure rounds of passes only until the
table stops getting better.

After each round (every speed of the plan once, up and down) from `MIN_ROUNDS` on, the leg's
points so far are normalised to 20 degC (procedures.metrology.thermal, steel), made static
(procedures.fit.dynamic) and fitted with the default model, as `station fit` does; the
figure of merit is the cross-validated held-out RMS (whole cycles held out,
procedures.fit.crossval): what the table would leave on a pass it has not seen.

The held-out RMS is taken about each held-out pass's mean (`heldout_shape_um`): a pass's offset
is its zero reference, which no table and no number of passes changes.

Rule: stop when both
- the table's shape has converged: the held-out RMS is within `NEAR_FLOOR` (1.05) times the
  within-pass scatter (the measurement noise: more passes can only bring the table nearer to a
  floor it has reached), or the last round improved it by less than `IMPROVEMENT` (5 %) of the
  round before, `h_k > (1 - IMPROVEMENT) * h_(k-1)`; and
- its reversal (mean down minus mean up, the constant per direction that pass offsets decide) is
  known to within `REVERSAL_SE` (0.7) times the within-pass scatter: the standard error of the
  per-cycle reversals. Half a reversal error shows in every verified point; a verification's floor
  is about 1.5 x the within-pass scatter (the pass offsets added), so this keeps the reversal's
  share of its residual to about a quarter of the floor. The within-pass scatter, not the noise
  floor, is the yardstick because it does not depend on the material: a wrong expansion
  coefficient or fixed point (a station config that does not describe the leg) inflates the pass
  offsets and so the noise floor, not the within-pass scatter;
else measure another round, up to the plan's cycles.

Material: the leg's own (`AdaptiveRule.material`: its expansion coefficient and fixed point,
station.services.config.StationConfig.material_of, which the session records as
station_config.leg_materials), given by the job that composes the sweep (station/services/jobs.py
run_sweep, and the recorded ones on replay); none given = the default material (steel, fixed
at 0 mm), as `station fit` takes a session that recorded none.
Why 5 %: the held-out RMS of a model that has converged still wanders by a few percent from
round to round (it is itself an estimate from a few thousand points); a smaller threshold would
keep measuring on that wander.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from procedures.engine.errors import InputError

IMPROVEMENT = 0.05
NEAR_FLOOR = 1.05
REVERSAL_SE = 0.7
MIN_ROUNDS = 2


@dataclass
class AdaptiveRule:
    """The stopping rule for one leg; feed it the leg's points after each round (`after_round`)."""

    improvement: float = IMPROVEMENT
    near_floor: float = NEAR_FLOOR
    reversal_se: float = REVERSAL_SE
    min_rounds: int = MIN_ROUNDS
    # the leg's material (procedures.metrology.thermal.Material or anything with its fields:
    # expansion_um_m_k, fixed_point_mm); None = the default (steel, fixed at 0 mm)
    material: Any = None
    heldout_um: list[float] = field(default_factory=list)
    noise_floor_um: float | None = None

    def after_round(self, points: np.ndarray, leg: int) -> str | None:
        """The reason to stop after this round (None: measure another). `points`: this leg's
        points so far (POINT_DTYPE)."""
        f = leg_figures(points, leg, self.material)
        h = f.heldout_shape_um
        self.heldout_um.append(h)
        self.noise_floor_um = f.noise_floor_um
        k = len(self.heldout_um)
        if not np.isfinite(h):
            return None if k < self.min_rounds else "no held-out figure (fewer than two cycles?); stopping"
        if k < self.min_rounds:
            return None
        prev = self.heldout_um[-2]
        if f.within_pass_um and h <= self.near_floor * f.within_pass_um:
            shape = f"held-out RMS {h:.4f} um within {self.near_floor:g} x the within-pass scatter {f.within_pass_um:.4f} um"
        elif np.isfinite(prev) and h > (1.0 - self.improvement) * prev:
            shape = f"held-out RMS {h:.4f} um improved by less than {100 * self.improvement:g} % on {prev:.4f} um"
        else:
            return None
        if f.reversal_se_um is None or not f.within_pass_um or f.reversal_se_um > self.reversal_se * f.within_pass_um:
            return None
        return (f"after round {k}: {shape}; reversal known to {f.reversal_se_um:.4f} um (standard error), within "
                f"{self.reversal_se:g} x the within-pass scatter")


@dataclass(frozen=True)
class LegFigures:
    """What the rule looks at, um: `heldout_shape_um` (held-out RMS about each held-out pass's
    mean), `within_pass_um` and `noise_floor_um` (procedures.fit.noise), `reversal_se_um` (the
    standard error of the leg's reversal: the scatter of the per-cycle reversals / sqrt(cycles))."""

    heldout_shape_um: float
    within_pass_um: float | None
    noise_floor_um: float | None
    reversal_se_um: float | None


def leg_figures(points: np.ndarray, leg: int, material: Any = None) -> LegFigures:
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
        data = split_legs(static_points(normalised), source=f"leg {leg} so far")[leg]
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
    reversals = []
    for c in np.unique(data.cycle):
        up = (data.cycle == c) & (data.direction > 0)
        down = (data.cycle == c) & (data.direction < 0)
        if np.any(up) and np.any(down):
            reversals.append(float(np.mean(data.error_um[down]) - np.mean(data.error_um[up])))
    se = float(np.std(reversals, ddof=1) / np.sqrt(len(reversals))) if len(reversals) >= 2 else None
    nf = estimate_noise_floor(data)
    return LegFigures(float(np.sqrt(np.mean(shape ** 2))), nf.within_pass_um, nf.noise_floor_um, se)
