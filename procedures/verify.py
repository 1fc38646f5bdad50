"""Verification of a compensation: the compensated error of a sweep, before and after.

`verify(after_points, before_points)` compares a verification sweep (table active) with the
calibration session it was made from, per leg: the error RMS and range, the noise floor and the
ISO 230-2 values (procedures.iso230), side by side.

Definitions (docs/compensation.md), errors measured minus commanded, um:

- residual RMS: the root mean square of a session's errors about their mean. The mean is left
  out because an interferometer measures displacement from the point where it was zeroed:
  a constant is the reference of the session, not an error of the leg (with a table active the
  zero point itself is corrected, which shifts every reading by the table's value there, and
  the drive's backlash state at the zero point may differ). The mean is reported beside it.
- noise floor: the pooled pass-to-pass standard deviation over (target, direction) cells with
  at least two passes (procedures.fit.noise, the same figure `station fit` reports): what a
  perfect static table would leave, i.e. measurement noise, pass offsets, and the thermal and
  drift changes from pass to pass within the session.
- ratio = residual RMS / noise floor of the verification session. A table that compensates
  every systematic error exactly scores sqrt((n - 1) / n) for n cycles when the conditions
  repeat (about 0.89 for 5 cycles) and about 1 otherwise; systematic residuals add in
  quadrature. The acceptance limit is 1.1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable

import numpy as np

from procedures.errors import InputError
from procedures.fit.data import split_legs
from procedures.fit.noise import estimate_noise_floor
from procedures.iso230 import LegIso230, evaluate_leg

ACCEPT_RATIO = 1.1
"""A verified leg passes when its residual RMS is at most this times its noise floor."""

ISO_SHOWN = ("E", "M", "A", "R", "B")
THERMAL_NOTE_K = 0.1  # a material temperature difference worth pointing out (about 0.2 um over 180 mm)


@dataclass(frozen=True)
class ErrorSummary:
    """The error of one leg in one session, um (measured minus commanded).

    `rms_um` about the mean, `rms_raw_um` including it, `range_um` max - min; `noise_floor_um`
    and `within_pass_um` as procedures.fit.noise (None without repeat passes).
    """

    n_points: int
    n_cycles: int
    mean_um: float
    rms_um: float
    rms_raw_um: float
    range_um: float
    noise_floor_um: float | None
    within_pass_um: float | None
    iso: LegIso230
    material_temp_c: float | None = None  # mean over the leg's points; None when not recorded

    def to_json(self) -> dict[str, Any]:
        return {
            "n_points": self.n_points, "n_cycles": self.n_cycles, "mean_um": self.mean_um, "rms_um": self.rms_um,
            "rms_raw_um": self.rms_raw_um, "range_um": self.range_um, "noise_floor_um": self.noise_floor_um,
            "within_pass_um": self.within_pass_um, "material_temp_c": self.material_temp_c,
            "iso230": {k: self.iso.values.get(k) for k in self.iso.values},
            "iso230_not_computed": dict(self.iso.reasons),
        }


@dataclass(frozen=True)
class LegVerification:
    """One leg: `after` (the verification sweep) and `before` (the calibration, if given)."""

    leg: int
    after: ErrorSummary
    before: ErrorSummary | None = None

    @property
    def ratio(self) -> float | None:
        """Residual RMS of the verification / its noise floor (None without a floor)."""
        f = self.after.noise_floor_um
        return self.after.rms_um / f if f else None

    @property
    def passed(self) -> bool | None:
        r = self.ratio
        return None if r is None else r <= ACCEPT_RATIO

    @property
    def rms_reduction_pct(self) -> float | None:
        if self.before is None or self.before.rms_um <= 0:
            return None
        return 100.0 * (1.0 - self.after.rms_um / self.before.rms_um)

    @property
    def range_reduction_pct(self) -> float | None:
        if self.before is None or self.before.range_um <= 0:
            return None
        return 100.0 * (1.0 - self.after.range_um / self.before.range_um)

    def to_json(self) -> dict[str, Any]:
        return {
            "leg": self.leg, "ratio": self.ratio, "passed": self.passed, "accept_ratio": ACCEPT_RATIO,
            "rms_reduction_pct": self.rms_reduction_pct, "range_reduction_pct": self.range_reduction_pct,
            "after": self.after.to_json(), "before": None if self.before is None else self.before.to_json(),
        }


def summarize(points: np.ndarray, leg: int, source: str = "the session") -> ErrorSummary:
    """ErrorSummary of `leg` in a session's points (POINT_DTYPE). InputError when the leg has
    no usable points."""
    data = split_legs(points, source=source).get(int(leg))
    if data is None or data.n_points == 0:
        raise InputError(f"{source}: no measured points for leg {leg}")
    e = data.error_um
    mean = float(np.mean(e))
    nf = estimate_noise_floor(data)
    pts = np.asarray(points)
    temps = pts["material_temp_c"][pts["leg"] == int(leg)]
    temps = temps[np.isfinite(temps)]
    return ErrorSummary(
        n_points=data.n_points,
        n_cycles=data.n_cycles,
        mean_um=mean,
        rms_um=float(np.sqrt(np.mean((e - mean) ** 2))),
        rms_raw_um=float(np.sqrt(np.mean(e**2))),
        range_um=float(np.ptp(e)),
        noise_floor_um=nf.noise_floor_um,
        within_pass_um=nf.within_pass_um,
        iso=evaluate_leg(np.asarray(points), int(leg)),
        material_temp_c=float(np.mean(temps)) if temps.size else None,
    )


def verify(after_points: np.ndarray, before_points: np.ndarray | None = None, legs: Iterable[int] | None = None,
           after_source: str = "the verification session", before_source: str = "the calibration session",
           ) -> dict[int, LegVerification]:
    """Per-leg verification figures (see the module docstring) for `legs` (default: every leg
    of the verification). InputError when a leg has no points in either session."""
    after_legs = sorted({int(v) for v in np.asarray(after_points)["leg"]}) if len(after_points) else []
    chosen = sorted({int(x) for x in legs}) if legs is not None else after_legs
    if not chosen:
        raise InputError(f"{after_source}: no measured points")
    out: dict[int, LegVerification] = {}
    for leg in chosen:
        after = summarize(after_points, leg, after_source)
        before = summarize(before_points, leg, before_source) if before_points is not None else None
        out[leg] = LegVerification(leg, after, before)
    return out


def _f(value: float | None) -> str:
    if value is None or not math.isfinite(value):
        return f"{'-':>8}"
    return f"{value:8.3f}"


def format_report(results: dict[int, LegVerification]) -> str:
    """Before / after side by side per leg (um), with the ratio and verdict."""
    lines: list[str] = []
    for leg, r in results.items():
        b, a = r.before, r.after
        lines.append(f"Leg {leg}: compensated error, um (measured minus commanded)"
                     + ("" if b else "  [no calibration session given: after only]"))
        lines.append(f"  {'':28} {'before':>8} {'after':>8}")

        def row(label: str, get) -> None:
            lines.append(f"  {label:28} {_f(get(b)) if b else _f(None)} {_f(get(a))}")

        row("residual RMS (about mean)", lambda s: s.rms_um)
        row("range (max - min)", lambda s: s.range_um)
        row("mean (zero reference)", lambda s: s.mean_um)
        row("noise floor (repeat passes)", lambda s: s.noise_floor_um)
        for name in ISO_SHOWN:
            row(f"ISO 230-2 {name}", lambda s, n=name: s.iso.values.get(n))
        ratio = r.ratio
        verdict = ("n/a (no repeat passes)" if ratio is None else
                   f"{ratio:.3f} -> {'PASS' if r.passed else 'ABOVE'} (limit {ACCEPT_RATIO:g})")
        lines.append(f"  residual RMS / noise floor: {verdict}")
        red = r.range_reduction_pct
        if red is not None:
            lines.append(f"  range reduction: {red:.1f} %, RMS reduction: {r.rms_reduction_pct:.1f} %")
        if b and b.material_temp_c is not None and a.material_temp_c is not None:
            dt_k = a.material_temp_c - b.material_temp_c
            if abs(dt_k) >= THERMAL_NOTE_K:
                lines.append(
                    f"  note: the leg was {abs(dt_k):.2f} K {'warmer' if dt_k > 0 else 'colder'} during verification "
                    f"({a.material_temp_c:.2f} C) than during calibration ({b.material_temp_c:.2f} C); thermal "
                    "expansion (steel ~11.5 um/m/K) is not in a static table: let the leg settle to the "
                    "calibration temperature, or see `station diagnose`")
        for note in a.iso.notes:
            lines.append(f"  note (after): {note}")
        lines.append("")
    return "\n".join(lines)
