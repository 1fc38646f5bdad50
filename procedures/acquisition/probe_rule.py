"""How many reversal probe pairs a leg needs: pairs until the reversal's standard error reaches a
target (SweepPlan.probe_target_um), at least `PROBE_MIN_PAIRS`, at most the plan's
`reversal_probes` (docs/onthefly.md, "Reversal probes").

Why the target, `PROBE_TARGET_UM` = 0.015 um: half of a reversal error shows in every verified
point, so a table whose reversal is off by `r` verifies at about
rho_0 x sqrt(1 + (r / 2 / floor)^2), rho_0 being what a perfect table reads (up to 1.02 with the
20-cycle verification; the simulated legs' floor is about 0.06 um). For every leg at or below 1.1:
r / 2 <= floor x sqrt((1.1 / 1.02)^2 - 1) = 0.40 x 0.06 = 0.024 um, less the table's shape error
(0.006 um RMS, in quadrature: 0.0235 um), so r <= 0.047 um. A leg's reversal error is a draw of
its standard error; to keep it within that at three standard errors (0.27 % of legs beyond),
the standard error must reach 0.047 / 3 = 0.0157 um: 0.015 um. A leg whose probes scatter like
the simulated legs' (pass offsets 0.04 um: the pairs' differences 0.06 um) needs about 16 pairs
for it, one with half the offsets the fewest, one with twice the offsets the most.

The standard error is `station fit`'s (procedures/fit/reversal_probes.py): the probes' residuals
against the fit of the leg's passes (normalised to 20 degC with the leg's material, made static,
the default model), the scatter of the pairs' differences / sqrt(pairs); so the figure the sweep
stops on is the one `station fit` prints. Deterministic: the same readings give the same count
(a replay stops where its recording did).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np

from procedures.acquisition.plans import PROBE_MIN_PAIRS

if TYPE_CHECKING:  # names for the annotations only: the fit loads when a rule first shapes
    from procedures.fit.model import LegFit
    from procedures.metrology.thermal import Material

PROBE_TARGET_UM = 0.015
PROBE_MAX_PAIRS = 48
"""The most pairs with a target: twice the fixed count (24), about 1.4 min more than it; a leg
whose probes scatter more than about 0.1 um stops here short of the target (and says so)."""


def stop_reason(pairs: int, stderr_um: float | None, target_um: float, min_pairs: int, max_pairs: int) -> str | None:
    """Why a leg's probes stop after `pairs` pairs whose reversal has standard error `stderr_um`
    (None: not yet known), or None to take another pair."""
    if pairs >= max_pairs:
        se = f"{stderr_um:.4f} um" if stderr_um is not None else "unknown"
        return f"the most pairs ({max_pairs}) taken; standard error {se} (target {target_um:g} um)"
    if pairs < min_pairs or stderr_um is None or stderr_um > target_um:
        return None
    return f"standard error {stderr_um:.4f} um within the target {target_um:g} um after {pairs} pairs"


@dataclass
class ProbeRule:
    """The stopping rule of one leg's probes. `shape(passes)` once, from the leg's passes (POINT_DTYPE),
    then `after_pair(probes)` after each pair (all the leg's probe points so far)."""

    target_um: float
    max_pairs: int
    min_pairs: int = PROBE_MIN_PAIRS
    material: Material | None = None  # the leg's material (None: the default), as AdaptiveRule's
    fit: LegFit | None = None  # the passes' leg fit (None: no shape: every pair is taken)
    passes: np.ndarray | None = field(default=None, repr=False)
    pairs: int = 0
    stderr_um: float | None = None

    def shape(self, passes: np.ndarray | None, leg: int) -> None:
        """Fit the leg's `passes` as `station fit` does (the default model), for the probes' residuals."""
        from procedures.vocabulary import InputError
        from procedures.fit import fit
        from procedures.metrology.thermal import Material, normalise_points

        self.passes = passes
        if passes is None or not len(passes):
            self.fit = None
            return
        try:
            normalised = normalise_points(passes, {leg: self.material or Material()}).points
            self.fit = fit(normalised, "default", legs=[leg]).legs[leg]
        except (InputError, KeyError):
            self.fit = None

    def after_pair(self, probes: np.ndarray, leg: int) -> str | None:
        """The reason to stop after the pair just read (None: take another). Without a fit of the
        passes (a sweep resumed among the probes: its passes are in the file, not in this sweep),
        every pair up to the most."""
        from procedures.fit.reversal_probes import reversal_of_residuals
        from procedures.metrology.thermal import Material, normalise_points

        self.pairs = int(min(np.sum(probes["direction"] > 0), np.sum(probes["direction"] < 0)))
        self.stderr_um = None
        if self.fit is not None and self.pairs:
            both = np.concatenate([self.passes, probes])
            normalised = normalise_points(both, {leg: self.material or Material()}).points[len(self.passes):]
            d = np.asarray(normalised["direction"])
            resid = np.asarray(normalised["error_um"], dtype=float) - self.fit.predict_um(
                np.asarray(normalised["target_mm"], dtype=float), d)
            found = reversal_of_residuals(resid, d, np.asarray(normalised["run"]))
            self.stderr_um = found[1] if found is not None else None
        return stop_reason(self.pairs, self.stderr_um, self.target_um, self.min_pairs, self.max_pairs)


def recorded_stop(plan: Mapping[str, Any] | None, pairs: int, stderr_um: float | None) -> str | None:
    """Why a recorded leg's probes stopped, from its session's `plan` (the stored dict) and the
    fit's pairs and standard error (`station fit`'s probe line); None for a fixed count. The fit's
    figure is the one the sweep stopped on (module docstring) unless the sweep was resumed among
    the leg's probes."""
    target = float(plan.get("probe_target_um", 0.0) or 0.0) if isinstance(plan, dict) else 0.0
    if target <= 0:
        return None
    most = int(plan.get("reversal_probes", PROBE_MAX_PAIRS))
    reason = stop_reason(pairs, stderr_um, target, min(PROBE_MIN_PAIRS, most), most)
    return reason or f"stopped short of the target {target:g} um (the sweep ended before)"
