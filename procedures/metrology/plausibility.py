"""Values that are possible but more likely a slip, named with the slip (issue 22, item 6).

A physical range (procedures/io/ranges.py) refuses what no leg can produce. Inside it some values
are far more likely a unit slip than a measurement: 68 in a degC column is 20 degC typed in
degF; 500 in an um column is 0.5 um typed in nm; a table that corrects more than the leg's error
ever spanned comes from an extrapolated model, or a model of something else. Such a value is
refused, naming where it is (file, line, field) and the slip it looks like, unless the user
states that it is right (`--accept-implausible`); then it is kept, with a warning line.

Measured data (`station import`, issue 35) are refused only when physically impossible for the
declared axis (`Implausible.impossible`: an error larger than the travel the targets span; the
physical ranges of procedures/io/ranges.py refuse the rest of the impossible): uncompensated axes
and screws of low accuracy grades do reach hundreds of micrometres, so an unusual value is
imported with a warning line giving the figure that made it suspicious (`settle_measured`).

Front-end independent: `station import` (procedures.io.csv_io), and `station table`, `station push`
and the terminal UI's Compensation page (through station.services.table_jobs) call the same checks
and `settle`; each front end says how its user accepts the values (`Override`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from procedures.vocabulary import InputError

ACCEPT_OPTION = "--accept-implausible"

FAHRENHEIT_FROM_C = 40.0
"""A workshop's air, and a leg's material, above this many degC is rare (a screw warms a few
kelvin with travel); 50..104 degF is 10..40 degC, so a degC column reading above it most
likely holds degF (68 degF = 20 degC)."""

NM_FROM_UM = 100.0
"""A precision ball-screw leg's positioning error is micrometres to tens of micrometres; an error
column whose values go beyond 100 um may hold nm (0.5 um = 500 nm), or come from an uncompensated
axis or a screw of a low accuracy grade (they reach hundreds of um): suspicious, not impossible."""

CORRECTION_SPAN_FACTOR = 1.5
"""A table may correct a little more than the recorded error spanned (the model smooths and
meets both directions), not 1.5 times as much: beyond, it extrapolates or is not this leg's."""

CORRECTION_SPAN_MARGIN_UM = 0.5
"""...plus this, so that a leg with almost no error (a compensated one) is not flagged for noise."""


@dataclass(frozen=True)
class Override:
    """How a front end lets its user accept implausible values: `how` the refusal says to do it,
    `kept` the warning line names what kept them. The default is the command line's option."""

    how: str = f"add {ACCEPT_OPTION}"
    kept: str = ACCEPT_OPTION


class ImplausibleError(InputError):
    """A refusal of implausible values (`settle`): bad input the user may override, unlike the
    other InputErrors. `findings`: what was refused; `leg`: whose values, when the caller knows."""

    def __init__(self, message: str, findings: Sequence["Implausible"] = (), leg: int | None = None) -> None:
        super().__init__(message)
        self.findings = tuple(findings)
        self.leg = leg


@dataclass(frozen=True)
class Implausible:
    """One implausible value: `where` (file, line, field or key), the value, the likely slip."""

    where: str
    value: float
    slip: str
    impossible: bool = False  # physically impossible for the declared axis: refused even for measured data

    def text(self) -> str:
        return f"{self.where} = {self.value:g}: {self.slip}"


def nm_slip(value_um: float) -> str:
    return (f"looks like nm in an um field ({value_um:g} nm = {value_um / 1000.0:g} um; a ball-screw leg is off by "
            f"micrometres to tens of micrometres, not {NM_FROM_UM:g} um and more)")


def large_error(value_um: float, span_mm: float) -> str:
    """The warning of a measured error beyond NM_FROM_UM: the figure, and both readings of it."""
    return (f"{abs(value_um):g} um is beyond {NM_FROM_UM:g} um: possible for an uncompensated axis or a screw of a low "
            f"accuracy grade, unusual for a precision leg; if the column holds nm it is {value_um / 1000.0:g} um "
            f"(targets span {span_mm:g} mm)")


def impossible_error(value_um: float, span_mm: float) -> str:
    return (f"an error of {abs(value_um) / 1000.0:g} mm is larger than the {span_mm:g} mm the targets span: no axis is "
            "off by more than its travel; is the column in um (not nm), and are the targets in mm?")


def fahrenheit_warning(value_c: float) -> str:
    return (f"{value_c:g} degC is above {FAHRENHEIT_FROM_C:g} degC, rare for a workshop or a leg; if the column holds "
            f"degF it is {(value_c - 32.0) * 5.0 / 9.0:.1f} degC")


def check_points(points: np.ndarray, source: str, lines: Sequence[int] | None = None) -> list[Implausible]:
    """The first implausible value of each field of `points` (POINT_DTYPE rows from `source`;
    `lines`: each row's line in the file, to name it): temperatures in degF, errors in nm (the
    largest error, so the warning gives the extreme figure); an error larger than the travel
    the targets span is `impossible` (named before any other error)."""
    found: list[Implausible] = []

    def where(row: int, field: str) -> str:
        line = f"line {lines[row]}" if lines is not None and row < len(lines) else f"row {row + 1}"
        return f"{source}, {line}, field {field}"  # as the import's other problems are named

    names = points.dtype.names or ()
    for field in ("material_temp_c", "air_temp_c"):
        if field in names:
            values = np.asarray(points[field], float)
            hits = np.flatnonzero(np.isfinite(values) & (values > FAHRENHEIT_FROM_C))
            if hits.size:
                row = int(hits[0])
                found.append(Implausible(where(row, field), float(values[row]), fahrenheit_warning(float(values[row]))))
    if "error_um" in names:
        values = np.asarray(points["error_um"], float)
        targets = np.asarray(points["target_mm"], float) if "target_mm" in names else np.zeros(0)
        targets = targets[np.isfinite(targets)]
        span_mm = float(np.ptp(targets)) if targets.size else 0.0
        ok = np.isfinite(values)
        if span_mm > 0:
            hits = np.flatnonzero(ok & (np.abs(values) / 1000.0 > span_mm))
            if hits.size:
                row = int(hits[0])
                found.append(Implausible(where(row, "error_um"), float(values[row]),
                                         impossible_error(float(values[row]), span_mm), impossible=True))
                return found
        hits = np.flatnonzero(ok & (np.abs(values) > NM_FROM_UM))
        if hits.size:
            row = int(hits[np.argmax(np.abs(values[hits]))])
            found.append(Implausible(where(row, "error_um"), float(values[row]),
                                     large_error(float(values[row]), span_mm)))
    return found


def check_table_values(table, source: str, limit_um: float = float("inf")) -> Implausible | None:
    """A table leg (procedures.compensation.table.LegTable) whose correction goes beyond 100 um: most likely
    nm written into the um columns. The first such value, named by file, leg, row (with its
    position) and column, as the table's other refusals name it; else None. Values beyond
    `limit_um` (what the drive can hold) are left to that limit's own, firmer refusal."""
    for field_name in ("error_fwd_um", "error_rev_um"):
        v = np.asarray(getattr(table, field_name), float)
        hits = np.flatnonzero(np.isfinite(v) & (np.abs(v) > NM_FROM_UM) & (np.abs(v) <= limit_um))
        if hits.size:
            i = int(hits[0])
            return Implausible(f"{source}, leg {table.leg}, {table.point_name(i)}, field {field_name}",
                               float(v[i]), nm_slip(float(v[i])))
    return None


def check_correction(leg: int, correction_span_um: float, error_span_um: float, source: str) -> Implausible | None:
    """A table for `leg` whose corrections span (max - min, both directions) more than the error
    recorded in `source` spanned: an Implausible naming both, else None."""
    if not (np.isfinite(correction_span_um) and np.isfinite(error_span_um)):
        return None
    if correction_span_um <= CORRECTION_SPAN_FACTOR * error_span_um + CORRECTION_SPAN_MARGIN_UM:
        return None
    return Implausible(f"leg {leg}: correction span (um)", correction_span_um,
                       f"larger than the error it corrects ({error_span_um:.3f} um peak to peak in {source}): "
                       "the model extrapolates (a table beyond the recorded stroke, a --step coarser than the "
                       "error's wiggles) or is not this leg's; a table must never add more error than it removes")


def settle(found: Sequence[Implausible], accept: bool, what: str = "nothing was written",
           override: Override = Override()) -> list[str]:
    """Refuse `found` (ImplausibleError: the first, how many more, how to accept them), or, when
    the user accepted them, their warning lines. [] when nothing was found. `what`: what the
    refusal adds ("" when the caller says it itself); `override`: the front end's way to accept."""
    if not found:
        return []
    if not accept:
        more = f" (and {len(found) - 1} more implausible value(s))" if len(found) > 1 else ""
        raise ImplausibleError(f"{found[0].text()}{more}; correct it, or {override.how} if the values are right"
                               + (f"; {what}" if what else ""), found)
    return [f"warning: {f.text()} (kept: {override.kept})" for f in found]


def settle_measured(found: Sequence[Implausible], accept: bool, what: str = "nothing was written",
                    override: Override = Override()) -> list[str]:
    """Measured data (`station import`): refuse only the `impossible` values (as `settle`, which
    `accept` overrides); every other one is kept with a warning line giving its figure."""
    impossible = [f for f in found if f.impossible]
    out = settle(impossible, accept, what, override)
    return out + [f"warning: {f.text()} (imported as it is; check the unit if it should not be)"
                  for f in found if not f.impossible]
