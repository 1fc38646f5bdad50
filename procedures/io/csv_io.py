"""CSV interchange: measurements from other laser software in, session points out.

Format (shared/data/README.md): one row per measured point, comma separated, header first.
Required columns: leg, run, direction, target_mm, error_um. Optional: time_s, material_temp_c,
air_temp_c, air_pressure_hpa, humidity_pct, load_n, speed_mm_s (the signed speed of the axis at an
on-the-fly reading, mm/s, + while the position increases), co2_ppm (the CO2 content of the air, which the
session keeps beside /points: procedures/io/recording/columns.py). A missing optional column, or an empty /
"nan" cell in one, means "not measured" (NaN), never zero. `error_um` = measured minus
commanded, micrometres; `direction` +1 = approached while the position increased.

Import checks the whole file before anything is written and names file, line (the header is
line 1) and field of each problem; the session file is written under a temporary name and
renamed at the end, so a failed import leaves nothing behind. Export does the same.
Every number is checked against physical ranges (`procedures.io.ranges.PointLimits`): the legs
declared (a hexapod's 1-6 by default), targets within the drive's soft limits, |error_um|
within a micrometre sanity limit, temperatures, pressure, humidity, load and time in what a
workshop sees.
"""

from __future__ import annotations

import csv
import hashlib
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from procedures.io.atomic_outputs import atomic_path
from procedures.vocabulary import InputError
from procedures.io.outputs import check_output_file
from procedures.metrology.plausibility import check_points, settle_measured
from procedures.io.numbers import NotANumber, finite_float
from procedures.io.ranges import LEG_NUMBERS, PointLimits
from procedures.io.recording.columns import read_point_column, write_point_column
from procedures.io.recording.reader import Session, read_session
from procedures.io.recording.schema import FLAG_IMPORTED, POINT_DTYPE
from procedures.io.recording.writer import SessionWriter

REQUIRED_COLUMNS = ("leg", "run", "direction", "target_mm", "error_um")
OPTIONAL_COLUMNS = ("time_s", "material_temp_c", "air_temp_c", "air_pressure_hpa", "humidity_pct", "load_n",
                    "speed_mm_s")  # speed: signed axis speed at an on-the-fly reading (empty/absent: at rest)
INT_COLUMNS = ("leg", "run", "direction")
EXTRA_COLUMNS = ("co2_ppm",)
"""Optional columns that are not fields of /points but per-point datasets beside it."""
CO2_PPM_RANGE = (0.0, 5000.0)  # outdoor air ~420 ppm, a crowded room a few thousand
MAX_PROBLEMS_SHOWN = 5


def _software_version() -> str:
    try:
        from importlib.metadata import version

        return version("station")
    except Exception:  # not installed as a package: the recording still says so
        return "unknown"


class _Problems:
    """Collects problems so one run over a bad file reports several of them."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.items: list[str] = []

    def add(self, line: int | None, field: str | None, reason: str) -> None:
        where = [str(self.path)]
        if line is not None:
            where.append(f"line {line}")
        if field:
            where.append(f"field {field}")
        self.items.append(f"{', '.join(where)}: {reason}")

    def raise_if_any(self) -> None:
        if not self.items:
            return
        shown = self.items[:MAX_PROBLEMS_SHOWN]
        more = len(self.items) - len(shown)
        tail = f" (and {more} more problem{'s' if more > 1 else ''})" if more else ""
        raise InputError("; ".join(shown) + tail + "; nothing was written")


def _parse_int(text: str) -> int | None:
    try:
        return int(text)
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        return None
    return int(value) if value.is_integer() else None


def read_csv_points(csv_path: str | os.PathLike, limits: PointLimits | None = None,
                    extra: dict[str, np.ndarray] | None = None,
                    lines: list[int] | None = None) -> tuple[np.ndarray, list[str]]:
    """Parse and check an interchange CSV; return (POINT_DTYPE rows, optional columns present).

    Rows keep the file order and get `index` 0, 1, ...; commanded_mm = target_mm,
    measured_mm = target_mm + error_um / 1000, drive_position_mm and signal_pct unknown (NaN),
    flags FLAG_IMPORTED. Raises InputError naming file, line and field of every problem found
    (up to MAX_PROBLEMS_SHOWN): missing required column, unknown or repeated column, wrong
    number of fields, empty file, non-numeric or non-finite value, empty required value,
    direction not +1/-1, leg or run < 1, a run mixing directions, duplicate (leg, run, target),
    and a value outside `limits` (default `PointLimits()`: legs 1-6, the built-in drive
    profile's soft limits, the error sanity limit, workshop ranges of the optional columns).
    The columns of EXTRA_COLUMNS present go to `extra` (name -> one value per row, NaN = not
    measured) when it is given, and are listed in the returned optional columns. `lines`, when
    given, gets each row's line number in the file.
    """
    limits = limits or PointLimits()
    path = Path(csv_path)
    problems = _Problems(path)
    try:
        # utf-8-sig: spreadsheets often prepend a byte-order mark
        with open(path, newline="", encoding="utf-8-sig") as fh:
            reader = csv.reader(fh)
            header = None
            rows: list[tuple[int, list[str]]] = []
            for fields in reader:
                if not fields or all(not f.strip() for f in fields):
                    continue  # blank line
                if header is None:
                    header = [f.strip() for f in fields]
                    header_line = reader.line_num
                    continue
                rows.append((reader.line_num, fields))
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not a UTF-8 text file ({exc.reason} at byte {exc.start}); "
                         "save it as CSV (UTF-8)") from None
    except csv.Error as exc:
        raise InputError(f"{path}: not readable as CSV ({exc}); nothing was written") from None

    if header is None:
        raise InputError(f"{path}: the file is empty; expected a header line "
                         f"({','.join(REQUIRED_COLUMNS)}) and one row per point")
    if len(header) == 1 and header[0].count(";") >= 2:  # one field holding a whole header: not this layout
        raise InputError(f"{path}: line {header_line}: the file is semicolon-separated (header {header[0][:60]!r}); "
                         "the interchange CSV is comma-separated: import it with a map, `station import "
                         f"{path.name} --map MAP.toml` with [file] delimiter = \";\" (and decimal = \",\" for decimal "
                         "commas; docs/import.md, docs/import-maps/), or save it with commas; nothing was written")
    known = REQUIRED_COLUMNS + OPTIONAL_COLUMNS + EXTRA_COLUMNS
    seen: set[str] = set()
    for name in header:
        if name in seen:
            problems.add(header_line, name, "column appears twice")
        seen.add(name)
        if name not in known:
            hint = " (the file looks semicolon-separated; use commas)" if ";" in name else ""
            problems.add(header_line, name or "(empty)", f"unknown column{hint}; known columns: {', '.join(known)}")
    missing = [c for c in REQUIRED_COLUMNS if c not in seen]
    if missing:
        problems.add(header_line, None, f"missing required column{'s' if len(missing) > 1 else ''} "
                     f"{', '.join(missing)}; the header must name {', '.join(REQUIRED_COLUMNS)}")
    problems.raise_if_any()
    if not rows:
        raise InputError(f"{path}: the file has a header but no data rows; nothing was written")

    col = {name: i for i, name in enumerate(header)}
    optional = [c for c in OPTIONAL_COLUMNS + EXTRA_COLUMNS if c in col]
    extra_values = {c: np.full(len(rows), np.nan) for c in EXTRA_COLUMNS if c in col}
    out = np.zeros(len(rows), POINT_DTYPE)
    for name in POINT_DTYPE.names:
        if POINT_DTYPE[name].kind == "f":
            out[name] = np.nan
    run_direction: dict[tuple[int, int], tuple[int, int]] = {}
    first_at: dict[tuple[int, int, float], int] = {}
    for k, (line, fields) in enumerate(rows):
        if len(fields) != len(header):
            problems.add(line, None, f"{len(fields)} fields, but the header has {len(header)}")
            continue
        values: dict[str, float | int] = {}
        ok = True
        for name in REQUIRED_COLUMNS + tuple(optional):
            text = fields[col[name]].strip()
            required = name in REQUIRED_COLUMNS
            if text == "" or (not required and text.lower() == "nan"):
                if required:
                    problems.add(line, name, "empty; a value is required")
                    ok = False
                else:
                    values[name] = math.nan  # not measured
                continue
            if name in INT_COLUMNS:
                value = _parse_int(text)
                if value is None:
                    problems.add(line, name, f"{text!r} is not a whole number")
                    ok = False
                    continue
            else:
                try:
                    value = finite_float(text)
                except NotANumber as exc:
                    if exc.parsed is None:
                        problems.add(line, name, str(exc))
                    else:
                        what = "NaN (leave optional cells empty for 'not measured')" if math.isnan(exc.parsed) else "infinite"
                        problems.add(line, name, f"{text!r}: the value is {what}; a finite number is required")
                    ok = False
                    continue
            values[name] = value
        if not ok:
            continue
        leg, run, direction = int(values["leg"]), int(values["run"]), int(values["direction"])
        if direction not in (1, -1):
            problems.add(line, "direction", f"{direction} is not +1 or -1")
            ok = False
        for name, v in (("leg", leg), ("run", run)):
            if v < 1:
                problems.add(line, name, f"{v} is not allowed; {name} numbers start at 1")
                ok = False
        if not ok:
            continue
        for name, v in values.items():
            reason = limits.problem(name, v)
            if name == "co2_ppm" and not math.isnan(v) and not CO2_PPM_RANGE[0] <= v <= CO2_PPM_RANGE[1]:
                reason = f"{v:g} ppm is outside {CO2_PPM_RANGE[0]:g} .. {CO2_PPM_RANGE[1]:g} ppm (CO2 content of the air)"
            if reason:
                if name == "leg":
                    reason += " of a hexapod" if tuple(limits.legs) == LEG_NUMBERS else " declared for this import"
                problems.add(line, name, reason)
                ok = False
        if not ok:
            continue
        first = run_direction.setdefault((leg, run), (direction, line))
        if first[0] != direction:
            problems.add(line, "direction", f"run {run} of leg {leg} mixes directions ({first[0]:+d} from line "
                         f"{first[1]}, {direction:+d} here); each one-direction pass must be its own run")
        target = float(values["target_mm"])
        dup = first_at.setdefault((leg, run, target), line)
        if dup != line:
            problems.add(line, None, f"duplicate of line {dup} (leg {leg}, run {run}, target_mm {target!r})")
        r = out[k]
        r["index"] = k
        r["leg"], r["run"], r["direction"] = leg, run, direction
        r["target_mm"] = target
        r["commanded_mm"] = target
        r["error_um"] = values["error_um"]
        r["measured_mm"] = target + float(values["error_um"]) / 1000.0
        r["flags"] = FLAG_IMPORTED
        for name in optional:
            if name in extra_values:
                extra_values[name][k] = values[name]
            else:
                r[name] = values[name]
    problems.raise_if_any()
    if extra is not None:
        extra.update(extra_values)
    if lines is not None:
        lines.extend(line for line, _ in rows)
    return out, optional


def _check_out(path: Path, overwrite: bool) -> None:
    check_output_file(path, force=overwrite)  # the one overwrite rule (procedures/io/outputs.py)


def import_csv(
    csv_path: str | os.PathLike,
    h5_path: str | os.PathLike,
    *,
    operator: str = "",
    session_id: str | None = None,
    software_version: str | None = None,
    overwrite: bool = False,
    limits: PointLimits | None = None,
    accept_implausible: bool = False,
    warnings: list[str] | None = None,
    identity=None,
    station_config: dict | None = None,
    stage: str | None = None,
    started_utc: str | None = None,
) -> Session:
    """Convert an interchange CSV into a session file (rig "import"); return it as read back.

    The whole CSV is checked first (see read_csv_points; `limits`: the physical ranges); on any
    problem InputError is raised and no file is created. The plan metadata names the source
    file and its SHA-256, and the legs the points hold. Values that look like a unit slip (degF
    in a degC column, nm in the um column: procedures.metrology.plausibility) are imported with a warning
    line each in `warnings`; only a physically impossible one (an error larger than the travel the
    targets span) is refused the same way, unless `accept_implausible`.

    `identity(legs) -> dict` the session's /meta/identity for the legs the file holds (it may
    refuse: InputError, nothing written); `station_config` recorded as the session's (its
    [tolerances] and [metrology] decide and evaluate it); `stage` "calibration" / "verification"
    / "other" kept in the plan; `started_utc` when the measurement was made (else now).
    """
    csv_path, h5_path = Path(csv_path), Path(h5_path)
    if not csv_path.is_file():
        raise InputError(f"{csv_path}: no such file")
    _check_out(h5_path, overwrite)
    extra: dict[str, np.ndarray] = {}
    lines: list[int] = []
    points, optional = read_csv_points(csv_path, limits, extra, lines)
    notes = settle_measured(check_points(points, str(csv_path), lines), accept_implausible)
    if warnings is not None:
        warnings.extend(notes)
    sha = hashlib.sha256(csv_path.read_bytes()).hexdigest()
    plan = {
        "kind": "import",
        "source": csv_path.name,
        "source_sha256": sha,
        "optional_columns": optional,
        "legs": sorted({int(v) for v in points["leg"]}),
    }
    if stage:
        plan["stage"] = stage
    ident = identity(plan["legs"]) if callable(identity) else identity
    with atomic_path(h5_path) as tmp:
        with SessionWriter.create(
            tmp, session_id=session_id or f"import-{sha[:12]}", operator=operator, rig="import", plan=plan,
            station_config=station_config or {}, devices={"source": f"CSV file {csv_path.name}"},
            software_version=software_version or _software_version(), overwrite=True,
            **({"identity": ident} if ident else {}), **({"started_utc": started_utc} if started_utc else {}),
        ) as writer:
            writer.append_points(points)
            writer.finish("completed")
        for name, values in extra.items():  # closed, still at its temporary name
            write_point_column(tmp, name, values)
    return read_session(h5_path)


@dataclass(frozen=True)
class ExportSummary:
    """What `export_csv` wrote: rows, columns, and points left out (error unknown)."""

    path: Path
    rows: int
    columns: tuple[str, ...]
    skipped_no_error: int


def _fmt_float(value: float) -> str:
    return "" if math.isnan(value) else repr(float(value))  # repr: shortest text that round-trips


def export_csv(h5_path: str | os.PathLike, csv_path: str | os.PathLike, *, overwrite: bool = False) -> ExportSummary:
    """Write a session's points as an interchange CSV, in plan (index) order.

    Optional columns whose values are all unknown are left out; an unknown value in a column
    that is kept is an empty cell. Points without a measured error (NaN) are left out and
    counted. Floats are written with the shortest text that reads back to the same number.
    """
    h5_path, csv_path = Path(h5_path), Path(csv_path)
    session = read_session(h5_path)
    _check_out(csv_path, overwrite)
    order = np.argsort(session.points["index"], kind="stable")
    pts = session.points[order]
    extra = {}
    for name in EXTRA_COLUMNS:
        values = read_point_column(h5_path, name)
        if values is not None and len(values) == len(order):
            extra[name] = values[order]
    known = np.isfinite(pts["error_um"])
    skipped = int(np.count_nonzero(~known))
    pts = pts[known]
    extra = {name: v[known] for name, v in extra.items() if np.isfinite(v[known]).any()}
    if not len(pts):
        raise InputError(f"{h5_path}: no point with a measured error to export")
    columns = REQUIRED_COLUMNS + tuple(c for c in OPTIONAL_COLUMNS if np.isfinite(pts[c]).any()) + tuple(extra)
    with atomic_path(csv_path) as tmp:
        with open(tmp, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh, lineterminator="\n")
            w.writerow(columns)
            for i, r in enumerate(pts):
                w.writerow([str(int(r[c])) if c in INT_COLUMNS else _fmt_float(extra[c][i] if c in extra else r[c])
                            for c in columns])
            fh.flush()
            os.fsync(fh.fileno())
    return ExportSummary(path=csv_path, rows=len(pts), columns=columns, skipped_no_error=skipped)
