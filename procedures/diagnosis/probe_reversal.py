"""The reversal of an on-the-fly leg from its reversal probes, fixed before the diagnosis fits
the other effects (docs/diagnosis.md, "On-the-fly sessions").

With passes only, a constant reversal (`backlash`: a constant per direction) and the leg-end lag
(`speed`: lag x speed, the speed constant within a pass and only two speeds per direction) are
nearly collinear: the selection can name the speed effect alone and let its lags take the
reversal (measured on the simulated leg: lag_down 0.130 +/- 0.012 ms against the plant's 0.08).
The reversal probes (FLAG_PROBE: stop-and-go readings at rest, each right after a reversal)
measure the reversal independently of the speed. As `station fit` does
(procedures/fit/reversal_probes.py), each probe's residual is its reading minus the passes'
position-only shape at its position (the passes' mean error at each target, both directions
alike, interpolated: the twin fitted on the raw passes, which still hold the lag, the reversal
and the heating, missed the leg's slope over the probes' 1 mm gap on two of four simulated legs;
an external twin's prediction in the probe's direction), and the reversal is the mean downward residual minus the
mean upward one, its standard error from the pairs. The diagnosis then takes that reversal out of
the passes, does not try `backlash` again, and reports it as the backlash finding with the
probes' standard error; the other effects' uncertainties include what the reversal's standard
error does to them.

Sign convention as everywhere: error = measured minus commanded, um; reversal = down minus up.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import stdtr

from procedures.diagnosis.legdata import LegData
from procedures.diagnosis.twin import Twin
from procedures.fit.reversal_probes import is_probe, reversal_of_residuals

MIN_PAIRS = 2  # fewer: no standard error from the pairs, nothing to fix the reversal with


@dataclass(frozen=True)
class FixedReversal:
    """A leg's reversal from its probes: `reversal_um` (down minus up), `stderr_um`, `pairs`,
    `p_value` (two-sided, t with pairs - 1 degrees of freedom: is it nonzero)."""

    reversal_um: float
    stderr_um: float
    pairs: int
    p_value: float

    def note(self, leg: int) -> str:
        return (f"leg {leg}: reversal {self.reversal_um:+.4f} +/- {self.stderr_um:.4f} um from {self.pairs} reversal "
                "probe pairs, taken out of the passes before the other effects were fitted (with passes only, a "
                "reversal and a speed-dependent lag are nearly collinear)")


def probe_points(points: np.ndarray) -> np.ndarray:
    """The reversal probes among `points` with a finite reading (empty without a flags field)."""
    if "flags" not in (points.dtype.names or ()) or len(points) == 0:
        return points[:0]
    return points[is_probe(points) & np.isfinite(np.asarray(points["error_um"], dtype=float))]


def fixed_reversal(probes: np.ndarray, leg: LegData, twin: Twin | None) -> FixedReversal | None:
    """The reversal `probes` (this leg's) give against the passes' shape (module docstring);
    None with fewer than MIN_PAIRS pairs or no standard error."""
    if len(probes) < 2 * MIN_PAIRS:
        return None
    x = np.asarray(probes["target_mm"], dtype=float)
    d = np.asarray(probes["direction"]).astype(float)
    if twin is not None:
        shape = twin.predict_um(leg.leg, x, d)
    else:  # the passes' mean error at each target (both directions alike), interpolated
        n = np.bincount(leg.target_id, minlength=leg.n_targets)
        means = np.bincount(leg.target_id, leg.error_um, minlength=leg.n_targets) / np.maximum(n, 1)
        shape = np.interp(x, leg.targets_mm, means)
    found = reversal_of_residuals(np.asarray(probes["error_um"], dtype=float) - shape, d, np.asarray(probes["run"]))
    if found is None:
        return None
    r, se, pairs = found
    if pairs < MIN_PAIRS or se is None or not se > 0:
        return None
    p = float(2.0 * stdtr(pairs - 1, -abs(r) / se))
    return FixedReversal(r, se, pairs, p)
