"""The noise floor: how far one pass scatters from the others at the same target.

Definition (docs/models.md): for every cell (distinct target, direction) measured by at least two
passes, take the deviations of the passes from the cell mean; the noise floor is the pooled
standard deviation sqrt(sum of squared deviations / sum of (n_cell - 1)). Per-pass offsets
(re-zeroing, drift, warm-up between passes) are *kept*: a compensation table is static, so
scatter from pass to pass is part of what no table can remove. It is the RMS error a perfect
static model would leave on a new pass, and the yardstick for the held-out residual.

`within_pass_um` ("within-pass scatter") is the same after removing each pass's mean deviation:
the short-term measurement scatter alone, reported for diagnosis only. Names and the other
figures: docs/figures.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from procedures.fit.data import LegData


@dataclass(frozen=True)
class NoiseFloor:
    noise_floor_um: float | None  # None when no cell has two passes
    within_pass_um: float | None
    cells: int  # cells with at least two passes
    dof: int  # degrees of freedom of the pooled estimate


def noise_floor(position_mm, direction, run, error_um) -> NoiseFloor:
    """Noise floor and within-pass scatter of one leg's points (module docstring), um: the
    one computation behind every "noise floor" the station prints (fit, report, verify,
    diagnose). Cells are (target position, direction); `run` numbers the passes."""
    position_mm = np.asarray(position_mm, dtype=float)
    error_um = np.asarray(error_um, dtype=float)
    run = np.asarray(run)
    keys = np.stack([position_mm, np.asarray(direction, dtype=float)], axis=1)
    _, ids = np.unique(keys, axis=0, return_inverse=True)
    ids = ids.ravel()
    n_cells = int(ids.max()) + 1 if ids.size else 0
    counts = np.bincount(ids, minlength=n_cells)
    sums = np.bincount(ids, weights=error_um, minlength=n_cells)
    means = sums / np.maximum(counts, 1)
    dev = error_um - means[ids]
    multi = counts >= 2
    use = multi[ids]
    dof = int((counts[multi] - 1).sum())
    if dof == 0:
        return NoiseFloor(None, None, 0, 0)
    total = float(np.sqrt(np.sum(dev[use] ** 2) / dof))
    # remove each pass's mean deviation (its offset); the pass means cost one dof per pass
    runs, run_ids = np.unique(run[use], return_inverse=True)
    d = dev[use]
    run_mean = np.bincount(run_ids, weights=d) / np.bincount(run_ids)
    d2 = d - run_mean[run_ids]
    dof2 = dof - runs.size
    within = float(np.sqrt(np.sum(d2**2) / dof2)) if dof2 > 0 else None
    return NoiseFloor(total, within, int(multi.sum()), dof)


def estimate_noise_floor(data: LegData) -> NoiseFloor:
    """Pooled pass-to-pass scatter of one leg (see the module docstring), um."""
    return noise_floor(data.position_mm, data.direction, data.run, data.error_um)
