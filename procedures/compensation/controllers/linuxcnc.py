"""LinuxCNC COMP_FILE: the writer, the reader and the rule LinuxCNC applies.

The file (`write_linuxcnc_comp`): one `[JOINT_n] COMP_FILE` per leg (leg N -> joint N-1),
three numbers per line in machine units (mm), no header or comment (LinuxCNC's parser stops
silently at the first line that is not three numbers), at most 256 lines, strictly increasing
nominal positions.
COMP_FILE_TYPE 0: `nominal  actual_moving_+  actual_moving_-`, where actual = nominal + error;
COMP_FILE_TYPE 1: `nominal  forward_trim  reverse_trim`, where trim = -error.
(LinuxCNC converts type 0 to trims as nominal - actual and commands the motor at position +
trim, so both cancel the error; see docs/tables.md.) Validated first, written atomically: on
any error nothing is written.

Source: LinuxCNC 2.9 `src/emc/motion/usrmotintf.cc::usrmotLoadComp` (reads `nominal a b` triplets
with sscanf until a line is not three numbers; type 0 converts to trims `nominal - a`,
`nominal - b`; type 1 takes them as trims), `src/emc/motion/command.c` (EMCMOT_SET_JOINT_COMP:
strictly increasing nominals, at most EMCMOT_COMP_SIZE = 256 entries, slopes between entries) and
`src/emc/motion/control.c::compute_screw_comp` (trim of the segment holding `pos_cmd`, linear
within it, forward trim while the commanded velocity is > 0, reverse while < 0, held when
stopped; the first and last entries hold beyond the table). The motor is commanded to
`pos_cmd + trim` (`backlash_filt`, the rate-limited trim).

Sign: the trim is added to the command, so a table that cancels an error e(x) (measured minus
commanded, procedures.compensation.table) holds trim = -e(x) (type 1) or actual = x + e(x) (type 0).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Iterable

import numpy as np

from drivers.interfaces import TableSpec
from procedures.compensation.controllers.common import ControllerFileError
from procedures.compensation.table import CompTable, LegTable, TableValidationError, validate_table, write_table_files

__all__ = ["LINUXCNC_LIMITS", "LINUXCNC_MAX_LINES", "LinuxCncComp", "linuxcnc_paths", "linuxcnc_text", "load",
           "read_linuxcnc_comp", "write", "write_linuxcnc_comp"]

NAME = "linuxcnc"
RESOLUTION_MM = 1e-6  # the writer's 6 decimals
LINUXCNC_MAX_LINES = 256
LINUXCNC_LIMITS = TableSpec(max_points=LINUXCNC_MAX_LINES, max_correction_um=1000.0, entry_resolution_um=0.0,
                            min_step_mm=1e-6, banks=1, holder="LinuxCNC")
"""LinuxCNC: at most 256 lines per COMP_FILE; no documented correction limit (1 mm here)."""


def linuxcnc_paths(out: str | os.PathLike, legs: Iterable[int]) -> dict[int, Path]:
    """COMP_FILE path per leg: `OUT/joint<N-1>.comp` for a directory OUT, or
    `<stem>_joint<N-1>.comp` beside OUT when OUT ends in `.comp`."""
    out = Path(out)
    if out.suffix == ".comp":
        return {leg: out.with_name(f"{out.stem}_joint{leg - 1}.comp") for leg in legs}
    return {leg: out / f"joint{leg - 1}.comp" for leg in legs}


def linuxcnc_text(t: LegTable, comp_type: int = 0) -> str:
    """One COMP_FILE: `nominal a b` per line in mm (see the module docstring for a, b)."""
    if comp_type not in (0, 1):
        raise TableValidationError(f"LinuxCNC COMP_FILE_TYPE must be 0 or 1, got {comp_type}")
    lines = []
    for x, f, r in zip(t.positions_mm, t.error_fwd_um, t.error_rev_um):
        if comp_type == 0:
            a, b = x + f / 1000.0, x + r / 1000.0  # where the joint actually is, moving + / -
        else:
            a, b = -f / 1000.0, -r / 1000.0  # trims LinuxCNC adds to the command
        lines.append(f"{x:.6f} {a:.6f} {b:.6f}")
    return "\n".join(lines) + "\n"


def write_linuxcnc_comp(table: CompTable, out: str | os.PathLike, comp_type: int = 0,
                        spec: TableSpec | None = None) -> list[Path]:
    """Write one LinuxCNC COMP_FILE per leg (paths: `linuxcnc_paths`). A directory OUT is
    created if missing. Nothing is written when any leg fails validation (more than 256
    lines, beyond `spec`)."""
    spec = spec or LINUXCNC_LIMITS
    if spec.max_points > LINUXCNC_MAX_LINES or spec.holder != "LinuxCNC":
        spec = replace(spec, max_points=min(spec.max_points, LINUXCNC_MAX_LINES), holder="LinuxCNC")
    validate_table(table, spec, where=str(out))
    if comp_type not in (0, 1):
        raise TableValidationError(f"LinuxCNC COMP_FILE_TYPE must be 0 or 1, got {comp_type}")
    paths = linuxcnc_paths(out, table.legs)
    texts = {paths[leg]: linuxcnc_text(t, comp_type) for leg, t in table.legs.items()}
    out = Path(out)
    if out.suffix != ".comp":
        out.mkdir(parents=True, exist_ok=True)
    return write_table_files(texts)


def read_linuxcnc_comp(path: str | os.PathLike, comp_type: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A COMP_FILE as LinuxCNC loads it: (nominal_mm, forward_trim_mm, reverse_trim_mm).
    Type 0 lines are converted as LinuxCNC does (trim = nominal - actual). Reading stops at the
    first line that is not three numbers, as LinuxCNC's does (a line that is not text, too)."""
    nom, fwd, rev = [], [], []
    # bytes that are not UTF-8 become U+FFFD, which no number parses: reading stops there
    for line in Path(path).read_text(encoding="utf-8", errors="replace").splitlines():
        parts = line.split()
        if len(parts) < 3:
            break
        try:
            n, a, b = (float(p) for p in parts[:3])
        except ValueError:
            break
        if comp_type == 0:
            a, b = n - a, n - b
        nom.append(n)
        fwd.append(a)
        rev.append(b)
    return np.array(nom), np.array(fwd), np.array(rev)


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

    # the common reader interface of procedures.compensation.controllers
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


write = write_linuxcnc_comp  # the common writer name of procedures.compensation.controllers
