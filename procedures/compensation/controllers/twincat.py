"""Beckhoff TwinCAT CNC (ISG kernel): bilateral leadscrew error compensation list (kw.ssfk.*).

Sources: Beckhoff Information System, TwinCAT CNC "Axis compensation" (TF5200 / TX1270):
"Leadscrew error compensation" (infosys.beckhoff.com .../axiscompensation/15327297547.html):
the position setpoint is changed by a compensation value, linearly interpolated between
interpolation points; bilateral compensation has a table per direction on the same points; "the
value at the relevant end of the table is reused for axis positions outside the compensation
table". ISG kernel documentation "Example of a compensation value list"
(isg-stuttgart.de/kernel-html5/en-GB/113439115.html): `kw.ssfk.interval 0` (explicit
interpolation points), `kw.ssfk.kw_startpos`, `kw.ssfk.kw_nr_max`, `kw.ssfk.unit 1` (metric),
`kw.ssfk.bilateral 1`, `kw.ssfk.table[i].setpoint/.pos/.neg`, positions and values in 0.1 um;
the worked example gives programmed 19866.7 um, measured 19856.5 um (positive direction) ->
pos = -102 (x 0.1 um): the value is measured minus programmed. Comments: a line starting
with "# " (TwinCAT CNC "Comments in the ASCII file").

So pos/neg hold e(x) in 0.1 um and the CNC's correction is -value.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drivers.interfaces import TableSpec
from procedures.compensation.controllers.common import (ControllerFileError, by_direction, checked, interp_held, leg_errors_mm,
                                           leg_paths, read_lines, strictly_increasing, write_files)
from procedures.compensation.table import CompTable

NAME = "twincat"
# P-COMP-00059 sets the most table entries; 1500 by default (shared docs: real-world.md)
SUFFIX = ".lis"
STEM = "achskw{leg}"  # the file name TwinCAT NC expects per axis
UNIT_MM = 1e-4  # 0.1 um
RESOLUTION_MM = UNIT_MM
LIMITS = TableSpec(max_points=1500, max_correction_um=1000.0, entry_resolution_um=0.0, min_step_mm=1e-4,
                   banks=1, holder="TwinCAT CNC")


def text(t) -> str:
    pos, fwd, rev = leg_errors_mm(t)
    n = t.point_count
    setpoints = [round(x / UNIT_MM) for x in pos]
    lines = [
        f"# station: leg {t.leg}, bilateral leadscrew error compensation",
        "# positions and values in 0.1 um; values = measured minus programmed (the CNC subtracts them)",
        f"kopf.log_achs_nr                     {t.leg}",
        f"kopf.log_achs_name                   LEG{t.leg}",
        "kw.ssfk.interval                     0",
        f"kw.ssfk.kw_startpos                  {setpoints[0]}",
        f"kw.ssfk.kw_nr_max                    {n}",
        "kw.ssfk.unit                         1",
        "kw.ssfk.bilateral                    1",
    ]
    lines += [f"kw.ssfk.table[{i}].setpoint{'':<10}{s}" for i, s in enumerate(setpoints)]
    lines += [f"kw.ssfk.table[{i}].pos{'':<15}{round(v / UNIT_MM)}" for i, v in enumerate(fwd)]
    lines += [f"kw.ssfk.table[{i}].neg{'':<15}{round(v / UNIT_MM)}" for i, v in enumerate(rev)]
    return "\n".join(lines) + "\n"


def write(table: CompTable, out: str | os.PathLike, spec=None) -> list[Path]:
    """One compensation value list per leg (`OUT/achskw<N>.lis`, or `<name>_achskw<N>.lis`)."""
    checked(table, spec or LIMITS, out)
    paths = leg_paths(out, table.legs, SUFFIX, stem=STEM)
    return write_files(out, {paths[leg]: text(t) for leg, t in table.legs.items()}, SUFFIX)


@dataclass(frozen=True)
class TwinCatComp:
    setpoint_mm: np.ndarray
    pos_mm: np.ndarray
    neg_mm: np.ndarray

    def applied_mm(self, position_mm, direction) -> np.ndarray:
        x, d = by_direction(position_mm, direction)
        value = np.where(d > 0, interp_held(x, self.setpoint_mm, self.pos_mm), interp_held(x, self.setpoint_mm, self.neg_mm))
        return -value


_LINE = re.compile(r"^(kopf\.[a-z_]+|kw\.ssfk\.[a-z_]+|kw\.ssfk\.table\[(\d+)\]\.(setpoint|pos|neg))\s+(\S+)(\s+.*)?$")


def load(path: str | os.PathLike) -> TwinCatComp:
    """Read a kw.ssfk list. Refused with line and field named: an unknown or malformed entry,
    a non-integer value, unit other than 1 (metric 0.1 um), interval other than 0, a missing
    table entry, setpoints not increasing, kw_nr_max disagreeing with the table."""
    path = Path(path)
    head: dict[str, tuple[str, int]] = {}
    table: dict[str, dict[int, tuple[int, int]]] = {"setpoint": {}, "pos": {}, "neg": {}}
    for no, raw in enumerate(read_lines(path), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        m = _LINE.match(line)
        if not m:
            raise ControllerFileError(f"{path}, line {no}: {line[:60]!r} is not a kopf.* or kw.ssfk.* entry")
        key, index, field, value = m.group(1), m.group(2), m.group(3), m.group(4)
        if key == "kopf.log_achs_name":
            head[key] = (value, no)
            continue
        try:
            v = int(value)
        except ValueError:
            raise ControllerFileError(f"{path}, line {no}, field {key}: {value!r} is not an integer") from None
        if not -2**31 <= v < 2**31:  # the CNC's 32-bit integers (0.1 um): beyond them it is not a table
            raise ControllerFileError(f"{path}, line {no}, field {key}: {value[:20]!r}... is beyond a 32-bit integer")
        if index is not None:
            table[field][int(index)] = (v, no)
        else:
            head[key] = (value, no)
    for key, want in (("kw.ssfk.unit", "1"), ("kw.ssfk.interval", "0")):
        if key in head and head[key][0] != want:
            raise ControllerFileError(f"{path}, line {head[key][1]}, field {key}: {head[key][0]} is not supported "
                                      f"(expected {want}: metric 0.1 um, explicit interpolation points)")
    n = len(table["setpoint"])
    if n < 2:
        raise ControllerFileError(f"{path}: {n} kw.ssfk.table[i].setpoint entries; a table needs at least two")
    if "kw.ssfk.kw_nr_max" in head and int(head["kw.ssfk.kw_nr_max"][0]) != n:
        raise ControllerFileError(f"{path}, line {head['kw.ssfk.kw_nr_max'][1]}, field kw.ssfk.kw_nr_max: "
                                  f"{head['kw.ssfk.kw_nr_max'][0]} but the table has {n} setpoints")
    bilateral = head.get("kw.ssfk.bilateral", ("0", 0))[0] == "1"
    for field in ("setpoint", "pos") + (("neg",) if bilateral else ()):
        missing = [i for i in range(n) if i not in table[field]]
        if missing:
            raise ControllerFileError(f"{path}, field kw.ssfk.table[{missing[0]}].{field}: missing")
    sp = [table["setpoint"][i][0] * UNIT_MM for i in range(n)]
    strictly_increasing(path, sp, [table["setpoint"][i][1] for i in range(n)], "kw.ssfk.table[i].setpoint")
    pos = np.array([table["pos"][i][0] for i in range(n)]) * UNIT_MM
    neg = np.array([table["neg"][i][0] for i in range(n)]) * UNIT_MM if bilateral else pos
    return TwinCatComp(np.array(sp), pos, neg)
