"""Sampling warnings: a periodic error shorter than twice the target step shows up at another
wavelength (an alias). A 1.5625 mm gearbox term sampled every 1.25 mm appears at 6.25 mm, next to
a 5 mm lead: exactly the misreading to warn against.

With a step s (sampling frequency 1/s), a period p appears at the folded frequency
|1/p - k/s| (k the nearest integer to s/p). For a periodic finding at wavelength w the check
names the known periods that fold onto it (the screw lead, its harmonics, the motor-turn period
and its harmonics when given), lists the shortest periods that would (1 / (k/s +- 1/w)), and a
step that tells them apart: below half the shortest of them, so none of them aliases.
"""

from __future__ import annotations

import math

HARMONICS = 4  # lead / 1 .. lead / 4 and the same of the motor turn


def alias_of(period_mm: float, step_mm: float) -> float:
    """Wavelength (mm) at which a period appears when sampled every `step_mm` (inf: at zero
    frequency, a constant)."""
    fs = 1.0 / step_mm
    f = 1.0 / period_mm
    fa = abs(f - round(f / fs) * fs)
    return math.inf if fa < 1e-12 * fs else 1.0 / fa


def _or(items: list[str]) -> str:
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " or " + items[-1]


def _nice_step(limit_mm: float) -> float:
    """A round step at most `limit_mm` (0.05 mm resolution, at least 0.01 mm)."""
    v = math.floor(limit_mm / 0.05) * 0.05
    return round(v, 2) if v >= 0.05 else round(max(math.floor(limit_mm * 100) / 100, 0.01), 2)


def sampling_warning(wavelength_mm: float, step_mm: float, span_mm: float, lead_mm: float | None = None,
                     motor_turn_mm: float | None = None) -> dict | None:
    """A warning (JSON-able dict with a `note` in words) when a periodic finding at
    `wavelength_mm` could be an alias at the plan's step `step_mm`: of the lead or a harmonic of
    it, or of the motor-turn period (or a harmonic). None when no known period folds onto it.
    `span_mm`: the measured stroke (sets the wavelength resolution)."""
    if not (wavelength_mm > 0 and step_mm > 0 and span_mm > 0):
        return None
    f_obs = 1.0 / wavelength_mm
    tol = 1.5 / (2 * span_mm)  # frequency resolution of the scan, cycles/mm
    known = []
    for name, base in (("the screw lead", lead_mm), ("the motor turn", motor_turn_mm)):
        if not base:
            continue
        for h in range(1, HARMONICS + 1):
            p = base / h
            if p >= 2 * step_mm:  # resolved at this step: it shows at its own wavelength
                continue
            a = alias_of(p, step_mm)
            if math.isfinite(a) and abs(1.0 / a - f_obs) <= tol:
                label = f"{name} ({base:g} mm)" if h == 1 else f"harmonic {h} of {name} ({base:g} mm / {h} = {p:.4g} mm)"
                known.append({"period_mm": p, "source": label})
    fs = 1.0 / step_mm
    could_be = sorted((1.0 / (k * fs + sgn * f_obs) for k in (1, 2) for sgn in (-1, 1) if k * fs + sgn * f_obs > 0),
                      reverse=True)
    could_be = [p for p in could_be if p < 2 * step_mm][:3]
    near_lead = bool(lead_mm) and 0.5 * lead_mm <= wavelength_mm <= 2 * lead_mm
    if not known and not (near_lead and motor_turn_mm is None and could_be):
        return None
    p_ref = max([k["period_mm"] for k in known] or could_be[:1])
    tell = _nice_step(0.4 * p_ref)
    others = _or([f"{p:.4g}" for p in could_be])
    if known:
        names = "; ".join(k["source"] for k in known)
        note = (f"the {wavelength_mm:.4g} mm periodic error may be an alias: sampled every {step_mm:.4g} mm, "
                f"{names} would appear at {wavelength_mm:.4g} mm (so would any period of {others} mm)")
    else:
        note = (f"the {wavelength_mm:.4g} mm periodic error, next to the {lead_mm:g} mm lead, may be an alias: sampled "
                f"every {step_mm:.4g} mm, a period of {others} mm (a motor-turn or gearbox period) would appear at "
                f"{wavelength_mm:.4g} mm (give the motor-turn period to check it)")
    note += f"; measure with a step of {tell:g} mm (below half the {p_ref:.4g} mm period) to tell them apart"
    return {"may_be_alias_of": known, "aliasing_periods_mm": could_be, "step_mm": step_mm,
            "step_to_tell_apart_mm": tell, "note": note}
