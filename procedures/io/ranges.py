"""Physical ranges of a measured point's values, in one place.

Two uses:
- import (`procedures.io.csv_io`): `PointLimits()` or one built from the drive profile and the legs
  the operator declares. Values a leg on this station cannot produce are refused, naming file,
  line and field: a target beyond the drive's soft limits, an error beyond a micrometre sanity
  limit (a unit mix-up, or a broken measurement), a leg the platform does not have, a
  temperature, pressure, humidity or load outside what a workshop sees.
- reading a session file (`procedures.io.recording.reader`): `SESSION_BOUNDS`, far looser: beyond
  them no rig measures anything, so a value there is garbage from a damaged file, and must not
  reach an analysis (300-digit ISO 230-2 values, overflow in a fit).

NaN means "not measured" in the optional fields (and in `error_um` of a session file); an
infinite value is never allowed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable

import numpy as np

LEG_NUMBERS = (1, 2, 3, 4, 5, 6)
"""A Gough-Stewart platform has six legs (as `station sweep --legs` accepts)."""

SOFT_LIMITS_MM = (-95.0, 95.0)
"""The built-in drive profile's soft limits (drivers/modbus/profiles/default.toml [limits]);
the import command passes the limits of the profile in use."""

MAX_ERROR_UM = 1000.0
"""Sanity limit on |error_um|: a ball-screw leg is off by micrometres to tens of micrometres;
a millimetre is a unit mix-up (nm for um) or a broken measurement, never a leg to compensate
(a drive table corrects at most a few hundred micrometres)."""

_UNITS = {"target_mm": "mm", "error_um": "um", "time_s": "s", "air_temp_c": "degC", "material_temp_c": "degC",
          "air_pressure_hpa": "hPa", "humidity_pct": "%RH", "load_n": "N", "speed_mm_s": "mm/s"}
_HINTS = {
    "target_mm": "the drive's soft limits: a target beyond them was never reached; positions are mm from mid-stroke",
    "time_s": "seconds since the session start",
    "air_temp_c": "air temperature in degrees Celsius",
    "material_temp_c": "leg material temperature in degrees Celsius",
    "air_pressure_hpa": "hPa; about 1013 at sea level",
    "humidity_pct": "relative humidity in percent",
    "load_n": "axial load in newtons",
    "speed_mm_s": "signed axis speed at an on-the-fly reading, mm/s; leave it empty for readings at rest",
}


def legs_text(legs: Iterable[int]) -> str:
    """(1, 2, 3, 5) -> '1-3, 5'."""
    out: list[str] = []
    run: list[int] = []
    for leg in sorted(set(legs)) + [None]:
        if run and (leg is None or leg != run[-1] + 1):
            out.append(f"{run[0]}-{run[-1]}" if len(run) > 2 else ", ".join(map(str, run)))
            run = []
        if leg is not None:
            run.append(leg)
    return ", ".join(out)


def _num(value: float) -> str:
    return f"{value:.6g}"  # 1e300 stays short; 12.5 stays 12.5


@dataclass(frozen=True)
class PointLimits:
    """What values a point may hold. `legs`: the leg numbers allowed; `stroke_mm`: targets;
    `max_error_um`: |error_um|; the others (lo, hi) in the field's unit."""

    legs: tuple[int, ...] = LEG_NUMBERS
    stroke_mm: tuple[float, float] = SOFT_LIMITS_MM
    max_error_um: float = MAX_ERROR_UM
    max_run: int = 100_000
    time_s: tuple[float, float] = (0.0, 31 * 86400.0)  # a month of one session, resumes included
    air_temp_c: tuple[float, float] = (-10.0, 50.0)
    material_temp_c: tuple[float, float] = (-10.0, 80.0)  # a screw warms up with travel
    air_pressure_hpa: tuple[float, float] = (500.0, 1100.0)  # 5 500 m altitude .. a deep mine
    humidity_pct: tuple[float, float] = (0.0, 100.0)
    load_n: tuple[float, float] = (-100_000.0, 100_000.0)  # 100 kN either way, compression positive
    speed_mm_s: tuple[float, float] = (-1000.0, 1000.0)  # a leg moves at tens of mm/s; 1 m/s is a unit error

    def bounds(self, name: str) -> tuple[float, float] | None:
        """(lo, hi) of a float field, None for fields without a range here."""
        if name == "target_mm":
            return self.stroke_mm
        if name == "error_um":
            return (-self.max_error_um, self.max_error_um)
        value = getattr(self, name, None)
        return value if isinstance(value, tuple) and name in _UNITS else None

    def problem(self, name: str, value: float, required: bool = False) -> str | None:
        """Why `value` is not allowed in field `name`, or None. NaN is 'not measured', allowed
        unless `required`; infinity never is."""
        if name == "leg":
            return None if int(value) in self.legs else f"leg {int(value)} is not one of the legs {legs_text(self.legs)}"
        if name == "run":
            return None if 1 <= value <= self.max_run else f"run {int(value)} is outside 1 .. {self.max_run}"
        if name == "direction":
            return None if value in (1, -1) else f"{int(value)} is not +1 or -1"
        b = self.bounds(name)
        if isinstance(value, float) and math.isnan(value):
            return "NaN, but a value is required" if required else None
        if b is None:
            return None
        unit = _UNITS[name]
        if not math.isfinite(value):
            return f"{value} is not a finite number"
        lo, hi = b
        if lo <= value <= hi:
            return None
        if name == "error_um":
            return (f"{_num(value)} um is beyond the sanity limit of +/-{_num(self.max_error_um)} um "
                    "(a leg's error is micrometres: is the column in um, not nm or mm?)")
        return f"{_num(value)} {unit} is outside {_num(lo)} .. {_num(hi)} {unit} ({_HINTS[name]})"

    def check_array(self, points: np.ndarray, fields: Iterable[str],
                    required: Iterable[str] = ()) -> tuple[int, str, str, int] | None:
        """The first (row, field, reason) of `points` (a structured array) with a value out of
        range, and how many rows have one; None when all are within. NaN is allowed except in
        the `required` fields."""
        required = set(required)
        bad_any = np.zeros(len(points), bool)
        first: tuple[int, str] | None = None
        for name in fields:
            v = points[name]
            if name == "leg":
                bad = ~np.isin(v, np.asarray(self.legs))
            elif name == "run":
                bad = (v < 1) | (v > self.max_run)
            elif name == "direction":
                bad = (v != 1) & (v != -1)
            else:
                lo, hi = self.bounds(name)
                v = v.astype(float)
                with np.errstate(invalid="ignore"):
                    bad = np.isinf(v) | (v < lo) | (v > hi)
                if name in required:
                    bad |= np.isnan(v)
            if bad.any():
                i = int(np.argmax(bad))
                if first is None or i < first[0]:
                    first = (i, name)
                bad_any |= bad
        if first is None:
            return None
        i, name = first
        value = points[name][i]
        value = float(value) if points.dtype[name].kind == "f" else int(value)
        reason = self.problem(name, value, name in required) or f"{value} is out of range"
        return i, name, reason, int(np.count_nonzero(bad_any))


SESSION_BOUNDS = PointLimits(
    stroke_mm=(-1000.0, 1000.0),  # the leg is 1.1 m long: no target lies a metre from mid-stroke
    max_error_um=100_000.0,  # 0.1 m
    time_s=(-1e9, 1e10),
    air_temp_c=(-100.0, 200.0),
    material_temp_c=(-100.0, 500.0),
    air_pressure_hpa=(0.0, 2000.0),
    humidity_pct=(0.0, 100.0),
    load_n=(-1e7, 1e7),
    max_run=2**31 - 1,
)
"""Loose bounds for reading session files: a value beyond them is garbage, not a measurement."""
