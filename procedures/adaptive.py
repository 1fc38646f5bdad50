"""Adaptive stopping of an on-the-fly calibration: measure rounds of passes only until the
table stops getting better.

After each round (every speed of the plan once, up and down) from `MIN_ROUNDS` on, the leg's
points so far are normalised to 20 degC (procedures.metrology.thermal, steel), made static
(procedures.fit.dynamic) and fitted with the default model, as `station fit` does; the
figure of merit is the cross-validated held-out RMS (whole cycles held out,
procedures.fit.crossval): what the table would leave on a pass it has not seen.

The held-out RMS is taken about each held-out pass's mean (`heldout_shape_um`): a pass's offset
is its zero reference, which no table and no number of passes changes.

Rule: stop when the last round improved the held-out RMS by less than `IMPROVEMENT` (5 %) of
the round before, i.e. `h_k > (1 - IMPROVEMENT) * h_(k-1)`, or when the held-out RMS is within
`NEAR_FLOOR` (1.05) times the within-pass scatter of the points so far (the measurement noise:
more passes can only bring the table nearer to a floor it has reached); else measure another
round, up to the plan's cycles.
Why 5 %: the held-out RMS of a model that has converged still wanders by a few percent from
round to round (it is itself an estimate from a few thousand points); a smaller threshold would
keep measuring on that wander.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from procedures.errors import InputError

IMPROVEMENT = 0.05
NEAR_FLOOR = 1.05
MIN_ROUNDS = 2


@dataclass
class AdaptiveRule:
    """The stopping rule for one leg; feed it the leg's points after each round (`after_round`)."""

    improvement: float = IMPROVEMENT
    near_floor: float = NEAR_FLOOR
    min_rounds: int = MIN_ROUNDS
    heldout_um: list[float] = field(default_factory=list)
    noise_floor_um: float | None = None

    def after_round(self, points: np.ndarray, leg: int) -> str | None:
        """The reason to stop after this round (None: measure another). `points`: this leg's
        points so far (POINT_DTYPE)."""
        h, floor = heldout_shape_um(points, leg)
        self.heldout_um.append(h)
        self.noise_floor_um = floor
        k = len(self.heldout_um)
        if not np.isfinite(h):
            return None if k < self.min_rounds else "no held-out figure (fewer than two cycles?); stopping"
        if k < self.min_rounds:
            return None
        if floor and h <= self.near_floor * floor:
            return (f"held-out RMS {h:.4f} um is within {self.near_floor:g} x the within-pass scatter {floor:.4f} um "
                    f"after {k} rounds")
        prev = self.heldout_um[-2]
        if np.isfinite(prev) and h > (1.0 - self.improvement) * prev:
            return (f"held-out RMS {h:.4f} um after round {k} improved by less than {100 * self.improvement:g} % "
                    f"on {prev:.4f} um after round {k - 1}")
        return None


def heldout_shape_um(points: np.ndarray, leg: int) -> tuple[float, float | None]:
    """(held-out RMS about each pass's mean, within-pass scatter) of `leg`'s points, um.

    The points are taken as `station fit` takes them: normalised to 20 degC (steel, the
    station's default material: the sweep does not hold the station config), the speed-dependent
    part removed, the default model with its options; each cycle is predicted by the model fitted
    on the others (procedures.fit.crossval). Each held-out pass's mean residual is removed: a
    pass offset (re-zeroing, the warm-up of a leg that a fast pass heats in seconds) is the zero
    reference of that pass, the same for any table, so more passes cannot reduce it; what they
    can reduce is the error of the table's shape, which this measures."""
    from procedures.fit.bidirectional import fit_bidirectional_leg
    from procedures.fit.crossval import cycle_folds
    from procedures.fit.data import split_legs
    from procedures.fit.dynamic import static_points
    from procedures.fit.noise import estimate_noise_floor
    from procedures.metrology.thermal import Material, normalise_points

    try:
        normalised = normalise_points(points, {leg: Material()}).points
        data = split_legs(static_points(normalised), source=f"leg {leg} so far")[leg]
        folds = cycle_folds(data)
        if folds is None:
            return float("nan"), None
        _, resid, _ = fit_bidirectional_leg(data, folds, where=f"leg {leg}")
    except (InputError, KeyError):
        return float("nan"), None
    if resid is None:
        return float("nan"), None
    runs, ids = np.unique(data.run, return_inverse=True)
    means = np.bincount(ids, weights=resid) / np.bincount(ids)
    shape = resid - means[ids]
    return float(np.sqrt(np.mean(shape ** 2))), estimate_noise_floor(data).within_pass_um
