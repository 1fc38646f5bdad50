"""Checks and per-leg selection of a session's points, shared by every analysis.

The analyses (fit, diagnosis, verification) each keep the per-leg view they need; the rules of
what a usable point is, and the messages for bad input, live here once.
"""

from __future__ import annotations

import numpy as np

from procedures.vocabulary import InputError, SchemaError

ANALYSIS_FIELDS = ("leg", "run", "direction", "target_mm", "error_um")
"""Fields every analysis needs; the optional ones (time, temperature, load) may be absent."""


def check_points(points: np.ndarray, source: str = "the session") -> None:
    """Refuse points an analysis cannot use: missing fields or a direction other than +1/-1
    (SchemaError naming the field or row), or no point at all (InputError)."""
    names = points.dtype.names or ()
    missing = [f for f in ANALYSIS_FIELDS if f not in names]
    if missing:
        raise SchemaError(f"{source}: the points lack the field(s) {', '.join(missing)}")
    if points.size == 0:
        raise InputError(f"{source}: no measured points; record (station sweep) or import a session first")
    direction = np.asarray(points["direction"]).astype(np.int64)
    bad = np.flatnonzero((direction != 1) & (direction != -1))
    if bad.size:
        i = int(bad[0])
        raise SchemaError(f"{source}: point row {i}: field direction is {direction[i]}, expected +1 or -1")


def usable_rows_by_leg(points: np.ndarray) -> dict[int, tuple[np.ndarray, int]]:
    """For each leg (ascending): the indices of its usable rows in recording order, and how many
    rows were dropped because their target or error is not finite (failed points). Legs with no
    usable row are left out."""
    target = np.asarray(points["target_mm"], dtype=float)
    error = np.asarray(points["error_um"], dtype=float)
    legs = np.asarray(points["leg"]).astype(np.int64)
    out: dict[int, tuple[np.ndarray, int]] = {}
    for leg in np.unique(legs):
        idx = np.flatnonzero(legs == leg)
        ok = np.isfinite(target[idx]) & np.isfinite(error[idx])
        if ok.any():
            out[int(leg)] = (idx[ok], int((~ok).sum()))
    return out
