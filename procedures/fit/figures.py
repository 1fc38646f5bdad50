"""The figures the station prints about a leg's errors: one name per definition (docs/figures.md).

Each figure has one JSON key (units in the name) and one printed name, `LABELS[key]`, used by
every command and screen that shows it, and is computed by one function (the functions below,
`procedures.fit.noise.noise_floor`, or the diagnosis functions named in docs/figures.md), so two
commands that show the same figure print the same value for the same input. A figure of another
object carries that object's name in front: "model held-out RMS" (JSON `model_heldout_rms_um`) is
the held-out RMS of the model a report compensates with, "twin held-out RMS" that of the
diagnosis twin.

Errors are measured minus commanded, um.
"""

from __future__ import annotations

import numpy as np

LABELS: dict[str, str] = {
    # station fit, station report, station verify, station diagnose (procedures.fit.noise)
    "noise_floor_um": "noise floor",
    "within_pass_um": "within-pass scatter",
    # station fit (the model's cross-validation); station report quotes them as "model ..."
    "heldout_rms_um": "held-out RMS",
    "heldout_ratio": "held-out ratio",
    "ideal_heldout_ratio": "ideal held-out ratio",
    "range_before_um": "range before",
    "heldout_range_um": "held-out range",
    "heldout_range_reduction_pct": "held-out range reduction",
    # station report (the model's residual on the session's points)
    "rms_before_um": "RMS before",
    "residual_range_um": "residual range",
    "residual_range_reduction_pct": "residual range reduction",
    "residual_rms_um": "residual RMS",
    # station diagnose (after the twin and the named effects)
    "repeat_scatter_after_effects_um": "repeat scatter after effects",
    "within_pass_scatter_after_effects_um": "within-pass scatter after effects",
    "pass_offset_scatter_after_effects_um": "pass-offset scatter after effects",
}
"""JSON key -> printed name. Keys and names are unique (tests/procedures/test_figures.py)."""


def range_um(values) -> float:
    """max - min, um (range before: of the errors; held-out / residual range: of residuals)."""
    return float(np.ptp(np.asarray(values, dtype=float)))


def rms_um(values) -> float:
    """Root mean square about zero, um (held-out RMS: an offset the model missed counts)."""
    v = np.asarray(values, dtype=float)
    return float(np.sqrt(np.mean(v**2)))


def rms_about_mean_um(values) -> float:
    """Root mean square about the mean, um (RMS before, residual RMS: the session's zero
    reference is not a leg error)."""
    v = np.asarray(values, dtype=float)
    return float(np.sqrt(np.mean((v - v.mean()) ** 2)))


def reduction_pct(before: float | None, after: float | None) -> float | None:
    """100 (1 - after / before); None when either is missing or `before` is not positive."""
    if before is None or after is None or not before > 0:
        return None
    return 100.0 * (1.0 - after / before)
