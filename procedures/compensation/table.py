"""Compensation tables: a model resampled on a fixed step, written for a drive (CSV).

A table holds, per leg, the predicted error (measured minus commanded, um) at
`start_mm + i * step_mm` when the target is approached in the positive (`error_fwd_um`) and the
negative (`error_rev_um`) direction. The controller *subtracts* these from the command.

Formats
- CSV (`write_table_csv` / `read_table_csv`): header `leg,position_mm,error_fwd_um,error_rev_um`,
  rows sorted by leg then position, a fixed step per leg. Before the header, optional comment
  lines (`#`); `# leg_serial: 3=HX-0042` names the serial of the leg the table was made for
  (from the model's identity), which a push checks (procedures/compensation/push.py). Tables without it
  are read as before. The first line is the integrity record (procedures/io/integrity.py):
  `# integrity: table rows=N sha256=...`; a table whose record does not match (cut, edited) is
  refused; one without a record (made by hand) only when complete (`CompTable.integrity`
  "unverified": whole rows, even steps here; the stroke covered at the push, `check_covers_stroke`).
- LinuxCNC COMP_FILEs and the other controllers' formats: procedures/compensation/controllers/ (one module
  each, LinuxCNC's in linuxcnc.py).

Every writer validates first and writes through a temporary file renamed into place, so on
any error nothing is written. Readers name the file, row and field of the first problem.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Iterable, Iterator, Mapping

import numpy as np

from drivers.errors import TableRefused
from drivers.interfaces import DriveLimits, TableBank, TableSpec
from procedures.io.atomic_outputs import write_files_atomic
from procedures.vocabulary import InputError
from procedures.io.recording.identity import model_leg_serials
from procedures.io.numbers import parse_finite
from procedures.io.integrity import (
    UNVERIFIED,
    VERIFIED,
    IntegrityError,
    check_csv_record,
    last_line_whole,
    split_csv_record,
    with_csv_record,
    wrong_kind,
)

CSV_HEADER = ("leg", "position_mm", "error_fwd_um", "error_rev_um")
SPACING_TOL_MM = 1e-5  # positions are written to 1e-6 mm: steps may differ by rounding only
_STEP_QUANTUM_MM = 1e-3  # suggested steps in messages are rounded up to whole micrometres
_AUTO_STEP_QUANTUM_MM = 1e-6  # automatic steps: whole nanometres, the drive's spacing unit


class TableValidationError(InputError):
    """A table file is malformed (the message names file, row and field). A table that is
    well formed but does not fit the drive is refused with drivers.errors.TableRefused."""


DEFAULT_SPEC = TableSpec()
"""The built-in drive profile's table (drivers/modbus/profiles/default.toml [table])."""



@dataclass(frozen=True)
class LegTable:
    """One leg's table: `error_*_um[i]` at `start_mm + i * step_mm`."""

    leg: int
    start_mm: float
    step_mm: float
    error_fwd_um: tuple[float, ...]
    error_rev_um: tuple[float, ...]
    rows: tuple[int, ...] | None = None  # the file's row of each point, when read from a CSV (for messages)

    def point_name(self, i: int) -> str:
        """Point i (0-based) as messages name it: its file row when read from one, and its position."""
        x = self.start_mm + i * self.step_mm
        return f"row {self.rows[i]} ({x:+.4f} mm)" if self.rows and i < len(self.rows) else f"point {i + 1} ({x:+.4f} mm)"

    @property
    def point_count(self) -> int:
        return len(self.error_fwd_um)

    @property
    def positions_mm(self) -> np.ndarray:
        return self.start_mm + self.step_mm * np.arange(self.point_count)

    @property
    def end_mm(self) -> float:
        return self.start_mm + self.step_mm * (self.point_count - 1)

    def to_bank(self) -> TableBank:
        """As a drivers.interfaces.TableBank (checksum left 0: the pusher computes it)."""
        return TableBank(self.start_mm, self.step_mm, tuple(self.error_fwd_um), tuple(self.error_rev_um))

    def correction_um(self, position_mm, direction) -> np.ndarray:
        """The table's error at `position_mm` (linear interpolation, end values held outside),
        for approach `direction` +1/-1 (broadcast)."""
        x = np.asarray(position_mm, dtype=float)
        d = np.broadcast_to(np.asarray(direction), np.broadcast(x, np.asarray(direction)).shape)
        x = np.broadcast_to(x, d.shape)
        pos = self.positions_mm
        fwd = np.interp(x, pos, self.error_fwd_um)
        rev = np.interp(x, pos, self.error_rev_um)
        return np.where(d > 0, fwd, rev)


@dataclass(frozen=True)
class CompTable:
    """Tables of several legs (`legs`: leg number -> LegTable, ascending)."""

    legs: Mapping[int, LegTable]
    serials: Mapping[int, str] = field(default_factory=dict)  # leg -> serial of the leg the table was made for
    integrity: str = ""  # read from a file: "verified" (its record matched) or "unverified" (it had none)

    def __post_init__(self) -> None:
        object.__setattr__(self, "legs", MappingProxyType({k: self.legs[k] for k in sorted(self.legs)}))
        object.__setattr__(self, "serials", MappingProxyType({int(k): str(v) for k, v in sorted(self.serials.items())
                                                              if int(k) in self.legs and v}))

    def rows(self) -> Iterator[tuple[int, float, float, float]]:
        """(leg, position_mm, error_fwd_um, error_rev_um), sorted by leg then position."""
        for leg, t in self.legs.items():
            for x, f, r in zip(t.positions_mm, t.error_fwd_um, t.error_rev_um):
                yield leg, float(x), float(f), float(r)


# -- making a table from a model ---------------------------------------------------------------

def _auto_step_mm(span_mm: float, native_mm: float, spec: TableSpec) -> float:
    """The recording's spacing (or coarser, to fit max_points), shrunk so that a whole number
    of steps spans the stroke: the table then ends on the stroke end instead of up to a step
    beyond it, where it could cross the soft limits. Rounded up to 1 nm (the drive's unit), so
    the end lies at most max_points nm beyond."""
    step = max(native_mm, span_mm / max(1, spec.max_points - 1), spec.min_step_mm)
    n_steps = max(1, math.ceil(span_mm / step - 1e-9))
    return math.ceil(span_mm / n_steps / _AUTO_STEP_QUANTUM_MM - 1e-9) * _AUTO_STEP_QUANTUM_MM


def make_table(model, step_mm: float | None = None, spec: TableSpec | None = None,
               legs: Iterable[int] | None = None) -> CompTable:
    """Resample `model` (a procedures.fit LegErrorModel) on a fixed step over each leg's
    recorded stroke, for a device holding tables as `spec` (default: the built-in drive's).

    Positions run from the stroke minimum in steps of `step_mm` until the stroke maximum is
    covered (the last point may lie up to one step beyond it; the model holds its end value
    there). Without `step_mm` the step is the recording's target spacing, coarsened until the
    table fits `spec.max_points` and adjusted so whole steps span the stroke (see
    `_auto_step_mm`). TableRefused (`TableSpec.check`) when the table does not fit: too many
    points (the message names the step that fits), a step below the minimum, a correction
    beyond `spec.max_correction_um`.
    """
    spec = spec or DEFAULT_SPEC
    if step_mm is not None and not (math.isfinite(step_mm) and step_mm > 0):
        raise TableValidationError(f"table step must be a positive number of mm, got {step_mm}")
    chosen = list(model.legs) if legs is None else sorted(set(int(x) for x in legs))
    out: dict[int, LegTable] = {}
    for leg in chosen:
        fit = model.leg(leg)
        lo, hi = fit.stroke_mm
        span = hi - lo
        step = step_mm if step_mm is not None else _auto_step_mm(span, fit.target_spacing_mm, spec)
        if step > span + 1e-9:  # `--step 1000` on a 180 mm stroke made a 2-point table ending at +910 mm
            raise TableValidationError(
                f"leg {leg}: a {step:g} mm step is longer than the leg's stroke ({lo:+g} .. {hi:+g} mm, {span:g} mm): "
                f"the table would end at {lo + step:+g} mm, beyond it; use a step of at most {span:g} mm "
                f"(the recording's spacing is {fit.target_spacing_mm:g} mm); nothing was made")
        n = int(math.ceil(span / step - 1e-9)) + 1
        if n > spec.max_points:  # before evaluating the model on a needlessly fine grid
            need = math.ceil(span / (spec.max_points - 1) / _STEP_QUANTUM_MM - 1e-9) * _STEP_QUANTUM_MM
            raise TableRefused(
                f"leg {leg}: a {step:g} mm step over the {span:g} mm stroke needs {n} points, more than "
                f"{spec.holder} holds ({spec.max_points}); use a step of at least {need:g} mm."
            )
        start = round(lo, 6)
        pos = start + step * np.arange(n)
        fwd = np.asarray(model.predict_um(leg, pos, 1), dtype=float)
        rev = np.asarray(model.predict_um(leg, pos, -1), dtype=float)
        table = LegTable(leg, float(start), float(step), tuple(float(v) for v in fwd), tuple(float(v) for v in rev))
        try:
            spec.check(table.to_bank(), f"leg {leg}")
        except TableRefused as exc:
            raise TableRefused(f"{exc.args[0]} Check the recording (is the interferometer zeroed?)") from None
        out[leg] = table
    return CompTable(out, model_leg_serials(getattr(model, "identity", None)))


# -- validation --------------------------------------------------------------------------------

def _expected_set(expected_legs: int | Iterable[int] | None) -> set[int] | None:
    if expected_legs is None:
        return None
    if isinstance(expected_legs, int):
        return set(range(1, expected_legs + 1))
    return {int(x) for x in expected_legs}


def _check_legs(where: str, have: Iterable[int], expected_legs) -> None:
    want = _expected_set(expected_legs)
    have = sorted(set(have))
    if want is not None and set(have) != want:
        raise TableValidationError(
            f"{where}: the table has leg(s) {have}, expected {sorted(want)}: it was made for another "
            "leg count; make the table from a model of these legs"
        )


def validate_table(table: CompTable, spec: TableSpec | None = None, expected_legs=None,
                   where: str = "table") -> None:
    """Check a CompTable against `spec` (`TableSpec.check`, TableRefused naming leg, point and
    field) and the expected legs (an int n means legs 1..n; TableValidationError)."""
    spec = spec or DEFAULT_SPEC
    if not table.legs:
        raise TableValidationError(f"{where}: the table is empty")
    _check_legs(where, table.legs, expected_legs)
    for leg, t in table.legs.items():
        spec.check(t.to_bank(), f"{where}, leg {leg}")


# -- writing -----------------------------------------------------------------------------------

def write_table_files(files: Mapping[Path, str], error: type[Exception] = TableValidationError) -> list[Path]:
    """Write every file or none (procedures.io.atomic_outputs). A missing directory raises `error` (the
    caller's own InputError subclass) naming it."""
    for path in files:
        if not path.parent.is_dir():
            raise error(f"{path}: directory {path.parent} does not exist")
    return write_files_atomic(files, encoding="ascii")


SERIAL_COMMENT = "# leg_serial:"
"""A comment line before the CSV header: `# leg_serial: LEG=SERIAL`, one per leg that has one."""


INTEGRITY_KIND = "table"
REMAKE = "make the table again (`station table MODEL.json --out TABLE.csv`) or restore the file from where it came"


def table_csv_text(table: CompTable) -> str:
    """The CSV, its integrity record first (procedures/io/integrity.py)."""
    lines = [f"{SERIAL_COMMENT} {leg}={serial}" for leg, serial in table.serials.items()]
    lines.append(",".join(CSV_HEADER))
    rows = 0
    for leg, x, f, r in table.rows():
        lines.append(f"{leg},{x:.6f},{f:.4f},{r:.4f}")
        rows += 1
    return with_csv_record(INTEGRITY_KIND, "\n".join(lines) + "\n", rows)


def write_table_csv(table: CompTable, path: str | os.PathLike, spec: TableSpec | None = None,
                    expected_legs=None) -> Path:
    """Validate `table` (against `spec`, default the built-in drive's) and write it as CSV.
    Positions to 1e-6 mm, errors to 1e-4 um. Nothing is written when validation fails."""
    path = Path(path)
    validate_table(table, spec, expected_legs, where=str(path))
    write_table_files({path: table_csv_text(table)})
    return path


# -- reading -----------------------------------------------------------------------------------

def read_table_csv(path: str | os.PathLike, spec: TableSpec | None = None,
                   expected_legs: int | Iterable[int] | None = None, check: bool = True) -> CompTable:
    """Read and validate a CSV table (see the module docstring).

    Refused, with file, row (line number, header = row 1) and field named: a wrong header, a
    row without four fields or with a non-number, rows not sorted by leg, positions not
    strictly increasing or unevenly spaced within a leg (drives need a fixed step), fewer than
    two points, and legs other than `expected_legs` (an int n means legs 1..n): these raise
    `TableValidationError`. A well-formed leg that does not fit `spec` (points, step,
    corrections: `TableSpec.check`) raises TableRefused naming file, leg, row and field; with
    `check` False that is left to whoever applies the table (a push checks it against the drive).
    """
    spec = spec or DEFAULT_SPEC
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise TableValidationError(wrong_kind(path, INTEGRITY_KIND, _NOT_A_TABLE) or
                                   f"{path}: not a text file (a table is CSV with the header {','.join(CSV_HEADER)})") from None
    lines = text.splitlines()
    integrity = _check_integrity(path, text, lines)
    serials, head = _comment_lines(lines, path)
    if head >= len(lines) or [c.strip() for c in lines[head].split(",")] != list(CSV_HEADER):
        found = lines[head][:80] if head < len(lines) else "(empty file)"
        raise TableValidationError(wrong_kind(path, INTEGRITY_KIND, _NOT_A_TABLE) or
                                   f"{path}, row {head + 1}: header is {found!r}, expected {','.join(CSV_HEADER)!r}")
    data: dict[int, dict[str, list]] = {}
    last_leg = None
    for row, raw in enumerate(lines[head + 1:], start=head + 2):
        if not raw.strip():
            continue
        cells = [c.strip() for c in raw.split(",")]
        if len(cells) != len(CSV_HEADER):
            raise TableValidationError(f"{path}, row {row}: {len(cells)} field(s), expected {len(CSV_HEADER)} ({','.join(CSV_HEADER)})")
        try:
            leg = int(cells[0])
        except ValueError:
            raise TableValidationError(f"{path}, row {row}, field leg: {cells[0]!r} is not a leg number") from None
        if leg < 1:
            raise TableValidationError(f"{path}, row {row}, field leg: {leg} is not a leg number (legs count from 1)")
        values = []
        for name, cell in zip(CSV_HEADER[1:], cells[1:]):
            values.append(parse_finite(cell, f"{path}, row {row}, field {name}", TableValidationError))
        x, f, r = values
        if leg != last_leg:
            if leg in data:
                raise TableValidationError(f"{path}, row {row}, field leg: leg {leg} appears again after leg {last_leg}; "
                                 "rows must be sorted by leg, then position")
            if last_leg is not None and leg < last_leg:
                raise TableValidationError(f"{path}, row {row}, field leg: leg {leg} after leg {last_leg}; rows must be sorted by leg")
            data[leg] = {"x": [], "f": [], "r": [], "row": []}
            last_leg = leg
        d = data[leg]
        if d["x"]:
            prev = d["x"][-1]
            step = x - prev
            if step <= 0:
                raise TableValidationError(f"{path}, row {row}, field position_mm: {x:g} mm is not above the previous "
                                 f"position {prev:g} mm; positions must increase strictly within a leg")
            if len(d["x"]) >= 2:
                step0 = d["x"][1] - d["x"][0]
                if abs(step - step0) > SPACING_TOL_MM:
                    raise TableValidationError(
                        f"{path}, row {row}, field position_mm: step {step:.6f} mm differs from the leg's step "
                        f"{step0:.6f} mm; drives need a fixed step: resample with `station table --step`"
                    )
        d["x"].append(x)
        d["f"].append(f)
        d["r"].append(r)
        d["row"].append(row)
    if not data:
        raise TableValidationError(f"{path}: no table rows after the header")
    _check_legs(str(path), data, expected_legs)
    legs: dict[int, LegTable] = {}
    for leg, d in data.items():
        if len(d["x"]) < 2:
            raise TableValidationError(f"{path}, row {d['row'][0]}: leg {leg} has a single point; a table needs at least two")
        x = np.asarray(d["x"])
        with np.errstate(over="ignore"):
            step = float((x[-1] - x[0]) / (x.size - 1))  # the mean step: robust to 1e-6 mm rounding
        if not np.isfinite(step):  # positions near the float limit (found by fuzzing)
            raise TableValidationError(f"{path}, rows {d['row'][0]}..{d['row'][-1]}, field position_mm: leg {leg}'s "
                                       f"positions span {x[0]:g} .. {x[-1]:g} mm, beyond any leg")
        legs[leg] = LegTable(leg, float(x[0]), round(step, 9), tuple(d["f"]), tuple(d["r"]), tuple(d["row"]))
        if check:
            spec.check(legs[leg].to_bank(), f"{path}, leg {leg}", point_name=lambda i, rows=d["row"]: f"row {rows[i]}")
    for leg, (row, _) in serials.items():
        if leg not in legs:
            raise TableValidationError(f"{path}, row {row}: names the serial of leg {leg}, which the table has no rows for")
    return CompTable(legs, {leg: serial for leg, (_, serial) in serials.items()}, integrity)


_NOT_A_TABLE = "give the table CSV `station table` wrote (station table MODEL.json --out TABLE.csv)"


def _check_integrity(path: Path, text: str, lines: list[str]) -> str:
    """VERIFIED when the file's record matches it; UNVERIFIED when it has none and its last row is
    whole (a row cut mid-field can still read as numbers); TableValidationError (an
    IntegrityError) naming what differs otherwise. Before any row is parsed: a cut file is then
    named as cut, not by the half row it ends with."""
    try:
        record, body = split_csv_record(path, lines, INTEGRITY_KIND, REMAKE)
        if record is None:
            last_line_whole(path, text, REMAKE)
            return UNVERIFIED
        check_csv_record(path, record, body, _data_rows(body), "table rows", REMAKE)
    except IntegrityError as exc:
        if not isinstance(exc, TableValidationError):
            raise TableIntegrityError(str(exc)) from None
        raise
    return VERIFIED


def _data_rows(lines: list[str]) -> int:
    """Rows after the header (the first line that is not a comment), blank lines not counted."""
    for i, line in enumerate(lines):
        if not line.lstrip().startswith("#"):
            return sum(1 for x in lines[i + 1:] if x.strip())
    return 0


class TableIntegrityError(TableValidationError, IntegrityError):
    """A table file that does not match its integrity record, or without one and not whole."""


STROKE_MARGIN_MM = 5.0
"""How far inside its soft limits a leg's working stroke ends: the room the drive profiles keep
for the ISO 230-2 overrun before each reversal (drivers/modbus/profiles/default.toml: +/-95 mm
soft limits around the +/-90 mm stroke). A table without an integrity record must reach it."""


def check_covers_stroke(table: LegTable, limits: DriveLimits, where: str) -> None:
    """TableIntegrityError when `table` (read from a file without a record) does not cover the
    leg's stroke, its drive's soft `limits` less STROKE_MARGIN_MM at each end: a file cut after
    a whole row reads as a shorter table, whose end value the drive would hold over the rest of
    the stroke."""
    lo, hi = limits.min_mm + STROKE_MARGIN_MM, limits.max_mm - STROKE_MARGIN_MM
    tol = 1e-6  # positions are written to 1e-6 mm
    if table.start_mm <= lo + tol and table.end_mm >= hi - tol:
        return
    raise TableIntegrityError(
        f"{where}, leg {table.leg}: covers {table.start_mm:+.3f} .. {table.end_mm:+.3f} mm, not the leg's stroke "
        f"{lo:+.3f} .. {hi:+.3f} mm (its drive's soft limits {limits.min_mm:+.3f} .. {limits.max_mm:+.3f} mm less "
        f"{STROKE_MARGIN_MM:g} mm), and the file has no integrity record to show it is whole: it may be cut short; "
        f"{REMAKE}")


def _comment_lines(lines: list[str], path: Path) -> tuple[dict[int, tuple[int, str]], int]:
    """The `# leg_serial: LEG=SERIAL` lines before the header ({leg: (row, serial)}) and the index
    of the header line. Other comment lines are skipped."""
    serials: dict[int, tuple[int, str]] = {}
    head = 0
    while head < len(lines) and lines[head].lstrip().startswith("#"):
        line = lines[head].strip()
        if line.startswith(SERIAL_COMMENT):
            leg_text, sep, serial = line[len(SERIAL_COMMENT):].strip().partition("=")
            serial = serial.strip()
            if not (sep and leg_text.strip().isdigit() and serial and " " not in serial and "," not in serial):
                raise TableValidationError(f"{path}, row {head + 1}: {line[:80]!r}: write it as "
                                           f"'{SERIAL_COMMENT} LEG=SERIAL', e.g. '{SERIAL_COMMENT} 3=HX-0042'")
            leg = int(leg_text)
            if leg in serials:
                raise TableValidationError(f"{path}, row {head + 1}: leg {leg}'s serial is given twice")
            serials[leg] = (head + 1, serial)
        head += 1
    return serials, head

