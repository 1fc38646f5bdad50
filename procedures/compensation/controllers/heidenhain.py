"""HEIDENHAIN TNC: nonlinear axis error compensation table (*.COM).

Sources: HEIDENHAIN Technical Manual MANUALplus 620 (01/2012) section 6.10.3 "Nonlinear axis
error compensation", p. 713-718: the .COM table has an AXISPOS column (compensation points,
relative to the machine datum), a column named after the axis (CfgAxes/axisList) with the
compensation values, and "if required, enter the compensation values measured in the negative
direction of traverse in the BACKLASH column"; tables are assigned to axes in a *.CMA table.
TNC 407/415/425 Technical Manual (01/98), module 9095: a .COM table "has more than 256
entries" is refused (so at most 256 rows).

Layout written (the TNC table file layout: `BEGIN <name> MM`, a header line, fixed-width rows
numbered NR from 0, `[END]`):

    BEGIN LEG1.COM MM
    NR    AXISPOS       X             BACKLASH
    0     -90.0000      +0.0012       +0.0032
    ...
    [END]

Values in mm, 4 decimals (0.1 um, the TNC's input resolution). The axis column holds the error
measured approaching in + (measured minus nominal), BACKLASH the error approaching in -; the
control compensates them, so its correction is minus the value (our reading of the manual's
"error" curves; the manual pages we could read do not print the sign: check one point on the
machine). Between points linear interpolation; beyond the table the end value (assumed, as the
other controllers do). The column layout is modelled on TNC table files: check it against a
.COM file your control exports before loading ours.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drivers.interfaces import TableSpec
from procedures.compensation.controllers.common import (ControllerFileError, by_direction, checked, interp_held, leg_errors_mm,
                                           leg_paths, number, read_lines, strictly_increasing, write_files)
from procedures.compensation.table import CompTable

NAME = "heidenhain"
SUFFIX = ".COM"
MAX_ROWS = 256
RESOLUTION_MM = 1e-4
LIMITS = TableSpec(max_points=MAX_ROWS, max_correction_um=1000.0, entry_resolution_um=0.0, min_step_mm=1e-4,
                   banks=1, holder="HEIDENHAIN .COM")


def text(t, axis: str = "X") -> str:
    pos, fwd, rev = leg_errors_mm(t)
    name = f"LEG{t.leg}.COM"
    lines = [f"BEGIN {name} MM", f"{'NR':<6}{'AXISPOS':<14}{axis:<14}BACKLASH"]
    for i, (x, f, r) in enumerate(zip(pos, fwd, rev)):
        lines.append(f"{i:<6}{x:<+14.4f}{f:<+14.4f}{r:+.4f}")
    lines.append("[END]")
    return "\n".join(lines) + "\n"


def write(table: CompTable, out: str | os.PathLike, axis: str = "X", spec=None) -> list[Path]:
    """One .COM per leg (`OUT/leg<N>.COM`, or `<name>_leg<N>.COM` for OUT ending in .COM);
    more than 256 rows refused, nothing written."""
    checked(table, spec or LIMITS, out)
    paths = leg_paths(out, table.legs, SUFFIX)
    return write_files(out, {paths[leg]: text(t, axis) for leg, t in table.legs.items()}, SUFFIX)


@dataclass(frozen=True)
class HeidenhainComp:
    axispos_mm: np.ndarray
    positive_mm: np.ndarray  # the axis column: error approaching in +
    negative_mm: np.ndarray  # BACKLASH: error approaching in - (the axis column when absent)

    def applied_mm(self, position_mm, direction) -> np.ndarray:
        x, d = by_direction(position_mm, direction)
        value = np.where(d > 0, interp_held(x, self.axispos_mm, self.positive_mm),
                         interp_held(x, self.axispos_mm, self.negative_mm))
        return -value


def load(path: str | os.PathLike, axis: str | None = None) -> HeidenhainComp:
    """Read a .COM table. Refused with line and field named: no BEGIN line or header, a row
    without the header's fields or with a non-number, AXISPOS not increasing, more than 256
    rows, no [END]."""
    path = Path(path)
    lines = read_lines(path)
    if not lines or not lines[0].strip().upper().startswith("BEGIN"):
        raise ControllerFileError(f"{path}, line 1: expected 'BEGIN <name>.COM MM', found {(lines[0] if lines else '')[:40]!r}")
    if len(lines) < 2:
        raise ControllerFileError(f"{path}, line 2: the header line (NR AXISPOS <axis> [BACKLASH]) is missing")
    header = lines[1].split()
    if "AXISPOS" not in header:
        raise ControllerFileError(f"{path}, line 2: no AXISPOS column in the header {lines[1].strip()!r}")
    axes = [h for h in header if h not in ("NR", "AXISPOS", "BACKLASH")]
    if axis is None:
        if len(axes) != 1:
            raise ControllerFileError(f"{path}, line 2: expected one axis column, found {axes}")
        axis = axes[0]
    if axis not in header:
        raise ControllerFileError(f"{path}, line 2: no column {axis!r} (columns {header})")
    pos, plus, minus, rows = [], [], [], []
    ended = False
    for no, raw in enumerate(lines[2:], start=3):
        if not raw.strip():
            continue
        if raw.strip().upper() == "[END]":
            ended = True
            break
        cells = raw.split()
        if len(cells) != len(header):
            raise ControllerFileError(f"{path}, line {no}: {len(cells)} field(s), the header has {len(header)} ({' '.join(header)})")
        row = dict(zip(header, cells))
        pos.append(number(path, no, "AXISPOS", row["AXISPOS"]))
        plus.append(number(path, no, axis, row[axis]))
        minus.append(number(path, no, "BACKLASH", row["BACKLASH"]) if "BACKLASH" in row else plus[-1])
        rows.append(no)
        if len(pos) > MAX_ROWS:
            raise ControllerFileError(f"{path}, line {no}: more than {MAX_ROWS} rows; the TNC refuses such a table")
    if not ended:
        raise ControllerFileError(f"{path}, line {len(lines)}: no [END] line (file cut short?)")
    if len(pos) < 2:
        raise ControllerFileError(f"{path}: {len(pos)} row(s); a table needs at least two")
    strictly_increasing(path, pos, rows, "AXISPOS")
    return HeidenhainComp(np.array(pos), np.array(plus), np.array(minus))
