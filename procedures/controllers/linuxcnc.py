"""LinuxCNC COMP_FILE: the writer (procedures.table, unchanged) and the rule LinuxCNC applies.

Source: LinuxCNC 2.9 `src/emc/motion/usrmotintf.cc::usrmotLoadComp` (reads `nominal a b` triplets
with sscanf until a line is not three numbers; type 0 converts to trims `nominal - a`,
`nominal - b`; type 1 takes them as trims), `src/emc/motion/command.c` (EMCMOT_SET_JOINT_COMP:
strictly increasing nominals, at most EMCMOT_COMP_SIZE = 256 entries, slopes between entries) and
`src/emc/motion/control.c::compute_screw_comp` (trim of the segment holding `pos_cmd`, linear
within it, forward trim while the commanded velocity is > 0, reverse while < 0, held when
stopped; the first and last entries hold beyond the table). The motor is commanded to
`pos_cmd + trim` (`backlash_filt`, the rate-limited trim).

Sign: the trim is added to the command, so a table that cancels an error e(x) (measured minus
commanded, procedures.table) holds trim = -e(x) (type 1) or actual = x + e(x) (type 0).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from procedures.controllers.common import ControllerFileError
from procedures.table import (LINUXCNC_LIMITS, LINUXCNC_MAX_LINES, CompTable, linuxcnc_paths, read_linuxcnc_comp,
                              write_linuxcnc_comp)

__all__ = ["LINUXCNC_LIMITS", "LINUXCNC_MAX_LINES", "LinuxCncComp", "linuxcnc_paths", "load", "write"]

NAME = "linuxcnc"
RESOLUTION_MM = 1e-6  # the writer's 6 decimals


@dataclass(frozen=True)
class LinuxCncComp:
    """A COMP_FILE as motmod holds it: nominal positions and the forward/reverse trims (mm)."""

    nominal_mm: np.ndarray
    forward_trim_mm: np.ndarray
    reverse_trim_mm: np.ndarray

    def trim_mm(self, position_mm, direction) -> np.ndarray:
        """The trim motmod adds to the command at `position_mm` reached moving in `direction`
        (+1: velocity > 0, forward trims; -1: reverse): linear within the segment, end entries
        held outside the table (compute_screw_comp)."""
        x = np.asarray(position_mm, dtype=float)
        d = np.broadcast_to(np.asarray(direction), np.broadcast(x, np.asarray(direction)).shape)
        x = np.broadcast_to(x, d.shape)
        fwd = np.interp(x, self.nominal_mm, self.forward_trim_mm)
        rev = np.interp(x, self.nominal_mm, self.reverse_trim_mm)
        return np.where(d > 0, fwd, rev)

    # the common reader interface of procedures.controllers
    applied_mm = trim_mm


def load(path: str | os.PathLike, comp_type: int = 0) -> LinuxCncComp:
    """Read a COMP_FILE the way usrmotLoadComp does (stops at the first line that is not three
    numbers) and keep only the entries command.c accepts (more than 256 or a nominal not above
    the previous one are refused there with an error; here they end the table likewise)."""
    try:
        nom, fwd, rev = read_linuxcnc_comp(path, comp_type)
    except FileNotFoundError:
        raise ControllerFileError(f"{path}: no such file") from None
    except UnicodeDecodeError:
        raise ControllerFileError(f"{path}: not a text file (a COMP_FILE holds three numbers per line)") from None
    if len(nom) == 0:
        raise ControllerFileError(f"{path}, line 1: not three numbers (nominal a b); LinuxCNC would stop reading "
                                  "there and load no compensation")
    keep = len(nom)
    for i in range(1, len(nom)):
        if nom[i] <= nom[i - 1]:
            keep = i
            break
    keep = min(keep, LINUXCNC_MAX_LINES)
    # sscanf reads "nan" and "inf" as numbers: LinuxCNC would load them and apply them
    bad = np.flatnonzero(~(np.isfinite(nom[:keep]) & np.isfinite(fwd[:keep]) & np.isfinite(rev[:keep])))
    if bad.size:
        raise ControllerFileError(f"{path}, line {bad[0] + 1}: a value that is not a finite number (nan or inf); "
                                  "LinuxCNC would apply it as a correction: write the table again")
    return LinuxCncComp(nom[:keep], fwd[:keep], rev[:keep])


def write(table: CompTable, out: str | os.PathLike, comp_type: int = 0, spec=None) -> list[Path]:
    """One COMP_FILE per leg (procedures.table.write_linuxcnc_comp)."""
    return write_linuxcnc_comp(table, out, comp_type, spec)
