"""Per-leg arrays for the diagnosis, from a session's points (POINT_DTYPE).

Sign conventions (drivers.interfaces): `error_um` = measured minus commanded target, um (positive
= the leg is longer than commanded); `direction` +1 = approached while the position increased.
Optional fields (time, material temperature, load) are NaN when not measured; a leg counts a
condition as recorded only when every usable point has it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from procedures.vocabulary import InputError
from procedures.acquisition.points import check_points, usable_rows_by_leg

MAX_FOLDS = 12


@dataclass(frozen=True)
class LegData:
    """The usable points of one leg, in recording order.

    `rows` are the indices of these points in the input array. `pass_id` numbers the passes
    0..n_passes-1 in run order; `cycle` (0-based) pairs the k-th upward with the k-th downward
    pass, the unit held out in cross-validation. `target_id` numbers the distinct targets (targets
    closer than a tenth of the usual spacing, e.g. backward targets 0.2 mm off the forward ones,
    count as one). `time_h` is hours since the first point of the leg; `load_kn` kN, compression
    positive; `temp_c` material temperature.
    """

    leg: int
    rows: np.ndarray
    x_mm: np.ndarray
    error_um: np.ndarray
    direction: np.ndarray
    run: np.ndarray
    pass_id: np.ndarray
    cycle: np.ndarray
    target_id: np.ndarray
    targets_mm: np.ndarray
    time_h: np.ndarray
    temp_c: np.ndarray
    load_kn: np.ndarray
    dropped: int = 0
    speed_mm_s: np.ndarray | None = None  # signed axis speed at the reading (on-the-fly), NaN/None = at rest

    @property
    def n_points(self) -> int:
        return int(self.x_mm.size)

    @property
    def n_passes(self) -> int:
        return int(self.pass_id.max()) + 1 if self.pass_id.size else 0

    @property
    def n_cycles(self) -> int:
        return int(self.cycle.max()) + 1 if self.cycle.size else 0

    @property
    def n_targets(self) -> int:
        return int(self.targets_mm.size)

    @property
    def has_time(self) -> bool:
        return bool(np.all(np.isfinite(self.time_h)))

    @property
    def has_temp(self) -> bool:
        return bool(np.all(np.isfinite(self.temp_c)))

    @property
    def has_speed(self) -> bool:
        return self.speed_mm_s is not None and bool(np.all(np.isfinite(self.speed_mm_s)))

    @property
    def has_load(self) -> bool:
        return bool(np.all(np.isfinite(self.load_kn)))

    @property
    def span_mm(self) -> tuple[float, float]:
        return float(self.x_mm.min()), float(self.x_mm.max())

    @property
    def spacing_mm(self) -> float:
        """Median spacing of the distinct targets, mm (0 for a single target)."""
        return float(np.median(np.diff(self.targets_mm))) if self.targets_mm.size > 1 else 0.0

    def passes_of_direction(self, direction: int) -> int:
        return int(np.unique(self.pass_id[self.direction == direction]).size)

    def folds(self, max_folds: int = MAX_FOLDS, unit: str = "cycle") -> np.ndarray | None:
        """Fold number of every point for cross-validation: whole cycles (`unit` "cycle": the
        k-th upward and k-th downward pass together, so every fold is balanced in direction)
        or whole passes ("pass"), dealt round-robin in time order into at most `max_folds`
        folds. None when the leg has fewer than two cycles (too few passes to hold any out)."""
        if self.n_cycles < 2:
            return None
        if unit == "pass":
            return self.pass_id % min(max_folds, self.n_passes)
        return self.cycle % min(max_folds, self.n_cycles)


def _cluster_targets(x_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct targets: unique positions, merging neighbours closer than a tenth of the usual
    (90th percentile) gap. Returns (centres_mm, id of every point)."""
    ux = np.unique(x_mm)
    if ux.size == 1:
        return ux, np.zeros(x_mm.size, dtype=np.int64)
    gaps = np.diff(ux)
    tol = 0.1 * float(np.percentile(gaps, 90))
    group = np.concatenate([[0], np.cumsum(gaps > tol)])
    centres = np.array([ux[group == g].mean() for g in range(group[-1] + 1)])
    ids = group[np.searchsorted(ux, x_mm)]
    return centres, ids


def _field(points: np.ndarray, name: str) -> np.ndarray:
    if name in (points.dtype.names or ()):
        return np.asarray(points[name], dtype=float)
    return np.full(points.size, np.nan)


def split_legs(points: np.ndarray, source: str = "the session") -> dict[int, LegData]:
    """Per-leg `LegData` from a POINT_DTYPE array (or any structured array with at least leg,
    run, direction, target_mm, error_um), legs ascending.

    Rows with a non-finite target or error (failed points) are dropped and counted. Raises
    SchemaError naming the field or row for missing fields or a direction other than +1/-1,
    InputError when no usable point is left.
    """
    check_points(points, source)
    target_all = np.asarray(points["target_mm"], dtype=float)
    error_all = np.asarray(points["error_um"], dtype=float)
    direction_all = np.asarray(points["direction"]).astype(np.int64)
    time_all = _field(points, "time_s")
    temp_all = _field(points, "material_temp_c")
    load_all = _field(points, "load_n")
    speed_all = _field(points, "speed_mm_s")
    out: dict[int, LegData] = {}
    for leg, (rows, dropped) in usable_rows_by_leg(points).items():
        run = np.asarray(points["run"][rows]).astype(np.int64)
        direction = direction_all[rows].astype(float)
        # passes in run order; a pass is one run (one direction)
        uruns, pass_id = np.unique(run, return_inverse=True)
        pass_dir = np.array([direction[pass_id == p][0] for p in range(uruns.size)])
        pass_cycle = np.zeros(uruns.size, dtype=np.int64)
        for d in (1.0, -1.0):
            sel = np.flatnonzero(pass_dir == d)
            pass_cycle[sel] = np.arange(sel.size)
        x = target_all[rows]
        centres, target_id = _cluster_targets(x)
        t = time_all[rows]
        t_h = (t - np.nanmin(t)) / 3600.0 if np.any(np.isfinite(t)) else t
        out[leg] = LegData(
            leg=leg, rows=rows, x_mm=x, error_um=error_all[rows], direction=direction, run=run,
            pass_id=pass_id.astype(np.int64), cycle=pass_cycle[pass_id], target_id=target_id,
            targets_mm=centres, time_h=t_h, temp_c=temp_all[rows], load_kn=load_all[rows] / 1000.0,
            dropped=dropped, speed_mm_s=speed_all[rows],
        )
    if not out:
        raise InputError(f"{source}: no point has a finite target_mm and error_um; nothing to diagnose")
    return out


def per_pass_line_removed(leg: LegData, v: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """`v` on `rows` minus a least-squares line in position fitted per pass: removes pass
    offsets and slopes, i.e. everything backlash, drift, load, thermal and scale can do."""
    pid, x = leg.pass_id[rows], leg.x_mm[rows]
    n = np.bincount(pid, minlength=leg.n_passes).astype(float)
    sx, sxx = np.bincount(pid, x, leg.n_passes), np.bincount(pid, x * x, leg.n_passes)
    den = np.where(n > 0, n * sxx - sx**2, 1.0)
    den = np.where(np.abs(den) > 1e-12, den, 1.0)
    cols = v if v.ndim == 2 else v[:, None]
    out = np.empty_like(cols)
    for j in range(cols.shape[1]):
        c = cols[:, j]
        sv, sxv = np.bincount(pid, c, leg.n_passes), np.bincount(pid, x * c, leg.n_passes)
        slope = (n * sxv - sx * sv) / den
        icpt = np.divide(sv - slope * sx, n, out=np.zeros_like(n), where=n > 0)
        out[:, j] = c - icpt[pid] - slope[pid] * x
    return out if v.ndim == 2 else out[:, 0]
