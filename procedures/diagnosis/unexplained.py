"""What no candidate explains: structure left above the repeat scatter once the twin and the
named effects are taken out (issue 25).

The residual of the final fit is averaged per target and direction; each cell mean is compared
with its standard error from the repeat scatter (scatter / sqrt(repeats)). When the cell means
stand out (chi-square test at the diagnosis' alpha) and the largest exceeds the threshold, the
structure is described as two profiles along the stroke, the direction-independent one (the
mean of both directions) and the direction-dependent one (negative minus positive), the larger
first: its shape (periodic at a wavelength, at the end(s) of the stroke, a step, a local bump, or
spread along the stroke), where, how large, and that it lies outside the library of candidate
effects.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2

from procedures.diagnosis.effects import cyclic_grid
from procedures.diagnosis.legdata import LegData
from procedures.diagnosis.twin import sinusoid_scan

END_SHARE = 0.1  # the outer 10 % of the stroke at each end count as "the end of the stroke"
PERIODIC_SHARE = 0.5  # a sinusoid explaining this share of a profile's square makes it periodic
STEP_SHARE = 0.7
BUMP_SHARE, BUMP_WIDTH = 0.7, 0.25  # this share of the square within this share of the stroke


def _shape(x: np.ndarray, v: np.ndarray, leg: LegData) -> dict:
    """Shape of a profile `v` (um) at positions `x` (mm, sorted)."""
    lo, hi = float(x[0]), float(x[-1])
    span = max(hi - lo, 1e-9)
    e = v * v
    total = float(e.sum())
    i_peak = int(np.argmax(np.abs(v)))
    out = {"peak_um": float(v[i_peak]), "peak_at_mm": float(x[i_peak]), "rms_um": float(np.sqrt(np.mean(e)))}
    grid = cyclic_grid(leg, oversample=2)
    if grid.size and x.size >= 8:
        amp, _, _ = sinusoid_scan(x, v, np.ones(x.size), grid)
        k = int(np.argmax(amp))
        if amp[k] ** 2 / 2 * x.size >= PERIODIC_SHARE * total:
            return {**out, "shape": "periodic", "wavelength_mm": float(1 / grid[k]), "amplitude_um": float(amp[k]),
                    "from_mm": lo, "to_mm": hi,
                    "words": f"periodic with a {1 / grid[k]:.3g} mm wavelength, {amp[k]:.3g} um amplitude"}
    ends = (x <= lo + END_SHARE * span) | (x >= hi - END_SHARE * span)
    if ends.any() and float(e[ends].sum()) >= 0.6 * total:
        where = ("both ends" if e[x <= lo + END_SHARE * span].sum() > 0.2 * total and e[x >= hi - END_SHARE * span].sum() > 0.2 * total
                 else ("the bottom end" if x[i_peak] < 0.5 * (lo + hi) else "the top end"))
        return {**out, "shape": "end of stroke", "from_mm": float(x[ends][0]), "to_mm": float(x[ends][-1]),
                "words": f"at {where} of the stroke (up to {v[i_peak]:+.3g} um at {x[i_peak]:.4g} mm)"}
    # a step: the best split into two constant parts
    c = np.cumsum(v)
    n = np.arange(1, x.size)
    left, right = c[:-1] / n, (c[-1] - c[:-1]) / (x.size - n)
    expl = n * left**2 + (x.size - n) * right**2 - c[-1] ** 2 / x.size
    k = int(np.argmax(expl))
    resid_total = total - c[-1] ** 2 / x.size
    if resid_total > 0 and expl[k] >= STEP_SHARE * resid_total and 2 <= k + 1 <= x.size - 2:
        at = 0.5 * (x[k] + x[k + 1])
        size = float(right[k] - left[k])
        return {**out, "shape": "step", "at_mm": float(at), "step_um": size, "from_mm": float(x[k]), "to_mm": float(x[k + 1]),
                "words": f"a step of {size:+.3g} um at {at:.4g} mm"}
    # a local bump: the narrowest window holding most of the square
    ce = np.concatenate([[0.0], np.cumsum(e)])
    best = None
    for a in range(x.size):
        b = int(np.searchsorted(ce, ce[a] + BUMP_SHARE * total))
        if b <= x.size and (best is None or x[b - 1] - x[a] < best[1] - best[0]):
            best = (float(x[a]), float(x[b - 1]))
    if best is not None and best[1] - best[0] <= BUMP_WIDTH * span:
        return {**out, "shape": "local bump", "from_mm": best[0], "to_mm": best[1],
                "words": f"a local bump between {best[0]:.4g} and {best[1]:.4g} mm (peak {v[i_peak]:+.3g} um at "
                         f"{x[i_peak]:.4g} mm)"}
    return {**out, "shape": "spread along the stroke", "from_mm": lo, "to_mm": hi,
            "words": f"spread along the stroke, no simple shape (peak {v[i_peak]:+.3g} um at {x[i_peak]:.4g} mm)"}


def unexplained(leg: LegData, resid_um: np.ndarray, scatter_um: float | None, threshold_um: float, alpha: float,
                exclude: np.ndarray | None = None, fitted_twin: bool = False) -> dict | None:
    """Structure above the repeat scatter that the twin and the named effects leave (`resid_um`,
    um per point; `exclude`: outlier points left out). None when there is none to report (no
    repeats, or the cell means are at the repeat scatter or below the threshold)."""
    if scatter_um is None or scatter_um <= 0:
        return None
    keep = np.ones(leg.n_points, bool) if exclude is None else ~exclude
    cell = (leg.target_id * 2 + (leg.direction > 0))[keep]
    r = resid_um[keep]
    size = 2 * leg.n_targets
    cnt = np.bincount(cell, minlength=size).astype(float)
    have = cnt >= 2
    mean = np.divide(np.bincount(cell, r, minlength=size), cnt, out=np.zeros(size), where=cnt > 0)
    z2 = (mean[have] / (scatter_um / np.sqrt(cnt[have]))) ** 2
    if z2.size < 4:
        return None
    p = float(chi2.sf(float(z2.sum()), z2.size))
    rms = float(np.sqrt(np.mean(mean[have] ** 2)))
    # localised structure (a bump, a step, the end of the stroke) has a small RMS over the whole stroke: its peak
    # cell mean must exceed the threshold
    if p >= alpha or float(np.max(np.abs(mean[have]))) <= threshold_um:
        return None
    up, down = mean[1::2], mean[0::2]  # cell = 2 * target + (direction > 0)
    both = have[1::2] & have[0::2]
    x = leg.targets_mm[both]
    profiles = {"direction-independent": 0.5 * (up + down)[both], "direction-dependent": (down - up)[both]}
    kind = max(profiles, key=lambda k: float(np.mean(profiles[k] ** 2)))
    if x.size < 4:
        return None
    shape = _shape(x, profiles[kind], leg)
    what = "the mean of both directions" if kind == "direction-independent" else "negative minus positive passes"
    where = ("a position shape finer than the twin fitted on this recording follows (its size is limited by "
             "cross-validation and conditioning), or outside the library of candidate effects"
             if fitted_twin and kind == "direction-independent" else "it lies outside the library of candidate effects")
    note = (f"structure no candidate explains: {rms:.3g} um RMS per target and direction above the {scatter_um:.3g} um "
            f"repeat scatter (p = {p:.2g}); mostly {kind} ({what}), {shape['words']}; {where}")
    return {"rms_um": rms, "repeat_scatter_um": scatter_um, "p_value": p, "kind": kind, **shape, "note": note}
