"""Cross-validation over held-out passes.

Points within one pass are not independent (a pass shares its offset, its temperature, its
drift), so data are held out a whole cycle at a time: the k-th upward and the k-th downward pass
(LegData.cycle) form one group, and a fold holds out whole groups. A held-out residual is
then what a model fitted on the other cycles leaves on a cycle it has never seen.
"""

from __future__ import annotations

from typing import Callable, Protocol

import numpy as np

from procedures.fit.data import LegData

MAX_FOLDS = 10


class _Predictor(Protocol):
    def predict_um(self, position_mm, direction) -> np.ndarray: ...


def cycle_folds(data: LegData, max_folds: int = MAX_FOLDS) -> np.ndarray | None:
    """Fold number (0-based) of every point: one fold per cycle (cycles dealt round-robin into
    at most `max_folds` folds). None when the leg has fewer than two cycles."""
    cycles = np.unique(data.cycle)
    if cycles.size < 2:
        return None
    n_folds = min(max_folds, cycles.size)
    fold_of_cycle = {int(c): i % n_folds for i, c in enumerate(cycles)}
    return np.array([fold_of_cycle[int(c)] for c in data.cycle], dtype=np.int64)


def heldout_residuals_um(
    data: LegData, folds: np.ndarray, fit_fn: Callable[[LegData], _Predictor]
) -> np.ndarray:
    """Residual (error minus prediction, um) of every point, predicted by a model that
    `fit_fn` fitted on the other folds."""
    resid = np.empty(data.n_points)
    for f in np.unique(folds):
        test = folds == f
        model = fit_fn(data.subset(~test))
        resid[test] = data.error_um[test] - model.predict_um(data.position_mm[test], data.direction[test])
    return resid
