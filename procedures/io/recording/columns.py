"""Optional per-point columns kept beside /points, as datasets of their own.

`/co2_ppm` (float64, ppm): the CO2 content of the air at each point, one value per /points row in
file order (NaN = not measured). It is not a field of /points: the compound point type stays the
same for every writer and reader of schema 1.x, and most sessions have no CO2 sensor (live
sweeps: the interferometer reports none). Written whole, once, by whoever makes the file (an
import of a CSV with a co2_ppm column, `station recorrect`); a file without it has no CO2
readings, and the refractive index uses the configured `[metrology] co2_ppm` (default 450).
"""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np

from procedures.io.recording.schema import UNWRITTEN_INDEX

POINT_COLUMNS = {"co2_ppm": "ppm"}
"""Optional per-point columns: name -> unit (the dataset's `units` attribute)."""


def write_point_column(path: str | os.PathLike, name: str, values: np.ndarray) -> None:
    """Store `values` (one per /points row, file order) as dataset /<name> of a finished,
    closed session file that is not yet at its final path (callers write to a temporary file and
    rename it)."""
    if name not in POINT_COLUMNS:
        raise ValueError(f"unknown per-point column {name!r}; known: {', '.join(POINT_COLUMNS)}")
    with h5py.File(path, "r+") as f:
        n = f["points"].shape[0]
        values = np.asarray(values, dtype="<f8")
        if values.shape != (n,):
            raise ValueError(f"{name}: {values.shape[0] if values.ndim else 0} values for {n} points")
        if name in f:
            del f[name]
        ds = f.create_dataset(name, data=values)
        ds.attrs["units"] = POINT_COLUMNS[name]


def read_point_column(path: str | os.PathLike, name: str) -> np.ndarray | None:
    """/<name> for the written /points rows (as procedures.io.recording.reader.read_session keeps
    them), or None when the file has no such column or its length does not match /points."""
    with h5py.File(Path(path), "r", swmr=True) as f:
        if name not in f or not isinstance(f[name], h5py.Dataset) or "points" not in f:
            return None
        index = f["points"]["index"] if f["points"].dtype.names and "index" in f["points"].dtype.names else None
        values = np.asarray(f[name][...], dtype=float)
    if index is None or values.shape != index.shape:
        return None
    return values[index != UNWRITTEN_INDEX]
