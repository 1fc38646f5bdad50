"""Reading other laser software's CSV through a mapping file (TOML) into the interchange CSV.

A map says where each quantity is in the foreign file and how to read it (docs/import.md):

    [file]
    delimiter = ";"          # ",", ";", "\\t", "|" or "whitespace"
    decimal = ","            # "." or ","
    skip_lines = 3           # lines before the header (title blocks)
    header = true            # false: columns by index only
    comment = "#"            # lines starting with it are skipped (optional)

    [columns]                # a column name (string) or a 1-based index (integer)
    target = "Target"        # required
    error = "Error"          # or measured = "Actual" (error = measured - target)
    direction = "Dir"        # optional: else from the target order
    run = "Run"              # optional: else every pass is a run
    leg = "Axis"             # optional: else [defaults] leg
    air_temp_c = "Air"       # optional: any of time_s, material_temp_c, air_temp_c,
                             # air_pressure_hpa, humidity_pct, load_n, speed_mm_s, co2_ppm

    [units]
    target = "mm"            # mm, um, nm or inch
    error = "um"             # (also the unit of `measured`)

    [convention]
    error = "measured-nominal"   # or "nominal-measured" (the file's error column has the other sign)
    forward = ["+", "1", "fwd"]  # direction column values meaning approach in + (case-insensitive)
    reverse = ["-", "-1", "rev"]

    [defaults]
    leg = 1

Runs: whatever the source numbers, the interchange runs are numbered 1, 2, ... per leg in the
order the one-direction passes appear (a source run holding both directions becomes two runs).
Direction from the target order: a pass is a stretch of rows whose targets keep moving the same
way; its rows are approached in that direction.

Every problem is an InputError naming the map file and key, or the data file, line and column.
"""

from __future__ import annotations

import io
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from procedures.io.csv_io import EXTRA_COLUMNS, OPTIONAL_COLUMNS
from procedures.vocabulary import InputError
from procedures.io.numbers import parse_finite

UNITS_TO_MM = {"mm": 1.0, "um": 1e-3, "nm": 1e-6, "inch": 25.4}
DELIMITERS = {",": ",", ";": ";", "\t": "\t", "\\t": "\t", "tab": "\t", "|": "|", "whitespace": None}
ENV_COLUMNS = OPTIONAL_COLUMNS + EXTRA_COLUMNS
QUANTITIES = ("target", "error", "measured", "direction", "run", "leg") + ENV_COLUMNS
CONVENTIONS = ("measured-nominal", "nominal-measured")
_SECTIONS = {
    "file": {"delimiter", "decimal", "skip_lines", "header", "comment"},
    "columns": set(QUANTITIES),
    "units": {"target", "error"},
    "convention": {"error", "forward", "reverse"},
    "defaults": {"leg"},
    # who and what was measured (station/services/import_identity.py checks the values)
    "identity": {"serial", "part_number", "leg_type", "screw_lot", "station", "stage", "measured_utc",
                 "laser_model", "laser_serial", "laser_calibrated_on", "laser_calibration_due"},
}


@dataclass(frozen=True)
class ImportMap:
    path: Path
    delimiter: str | None = ","
    decimal: str = "."
    skip_lines: int = 0
    header: bool = True
    comment: str | None = None
    columns: dict[str, str | int] = field(default_factory=dict)
    target_unit: str = "mm"
    error_unit: str = "um"
    error_sign: float = 1.0  # +1: the file's error is measured - nominal
    forward: tuple[str, ...] = ("+", "+1", "1", "fwd", "forward", "up", "pos", "positive")
    reverse: tuple[str, ...] = ("-", "-1", "rev", "reverse", "backward", "down", "neg", "negative")
    default_leg: int | None = None
    identity: dict[str, Any] = field(default_factory=dict)  # [identity] as written


def _bad(path, key: str, reason: str) -> InputError:
    return InputError(f"{path}, key {key}: {reason}")


def load_map(path: str | os.PathLike) -> ImportMap:
    """Read and check a map file (TOML). Refused naming the file and key: not TOML, an unknown
    section or key, a wrong type, an unknown unit, delimiter or convention, neither `error` nor
    `measured` (or both), no `target`, a decimal comma with a comma delimiter."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{path}: no such map file") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not a TOML map file ({exc})") from None
    for section, body in data.items():
        if section not in _SECTIONS:
            raise _bad(path, section, f"unknown section; known: {', '.join(_SECTIONS)}")
        if not isinstance(body, dict):
            raise _bad(path, section, "must be a [section] table")
        for key in body:
            if key not in _SECTIONS[section]:
                raise _bad(path, f"{section}.{key}", f"unknown key; known: {', '.join(sorted(_SECTIONS[section]))}")
    f, cols = data.get("file", {}), data.get("columns", {})
    conv, defaults = data.get("convention", {}), data.get("defaults", {})

    def text(section, key, default):
        v = data.get(section, {}).get(key, default)
        if not isinstance(v, str):
            raise _bad(path, f"{section}.{key}", f"{v!r} must be a string")
        return v

    delimiter = text("file", "delimiter", ",")
    if delimiter not in DELIMITERS:
        raise _bad(path, "file.delimiter", f"{delimiter!r} is not one of {', '.join(map(repr, DELIMITERS))}")
    decimal = text("file", "decimal", ".")
    if decimal not in (".", ","):
        raise _bad(path, "file.decimal", f"{decimal!r} must be '.' or ','")
    if decimal == "," and DELIMITERS[delimiter] == ",":
        raise _bad(path, "file.decimal", "a decimal comma needs another delimiter (file.delimiter = \";\" or \"\\t\")")
    skip = f.get("skip_lines", 0)
    if isinstance(skip, bool) or not isinstance(skip, int) or skip < 0:
        raise _bad(path, "file.skip_lines", f"{skip!r} must be a whole number >= 0")
    header = f.get("header", True)
    if not isinstance(header, bool):
        raise _bad(path, "file.header", f"{header!r} must be true or false")
    comment = f.get("comment")
    if comment is not None and (not isinstance(comment, str) or not comment):
        raise _bad(path, "file.comment", f"{comment!r} must be a non-empty string")
    for key, ref in cols.items():
        if isinstance(ref, bool) or not isinstance(ref, (str, int)) or (isinstance(ref, int) and ref < 1) or ref == "":
            raise _bad(path, f"columns.{key}", f"{ref!r} must be a column name or a column number from 1")
        if isinstance(ref, str) and not header:
            raise _bad(path, f"columns.{key}", f"{ref!r} is a name but file.header = false: give the column number")
    if "target" not in cols:
        raise _bad(path, "columns.target", "missing: which column holds the nominal (target) position")
    if ("error" in cols) == ("measured" in cols):
        raise _bad(path, "columns.error", "give exactly one of columns.error (the deviation) or columns.measured "
                   "(the measured position)")
    for key in ("target", "error"):
        unit = text("units", key, "mm" if key == "target" else "um")
        if unit not in UNITS_TO_MM:
            raise _bad(path, f"units.{key}", f"{unit!r} is not one of {', '.join(UNITS_TO_MM)}")
    convention = text("convention", "error", "measured-nominal")
    if convention not in CONVENTIONS:
        raise _bad(path, "convention.error", f"{convention!r} is not one of {', '.join(CONVENTIONS)}")
    if "measured" in cols and convention != "measured-nominal":
        raise _bad(path, "convention.error", "applies to an error column (columns.error); with columns.measured "
                   "the error is always measured minus nominal")
    words = {}
    for key in ("forward", "reverse"):
        v = conv.get(key, list(getattr(ImportMap, key)))
        if not isinstance(v, list) or not v or not all(isinstance(w, (str, int)) for w in v):
            raise _bad(path, f"convention.{key}", "must be a list of the direction column's values")
        words[key] = tuple(str(w).strip().lower() for w in v)
    if set(words["forward"]) & set(words["reverse"]):
        raise _bad(path, "convention.reverse", f"{sorted(set(words['forward']) & set(words['reverse']))} also "
                   "listed under convention.forward")
    leg = defaults.get("leg")
    if leg is not None and (isinstance(leg, bool) or not isinstance(leg, int) or leg < 1):
        raise _bad(path, "defaults.leg", f"{leg!r} must be a leg number from 1")
    if "leg" not in cols and leg is None:
        raise _bad(path, "defaults.leg", "missing: the file has no leg column (columns.leg), so name the leg here")
    return ImportMap(path, DELIMITERS[delimiter], decimal, skip, header, comment, dict(cols),
                     text("units", "target", "mm"), text("units", "error", "um"),
                     1.0 if convention == "measured-nominal" else -1.0, words["forward"], words["reverse"], leg,
                     dict(data.get("identity", {})))


@dataclass(frozen=True)
class Converted:
    """The interchange CSV made from a foreign file, and the source line of each of its rows."""

    csv_text: str
    source_lines: tuple[int, ...]  # interchange data row k (line k + 2) came from this source line
    columns: dict[str, str]  # interchange column -> how the source names it (for messages)


def _split(line: str, m: ImportMap, path: Path, no: int) -> list[str]:
    if m.delimiter is None:
        return line.split()
    import csv

    try:
        return next(csv.reader(io.StringIO(line), delimiter=m.delimiter), [])
    except csv.Error as exc:
        raise InputError(f"{path}, line {no}: not readable as delimited text ({exc})") from None


def convert(data_path: str | os.PathLike, m: ImportMap) -> Converted:
    """Read the foreign file with map `m`; return the interchange CSV (leg, run, direction,
    target_mm, error_um and the mapped environment columns). Problems name the data file, its
    line and the source column (and the map key)."""
    path = Path(data_path)
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not a UTF-8 text file ({exc.reason} at byte {exc.start}); save it as UTF-8 text") from None
    body = [(no, line) for no, line in enumerate(lines, start=1) if no > m.skip_lines]
    body = [(no, line) for no, line in body if line.strip() and not (m.comment and line.lstrip().startswith(m.comment))]
    if not body:
        raise InputError(f"{path}: no lines after the {m.skip_lines} skipped line(s) (file.skip_lines in {m.path})")
    index: dict[str, int] = {}
    names: dict[str, str] = {}
    width = None
    if m.header:
        header_no, header_line = body.pop(0)
        header = [h.strip() for h in _split(header_line, m, path, header_no)]
        width = len(header)
    for key, ref in m.columns.items():
        if isinstance(ref, int):
            if m.header and ref > width:
                raise InputError(f"{path}, line {header_no}: the header has {width} columns, but {m.path} key "
                                 f"columns.{key} asks for column {ref}")
            index[key], names[key] = ref - 1, f"column {ref}"
        else:
            if ref not in header:
                raise InputError(f"{path}, line {header_no}: no column {ref!r} (map {m.path}, key columns.{key}); "
                                 f"the header has {', '.join(repr(h) for h in header)}")
            index[key], names[key] = header.index(ref), f"column {ref!r}"
    if not body:
        raise InputError(f"{path}: no data rows after the header")
    rows = []
    for no, line in body:
        cells = [c.strip() for c in _split(line, m, path, no)]
        if width is not None and len(cells) != width:
            raise InputError(f"{path}, line {no}: {len(cells)} fields, but the header has {width}")
        need = max(index.values()) + 1
        if len(cells) < need:
            raise InputError(f"{path}, line {no}: {len(cells)} fields, but the map reads column {need}")

        def num(key):
            cell = cells[index[key]]
            hint = " (decimal comma? set file.decimal = \",\")" if m.decimal == "." and "," in cell else ""
            return parse_finite(cell, f"{path}, line {no}, {names[key]} (map key columns.{key})", hint=hint,
                                decimal_comma=m.decimal == ",")

        def whole(key):
            v = num(key)
            if not v.is_integer():
                raise InputError(f"{path}, line {no}, {names[key]} (map key columns.{key}): {cells[index[key]]!r} is not a whole number")
            return int(v)

        target_mm = num("target") * UNITS_TO_MM[m.target_unit]
        if "error" in index:
            error_um = m.error_sign * num("error") * UNITS_TO_MM[m.error_unit] * 1000.0
        else:
            error_um = (num("measured") * UNITS_TO_MM[m.error_unit] - target_mm) * 1000.0
        direction = None
        if "direction" in index:
            word = cells[index["direction"]].lower()
            if word in m.forward:
                direction = 1
            elif word in m.reverse:
                direction = -1
            else:
                raise InputError(f"{path}, line {no}, {names['direction']} (map key columns.direction): "
                                 f"{cells[index['direction']]!r} is neither a forward {list(m.forward)} nor a "
                                 f"reverse {list(m.reverse)} value (convention.forward / convention.reverse)")
        env = {}
        for key in ENV_COLUMNS:
            if key in index:
                cell = cells[index[key]]
                env[key] = "" if cell == "" else repr(num(key))
        rows.append({"line": no, "leg": whole("leg") if "leg" in index else m.default_leg,
                     "run": whole("run") if "run" in index else None, "direction": direction,
                     "target_mm": target_mm, "error_um": error_um, "env": env})
    _directions_from_order(path, rows)
    _number_runs(rows)
    env_cols = [k for k in ENV_COLUMNS if k in index]
    out = io.StringIO()
    out.write(",".join(["leg", "run", "direction", "target_mm", "error_um", *env_cols]) + "\n")
    for r in rows:
        out.write(",".join([str(r["leg"]), str(r["run"]), f"{r['direction']:+d}", repr(r["target_mm"]),
                            repr(r["error_um"]), *(r["env"][k] for k in env_cols)]) + "\n")
    interchange_names = {"target_mm": names["target"], "error_um": names.get("error", names.get("measured")),
                         **{k: names[k] for k in ("leg", "run", "direction") if k in names},
                         **{k: names[k] for k in env_cols}}
    return Converted(out.getvalue(), tuple(r["line"] for r in rows), interchange_names)


def _directions_from_order(path: Path, rows: list[dict]) -> None:
    """Rows without a direction: a pass keeps its targets moving one way (per leg and source
    run); its rows were approached that way."""
    if all(r["direction"] is not None for r in rows):
        return
    i = 0
    while i < len(rows):
        j = i + 1
        key = (rows[i]["leg"], rows[i]["run"])
        step = 0.0
        while j < len(rows) and (rows[j]["leg"], rows[j]["run"]) == key:
            d = rows[j]["target_mm"] - rows[j - 1]["target_mm"]
            if d == 0 or (step and (d > 0) != (step > 0)):
                break
            step = d
            j += 1
        if step == 0:
            raise InputError(f"{path}, line {rows[i]['line']}: cannot tell the approach direction from the target "
                             "order (a pass of one point, or a repeated target); map a direction column "
                             "(columns.direction)")
        for r in rows[i:j]:
            r["direction"] = 1 if step > 0 else -1
        i = j


def _number_runs(rows: list[dict]) -> None:
    """Runs 1, 2, ... per leg, one per one-direction pass in the order passes appear. A pass ends
    where the leg, the source run or the direction changes, or where the target stops moving in
    the pass's direction (the next pass starts over)."""
    count: dict[int, int] = {}
    prev = None
    for r in rows:
        key = (r["leg"], r["run"], r["direction"])
        restart = prev is not None and key == prev[0] and (r["target_mm"] - prev[1]) * r["direction"] <= 0
        if key != (prev[0] if prev else None) or restart:
            count[r["leg"]] = count.get(r["leg"], 0) + 1
        r["run"] = count[r["leg"]]
        prev = (key, r["target_mm"])


def source_message(message: str, tmp_csv: Path, data_path: Path, conv: Converted) -> str:
    """An interchange-level problem (procedures.io.csv_io) in terms of the source file: its path,
    its line numbers and its column names."""
    import re

    def line(m):
        k = int(m.group(1)) - 2
        return f"line {conv.source_lines[k]}" if 0 <= k < len(conv.source_lines) else m.group(0)

    out = message.replace(str(tmp_csv), str(data_path))
    out = re.sub(r"line (\d+)", line, out)

    def field(m):
        name = m.group(1)
        return f"field {name} ({conv.columns[name]})" if name in conv.columns else m.group(0)

    return re.sub(r"field (\w+)", field, out)
