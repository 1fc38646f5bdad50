"""Adaptive stopping of an on-the-fly calibration: measure rounds of passes only until the
table stops getting better.

After each round (every speed of the plan once, up and down) from `MIN_ROUNDS` on, the leg's
points so far are made static (procedures.fit.dynamic) and fitted with the default model; the
figure of merit is the cross-validated held-out RMS (whole cycles held out,
procedures.fit.crossval): what the table would leave on a pass it has not seen.

Rule: stop when the last round improved the held-out RMS by less than `IMPROVEMENT` (5 %) of
the round before, i.e. `h_k > (1 - IMPROVEMENT) * h_(k-1)`, or when the held-out RMS is within
`NEAR_FLOOR` (1.05) times the noise floor of the points so far (more passes can only bring the
table nearer to a floor it has reached); else measure another round, up to the plan's cycles.
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
        from procedures.fit.data import split_legs
        from procedures.fit.dynamic import static_points
        from procedures.fit.fitting import fit_leg
        from procedures.fit.noise import estimate_noise_floor

        try:
            data = split_legs(static_points(points), source=f"leg {leg} so far")[leg]
            stats = fit_leg(data).stats
        except (InputError, KeyError) as exc:
            self.heldout_um.append(float("nan"))
            return None if len(self.heldout_um) < self.min_rounds else f"no held-out figure ({exc}); stopping"
        h = stats.heldout_rms_um
        self.noise_floor_um = estimate_noise_floor(data).noise_floor_um
        self.heldout_um.append(float(h) if h is not None else float("nan"))
        k = len(self.heldout_um)
        if k < self.min_rounds or h is None or not np.isfinite(h):
            return None
        floor = self.noise_floor_um
        if floor and h <= self.near_floor * floor:
            return (f"held-out RMS {h:.4f} um is within {self.near_floor:g} x the noise floor {floor:.4f} um "
                    f"after {k} rounds")
        prev = self.heldout_um[-2]
        if np.isfinite(prev) and h > (1.0 - self.improvement) * prev:
            return (f"held-out RMS {h:.4f} um after round {k} improved by less than {100 * self.improvement:g} % "
                    f"on {prev:.4f} um after round {k - 1}")
        return None
