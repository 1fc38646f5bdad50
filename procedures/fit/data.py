"""Per-leg arrays from a session's points (POINT_DTYPE), the input of every fit.

Sign conventions (drivers.interfaces): `error_um` = measured minus commanded target, um;
`direction` +1 = the target was approached while the position increased.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from procedures.vocabulary import InputError
from procedures.acquisition.points import check_points, usable_rows_by_leg



@dataclass(frozen=True)
class LegData:
    """The usable points of one leg, in recording order.

    `position_mm`: commanded target (mm, leg coordinates); `error_um`: measured minus target;
    `direction`: +1/-1; `run`: one-direction pass number; `cycle`: 1-based rank of the pass among
    the passes of its direction (the k-th upward and the k-th downward pass form cycle k), the
    group used to hold data out in cross-validation. `dropped` counts rows without a finite
    error or target (failed points), which are left out.
    """

    leg: int
    position_mm: np.ndarray
    error_um: np.ndarray
    direction: np.ndarray
    run: np.ndarray
    cycle: np.ndarray
    time_s: np.ndarray
    dropped: int = 0

    @property
    def n_points(self) -> int:
        return int(self.position_mm.size)

    @property
    def n_passes(self) -> int:
        return int(np.unique(self.run).size)

    @property
    def n_cycles(self) -> int:
        return int(self.cycle.max()) if self.cycle.size else 0

    @property
    def stroke_mm(self) -> tuple[float, float]:
        return (float(self.position_mm.min()), float(self.position_mm.max()))

    def targets_mm(self) -> np.ndarray:
        """Distinct commanded targets, ascending."""
        return np.unique(self.position_mm)

    def target_spacing_mm(self) -> float:
        """Median spacing between neighbouring distinct targets, mm (0 for a single target)."""
        t = self.targets_mm()
        return float(np.median(np.diff(t))) if t.size > 1 else 0.0

    def subset(self, mask: np.ndarray) -> "LegData":
        return LegData(
            self.leg, self.position_mm[mask], self.error_um[mask], self.direction[mask],
            self.run[mask], self.cycle[mask], self.time_s[mask], 0,
        )


def _cycles(run: np.ndarray, direction: np.ndarray) -> np.ndarray:
    cycle = np.zeros(run.size, dtype=np.int64)
    for d in (1, -1):
        runs_d = np.unique(run[direction == d])
        for rank, r in enumerate(runs_d, start=1):
            cycle[(run == r) & (direction == d)] = rank
    return cycle


def split_legs(points: np.ndarray, source: str = "the session") -> dict[int, LegData]:
    """Split a POINT_DTYPE array (or any structured array with leg, run, direction, target_mm,
    error_um) into per-leg `LegData`, legs ascending.

    Rows whose `error_um` or `target_mm` is not finite are dropped (counted in `dropped`).
    Raises `SchemaError` for missing fields or a direction other than +1/-1 (naming the row),
    `InputError` when no usable point is left.
    """
    check_points(points, source)
    names = points.dtype.names or ()
    out: dict[int, LegData] = {}
    for leg, (rows, dropped) in usable_rows_by_leg(points).items():
        p = points[rows]
        run = np.asarray(p["run"]).astype(np.int64)
        direction = np.asarray(p["direction"]).astype(np.int64)
        time_s = np.asarray(p["time_s"], dtype=float) if "time_s" in names else np.full(p.size, np.nan)
        out[leg] = LegData(
            leg=leg,
            position_mm=np.asarray(p["target_mm"], dtype=float),
            error_um=np.asarray(p["error_um"], dtype=float),
            direction=direction,
            run=run,
            cycle=_cycles(run, direction),
            time_s=time_s,
            dropped=dropped,
        )
    if not out:
        raise InputError(f"{source}: no point has a finite error_um; nothing to fit")
    return out
