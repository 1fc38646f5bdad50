"""The table's reversal from reversal probes (docs/onthefly.md, "Reversal probes").

A leg's reversal (mean error approaching downwards minus upwards, um) is the one constant of
its table that the pass-to-pass offsets decide: every pass carries an offset of its own (the
simulated leg draws one at every reversal, a real one re-seats its nut and the laser's zero
drifts), so a fit of `n` up and `n` down passes knows the reversal only to about
sigma_offset * sqrt(2 / n), however many points each pass has. On the fly a cycle is a pair of
whole passes (half a minute); a probe pair is two stop-and-go readings, each right after a
reversal (a few seconds), so the probes sample the offsets far faster.

`apply_probes(fit, probes)`: with the shape of the table from the passes (the fit), each probe's
residual is its reading minus the fit's prediction at its position and direction; the mean
downward residual minus the mean upward one is the fit's reversal error as the probes see it,
and the fit's constant reversal coefficient (r_0, procedures/fit/bidirectional.py) is moved by
it. The reversal then comes from the probes alone: the passes' own estimate also carries the
error of the speed coefficients (procedures/fit/dynamic.py: k_d times the pass speed is a
constant per pass, so an error in k_d is an error in that direction's constant), which the
probes, read at rest, do not. The shape (everything but r_0) is left as fitted.

Sign convention as everywhere: error = measured minus commanded, um; reversal = down minus up.
The probes' points are normalised to 20 degC like every other point before they get here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from procedures.io.recording.schema import FLAG_PROBE

if TYPE_CHECKING:  # the annotation only: the model module imports this one's callers
    from procedures.fit.model import LegFit


@dataclass(frozen=True)
class ProbeReversal:
    """What the probes did to one leg's fit: `pairs` (the fewer of up and down readings),
    `shift_um` (added to the reversal: down minus up), `before_um`/`after_um` (the fit's reversal at
    mid-stroke), `stderr_um` (standard error of the probes' reversal: the scatter of the pairs'
    differences / sqrt(pairs))."""

    pairs: int
    shift_um: float
    before_um: float
    after_um: float
    stderr_um: float | None

    def to_json(self) -> dict[str, Any]:
        return {"pairs": self.pairs, "shift_um": self.shift_um, "before_um": self.before_um,
                "after_um": self.after_um, "stderr_um": self.stderr_um}

    def describe(self) -> str:
        se = f" +/- {self.stderr_um:.4f}" if self.stderr_um is not None else ""
        return (f"reversal from {self.pairs} probe pairs: {self.after_um:+.4f}{se} um "
                f"(the passes gave {self.before_um:+.4f} um)")


def is_probe(points: np.ndarray) -> np.ndarray:
    """Mask of the reversal probes among `points` (FLAG_PROBE)."""
    return (np.asarray(points["flags"]) & FLAG_PROBE) != 0


def _pair_stderr_um(resid: np.ndarray, direction: np.ndarray, run: np.ndarray, ok: np.ndarray) -> float | None:
    """Standard error of the probes' reversal from its pairs (an upward reading and the downward
    one after it, SweepPlan's order): the scatter of the pairs' differences / sqrt(pairs). A pair
    shares what changes slowly along the probes (the leg warming, drift), which a scatter per
    direction would count as noise. None with fewer than two whole pairs."""
    order = np.argsort(run, kind="stable")
    r, dd, good = resid[order], direction[order], ok[order]
    diffs = [r[i + 1] - r[i] for i in range(len(r) - 1)
             if dd[i] > 0 and dd[i + 1] < 0 and good[i] and good[i + 1]]
    if len(diffs) < 2:
        return None
    return float(np.std(diffs, ddof=1) / np.sqrt(len(diffs)))


def reversal_of_residuals(resid_um: np.ndarray, direction: np.ndarray, run: np.ndarray
                          ) -> tuple[float, float | None, int] | None:
    """(reversal, its standard error, pairs) of probe residuals `resid_um` (each probe's reading
    minus a prediction of the same shape for both directions, um; NaN = not read): the mean
    downward residual minus the mean upward one; the standard error from the pairs
    (`_pair_stderr_um`), else from the scatter per direction; pairs = the fewer of up and down
    readings. None without a reading in either direction. Also the diagnosis's reversal
    (procedures/diagnosis/probe_reversal.py)."""
    resid, d = np.asarray(resid_um, dtype=float), np.asarray(direction)
    ok = np.isfinite(resid)
    up, down = ok & (d > 0), ok & (d < 0)
    if not np.any(up) or not np.any(down):
        return None
    shift = float(np.mean(resid[down]) - np.mean(resid[up]))
    n_up, n_down = int(up.sum()), int(down.sum())
    stderr = _pair_stderr_um(resid, d, np.asarray(run), ok)
    if stderr is None and n_up + n_down > 2:  # no whole pairs to go by: the scatter per direction
        ss = float(np.sum((resid[up] - resid[up].mean()) ** 2) + np.sum((resid[down] - resid[down].mean()) ** 2))
        stderr = float(np.sqrt(ss / (n_up + n_down - 2) * (1.0 / n_up + 1.0 / n_down)))
    return shift, stderr, min(n_up, n_down)


def apply_probes(leg_fit: LegFit, probes: np.ndarray) -> ProbeReversal | None:
    """Move `leg_fit`'s constant reversal coefficient to what its `probes` (this leg's probe
    points, error normalised) say (module docstring), in place; the result is also stored in
    its `selection["reversal_probes"]`. None (the fit untouched) when the fit has no reversal
    term to move or the probes lack a reading in either direction."""
    basis = getattr(leg_fit, "basis", None)
    if basis is None or basis.reversal_degree < 0:
        return None
    d = np.asarray(probes["direction"])
    resid = np.asarray(probes["error_um"], dtype=float) - leg_fit.predict_um(np.asarray(probes["target_mm"], dtype=float), d)
    found = reversal_of_residuals(resid, d, np.asarray(probes["run"]))
    if found is None:
        return None
    shift, stderr, pairs = found
    before = float(leg_fit.reversal_um)
    # r_0 is the reversal's constant Legendre coefficient: P_0 = 1 everywhere, so adding the
    # shift to it moves the reversal by the shift at every position, the shape untouched
    leg_fit.coef_um[basis.trend_degree + 1] += shift
    result = ProbeReversal(pairs, shift, before, float(leg_fit.reversal_um), stderr)
    leg_fit.selection["reversal_probes"] = result.to_json()
    return result
