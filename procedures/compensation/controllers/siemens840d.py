"""Siemens SINUMERIK 840D sl: leadscrew error compensation as NC init programs.

Sources (SINUMERIK 840D sl / 828D Extended Functions, Function Manual K3 "Compensations",
6FC5397-1BP40-3BA1 (03/2013) section 4.4, and 6FC5397-1BP20-0BA0 (09/2009) section 5.4):
- MSEC/LEC `$AA_ENC_COMP[e,N,AXi]` with `$AA_ENC_COMP_STEP`, `_MIN`, `_MAX`, `_IS_MODULO`: values
  in mm; "A positive compensation value causes the corresponding machine axis to move in the
  negative direction"; linear interpolation between interpolation points; the first and last
  values stay active beyond the table; "the compensation value at the reference point should
  be zero" (no jump when compensation switches on after referencing). One table for both
  directions.
- Direction-dependent compensation with CEC tables: `$AN_CEC[t,N]`, `$AN_CEC_INPUT_AXIS[t]`
  (base axis), `$AN_CEC_OUTPUT_AXIS[t]` (compensated axis), `$AN_CEC_STEP/_MIN/_MAX[t]`,
  `$AN_CEC_DIRECTION[t]` = 1 (table acts only while the base axis moves in +), -1 (only in -),
  0 (both); tables of the same axis add up; below MIN the first value, above MAX the last.
  Table sizes: MD18342 $MN_MM_CEC_MAX_POINTS[t] (828D: 200 points per table).

Written here (mode "cec", default): per leg N two tables, t = 2(N-1) (DIRECTION 1, the error
approaching in +) and t+1 (DIRECTION -1, approaching in -), base and compensated axis AXN.
Mode "enc_comp": one `$AA_ENC_COMP[0,N,AXN]` table holding the mean of both directions (leaves
+/- half the reversal). Values are the error e(x) (measured minus commanded) in mm, shifted so
that the forward value at the reference point is 0; the sign follows the MSEC rule above (we
apply the same rule to the CEC tables: the manual states it for MSEC; check it on the machine
with one point). The controller's correction at x is then -(e(x) - e_fwd(reference)).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from procedures.compensation.controllers.common import (ControllerFileError, by_direction, checked, interp_held, leg_errors_mm,
                                           leg_paths, number, read_lines, write_files)
from drivers.interfaces import TableSpec
from procedures.compensation.table import CompTable

NAME = "siemens840d"
SUFFIX = ".ini"
RESOLUTION_MM = 1e-6  # 6 decimals; the control rounds to its internal resolution (MD10200 INT_INCR_PER_MM)
LIMITS = TableSpec(max_points=2000, max_correction_um=1000.0, entry_resolution_um=0.0,
                                   min_step_mm=1e-6, banks=1, holder="SINUMERIK (MD18342 / MD38000)")
MODES = ("cec", "enc_comp")
MAX_POINTS_READ = 100_000  # far above any NC's table; guards the reader against absurd MIN/MAX/STEP


def reference_shift_mm(t, reference_mm: float) -> float:
    """e_fwd at the reference point (mm): subtracted from every value so the table is 0 there."""
    pos, fwd, _ = leg_errors_mm(t)
    return float(np.interp(reference_mm, pos, fwd))


def text(t, mode: str = "cec", reference_mm: float = 0.0) -> str:
    if mode not in MODES:
        raise ControllerFileError(f"Siemens mode must be one of {', '.join(MODES)}, got {mode!r}")
    pos, fwd, rev = leg_errors_mm(t)
    shift = reference_shift_mm(t, reference_mm)
    leg, ax = t.leg, f"AX{t.leg}"
    about = [  # after the file's %_N_ line, which must come first
        f"; station: leg {leg} -> axis {ax}, {t.point_count} points {t.start_mm:.6f} .. {t.end_mm:.6f} mm",
        "; values: error measured minus commanded, mm; a positive value moves the axis negative",
        f"; shifted by {-shift:+.6f} mm so that the + value at the reference point {reference_mm:g} mm is zero",
    ]
    step, lo, hi = f"{t.step_mm:.6f}", f"{t.start_mm:.6f}", f"{t.end_mm:.6f}"
    if mode == "cec":
        lines = ["%_N_NC_CEC_INI", *about, "CHANDATA(1)"]
        for k, (direction, values) in enumerate(((1, fwd), (-1, rev))):
            tab = 2 * (leg - 1) + k
            lines += [f"$AN_CEC[{tab},{i}]={v - shift:.6f}" for i, v in enumerate(values)]
            lines += [f"$AN_CEC_INPUT_AXIS[{tab}]=({ax})", f"$AN_CEC_OUTPUT_AXIS[{tab}]=({ax})",
                      f"$AN_CEC_STEP[{tab}]={step}", f"$AN_CEC_MIN[{tab}]={lo}", f"$AN_CEC_MAX[{tab}]={hi}",
                      f"$AN_CEC_DIRECTION[{tab}]={direction}", f"$AN_CEC_MULT_BY_TABLE[{tab}]=0",
                      f"$AN_CEC_IS_MODULO[{tab}]=0"]
    else:
        lines = ["%_N_AX_EEC_INI", *about, "CHANDATA(1)"]
        lines += [f"$AA_ENC_COMP[0,{i},{ax}]={(f + r) / 2 - shift:.6f}" for i, (f, r) in enumerate(zip(fwd, rev))]
        lines += [f"$AA_ENC_COMP_STEP[0,{ax}]={step}", f"$AA_ENC_COMP_MIN[0,{ax}]={lo}",
                  f"$AA_ENC_COMP_MAX[0,{ax}]={hi}", f"$AA_ENC_COMP_IS_MODULO[0,{ax}]=0"]
    lines.append("M17")
    return "\n".join(lines) + "\n"


def write(table: CompTable, out: str | os.PathLike, mode: str = "cec", reference_mm: float = 0.0,
          spec=None) -> list[Path]:
    """One init program per leg (`OUT/leg<N>.ini`, or `<name>_leg<N>.ini` for OUT ending in .ini)."""
    checked(table, spec or LIMITS, out)
    paths = leg_paths(out, table.legs, SUFFIX)
    return write_files(out, {paths[leg]: text(t, mode, reference_mm) for leg, t in table.legs.items()}, SUFFIX)


@dataclass(frozen=True)
class _Table:
    values: np.ndarray
    start_mm: float
    step_mm: float
    direction: int  # 1, -1 or 0 (both)

    def at(self, x) -> np.ndarray:
        nodes = self.start_mm + self.step_mm * np.arange(self.values.size)
        return interp_held(x, nodes, self.values)


@dataclass(frozen=True)
class SiemensComp:
    """The tables of one axis as the NC applies them."""

    tables: tuple[_Table, ...]

    def value_mm(self, position_mm, direction) -> np.ndarray:
        """The summed compensation value of the tables active in `direction`."""
        x, d = by_direction(position_mm, direction)
        total = np.zeros(x.shape)
        for t in self.tables:
            active = (d == t.direction) | (t.direction == 0)
            total = total + np.where(active, t.at(x), 0.0)
        return total

    def applied_mm(self, position_mm, direction) -> np.ndarray:
        """A positive value moves the axis negative: the correction is -value."""
        return -self.value_mm(position_mm, direction)


_ASSIGN = re.compile(r"^\$(AN_CEC|AA_ENC_COMP)(_[A-Z_]+)?\[([^\]]*)\]\s*=\s*(.+)$")


def load(path: str | os.PathLike, axis: str | None = None) -> SiemensComp:
    """Read CEC and/or $AA_ENC_COMP tables from an init program (comments `;`), for `axis`
    (e.g. "AX1"; default: the only axis in the file). Refused with line and field named:
    unknown or malformed assignments, tables whose point count disagrees with MIN/MAX/STEP,
    CEC tables whose input and output axes differ, a DIRECTION other than -1/0/1."""
    path = Path(path)
    cec: dict[int, dict] = {}
    enc: dict[str, dict] = {}
    for no, raw in enumerate(read_lines(path), start=1):
        line = raw.split(";", 1)[0].strip()
        if not line or line.startswith("%") or line in ("M17", "M30") or line.startswith("CHANDATA"):
            continue
        m = _ASSIGN.match(line)
        if not m:
            raise ControllerFileError(f"{path}, line {no}: {raw.strip()[:60]!r} is not a $AN_CEC or $AA_ENC_COMP assignment")
        base, field, index, value = m.group(1), m.group(2) or "", [s.strip() for s in m.group(3).split(",")], m.group(4).strip()
        name = f"${base}{field}"
        if base == "AN_CEC":
            try:
                tab = int(index[0])
            except ValueError:
                raise ControllerFileError(f"{path}, line {no}, field {name}: table index {index[0]!r} is not a number") from None
            d = cec.setdefault(tab, {"values": {}, "line": no})
            if field == "":
                if len(index) != 2 or not index[1].isdigit():
                    raise ControllerFileError(f"{path}, line {no}, field {name}: expected [table,point]")
                d["values"][int(index[1])] = number(path, no, name, value)
            elif field in ("_INPUT_AXIS", "_OUTPUT_AXIS"):
                d[field] = value.strip("()").strip()
            elif field in ("_STEP", "_MIN", "_MAX", "_DIRECTION", "_MULT_BY_TABLE", "_IS_MODULO"):
                d[field] = number(path, no, name, value)
                d[field + "_line"] = no
            else:
                raise ControllerFileError(f"{path}, line {no}, field {name}: unknown CEC variable")
        else:
            ax = index[-1]
            d = enc.setdefault(ax, {"values": {}, "line": no})
            if field == "":
                if len(index) != 3 or not index[1].isdigit():
                    raise ControllerFileError(f"{path}, line {no}, field {name}: expected [encoder,point,axis]")
                d["values"][int(index[1])] = number(path, no, name, value)
            elif field in ("_STEP", "_MIN", "_MAX", "_IS_MODULO"):
                d[field] = number(path, no, name, value)
            else:
                raise ControllerFileError(f"{path}, line {no}, field {name}: unknown $AA_ENC_COMP variable")
    tables_by_axis: dict[str, list[_Table]] = {}
    for tab, d in sorted(cec.items()):
        where = f"{path}, CEC table {tab} (line {d['line']})"
        for key in ("_INPUT_AXIS", "_OUTPUT_AXIS", "_STEP", "_MIN", "_MAX"):
            if key not in d:
                raise ControllerFileError(f"{where}: $AN_CEC{key}[{tab}] is missing")
        if d["_INPUT_AXIS"] != d["_OUTPUT_AXIS"]:
            raise ControllerFileError(f"{where}, field $AN_CEC_OUTPUT_AXIS: {d['_OUTPUT_AXIS']} differs from the input "
                                      f"axis {d['_INPUT_AXIS']}; a leadscrew table compensates its own axis")
        direction = int(d.get("_DIRECTION", 0))
        if direction not in (-1, 0, 1) or direction != d.get("_DIRECTION", 0):
            raise ControllerFileError(f"{path}, line {d['_DIRECTION_line']}, field $AN_CEC_DIRECTION: "
                                      f"{d['_DIRECTION']:g} is not -1, 0 or 1")
        if d.get("_IS_MODULO", 0) or d.get("_MULT_BY_TABLE", 0):
            raise ControllerFileError(f"{where}: modulo or multiplied tables are not a leadscrew table")
        values = _points(where, d)
        tables_by_axis.setdefault(d["_INPUT_AXIS"], []).append(_Table(values, d["_MIN"], d["_STEP"], direction))
    for ax, d in enc.items():
        where = f"{path}, $AA_ENC_COMP of {ax} (line {d['line']})"
        for key in ("_STEP", "_MIN", "_MAX"):
            if key not in d:
                raise ControllerFileError(f"{where}: $AA_ENC_COMP{key} is missing")
        tables_by_axis.setdefault(ax, []).append(_Table(_points(where, d), d["_MIN"], d["_STEP"], 0))
    if not tables_by_axis:
        raise ControllerFileError(f"{path}: no $AN_CEC or $AA_ENC_COMP table in the file")
    if axis is None:
        if len(tables_by_axis) > 1:
            raise ControllerFileError(f"{path}: tables for axes {sorted(tables_by_axis)}; name the axis")
        axis = next(iter(tables_by_axis))
    if axis not in tables_by_axis:
        raise ControllerFileError(f"{path}: no table for axis {axis} (the file has {sorted(tables_by_axis)})")
    return SiemensComp(tuple(tables_by_axis[axis]))


def _points(where: str, d: dict) -> np.ndarray:
    if not d["values"]:
        raise ControllerFileError(f"{where}: no compensation values")
    if d["_STEP"] <= 0:
        raise ControllerFileError(f"{where}, field STEP: {d['_STEP']:g} is not a positive step")
    span = (d["_MAX"] - d["_MIN"]) / d["_STEP"]
    if not 0 <= span <= MAX_POINTS_READ:
        raise ControllerFileError(f"{where}: MIN {d['_MIN']:g}, MAX {d['_MAX']:g} and STEP {d['_STEP']:g} give no "
                                  f"table of 1 .. {MAX_POINTS_READ} points")
    n = int(round(span)) + 1
    have = sorted(d["values"])
    if have != list(range(n)):
        raise ControllerFileError(f"{where}: MIN/MAX/STEP give {n} points but the values are numbered "
                                  f"{have[0]}..{have[-1]} ({len(have)} values)")
    return np.array([d["values"][i] for i in range(n)])
