"""EPICS ecmc (ESS/PSI EtherCAT motion control): encoder correction lookup table.

Sources: epics-modules/ecmc `devEcmcSup/misc/ecmcLookupTable.h` (a text file of two columns,
space- or comma-separated; lines starting with '#' are comments; `PREC=<n>` lines; at least 3
rows, strictly increasing index column; linear interpolation between rows; "for values outside
the range ... the first or last value" is used) and `devEcmcSup/motion/ecmcEncoder.cpp`
(`actPos = actPos - scale * lookupTable->getValue(actPos)` once the axis is homed: column 1 is
the raw encoder position, column 2 the error subtracted from it, scaled by the encoder's
lookup-table scale; scale -1 flips the sign); paulscherrerinstitute/ecmccfg
`hugo/content/manual/general_cfg/lut.md` (loadLUTFile.cmd, the file format) and the encoder
YAML `lookuptable: filename/enable/range/scale`.

One table, one direction: the correction acts on the encoder reading whichever way the axis
moves. Written here: column 1 the position (mm, the axis' EGU), column 2 = -e(x) (mm) for the
chosen direction ("mean" of both by default, leaving +/- half the reversal), so with scale 1 the
corrected reading is raw + e(raw), the true position: the axis stops where raw + e(raw) equals
the target. With scale -1 the file would have to hold +e(x).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drivers.interfaces import TableSpec
from procedures.compensation.controllers.common import (ControllerFileError, checked, interp_held, leg_errors_mm, leg_paths, number,
                                           read_lines, strictly_increasing, write_files)
from procedures.compensation.table import CompTable

NAME = "ecmc"
SUFFIX = ".lut"
RESOLUTION_MM = 1e-9  # 9 decimals
DIRECTIONS = ("mean", "fwd", "rev")
LIMITS = TableSpec(max_points=100000, max_correction_um=1000.0, entry_resolution_um=0.0, min_step_mm=1e-6,
                   banks=1, holder="ecmc lookup table")


def values_mm(t, direction: str = "mean") -> np.ndarray:
    _, fwd, rev = leg_errors_mm(t)
    if direction not in DIRECTIONS:
        raise ControllerFileError(f"ecmc direction must be one of {', '.join(DIRECTIONS)}, got {direction!r}")
    e = {"mean": (fwd + rev) / 2, "fwd": fwd, "rev": rev}[direction]
    return -e


def text(t, direction: str = "mean") -> str:
    pos, _, _ = leg_errors_mm(t)
    lines = [
        f"# station: leg {t.leg}, encoder correction for approach direction: {direction}",
        "# col 1: encoder position [mm]; col 2: error ecmc subtracts (scale 1) = -(measured - commanded) [mm]",
        "PREC=10",
    ]
    lines += [f"{x:.6f} {v:.9f}" for x, v in zip(pos, values_mm(t, direction))]
    return "\n".join(lines) + "\n"


def write(table: CompTable, out: str | os.PathLike, direction: str = "mean", spec=None) -> list[Path]:
    """One lookup table per leg (`OUT/leg<N>.lut`, or `<name>_leg<N>.lut`)."""
    checked(table, spec or LIMITS, out)
    if table.legs and any(t.point_count < 3 for t in table.legs.values()):
        raise ControllerFileError(f"{out}: ecmc needs at least 3 rows per table")
    paths = leg_paths(out, table.legs, SUFFIX)
    return write_files(out, {paths[leg]: text(t, direction) for leg, t in table.legs.items()}, SUFFIX)


@dataclass(frozen=True)
class EcmcLut:
    index_mm: np.ndarray
    value_mm: np.ndarray
    scale: float = 1.0

    def corrected_mm(self, raw_mm) -> np.ndarray:
        """ecmcEncoder: the reading after correction."""
        raw = np.asarray(raw_mm, dtype=float)
        return raw - self.scale * interp_held(raw, self.index_mm, self.value_mm)

    def applied_mm(self, position_mm, direction=1) -> np.ndarray:
        """Where the axis (raw encoder position) stops minus the target: the loop closes on the
        corrected reading, so raw - scale*L(raw) = target (solved by fixed-point iteration;
        L's slope is far below 1). The same both ways."""
        target = np.asarray(position_mm, dtype=float)
        raw = target.copy()
        for _ in range(50):
            new = target + self.scale * interp_held(raw, self.index_mm, self.value_mm)
            if np.max(np.abs(new - raw), initial=0.0) < 1e-13:
                raw = new
                break
            raw = new
        return raw - target


def load(path: str | os.PathLike, scale: float = 1.0) -> EcmcLut:
    """Read a lookup table as ecmcLookupTable does: commas as spaces, '#' comments, PREC=
    lines, two numbers per row; refused (with line and field) for anything else, fewer than 3
    rows or an index column not strictly increasing."""
    path = Path(path)
    idx, val, rows = [], [], []
    for no, raw in enumerate(read_lines(path), start=1):
        line = raw.replace(",", " ")
        if not line.strip():
            continue
        if line.startswith("#"):
            continue
        if line.startswith("P"):
            if line.strip().startswith("PREC=") and line.strip()[5:].lstrip("-").isdigit():
                continue
            raise ControllerFileError(f"{path}, line {no}: {raw.strip()[:40]!r} is not PREC=<n>")
        cells = line.split()
        if len(cells) < 2:
            raise ControllerFileError(f"{path}, line {no}: expected two numbers (position, correction), found {raw.strip()[:40]!r}")
        idx.append(number(path, no, "position", cells[0]))
        val.append(number(path, no, "correction", cells[1]))
        rows.append(no)
    if len(idx) < 3:
        raise ControllerFileError(f"{path}: {len(idx)} row(s); ecmc needs at least 3")
    strictly_increasing(path, idx, rows, "position")
    return EcmcLut(np.array(idx), np.array(val), scale)
