"""Re-correction of a session's laser readings for the refractive index of air: from the index the
instrument applied (its record, `laser_air_compensation` in the session's devices) to the one
the station computes (Ciddor or modified Edlen, procedures/metrology/air.py) from the recorded,
corrected or stated air values. Writes a NEW session file; the source is never touched.

The model (docs/metrology.md). The interferometer counts the change of optical path of its
measuring arm. With the laser's dead path D (the beam between the interferometer optic and the
zero point, not counted as length) and the index n0 when the axis was zeroed, a leg
displacement L at index n gives the optical-path change, in vacuum length units,

    C = n * (D + L) - n0 * D

An instrument with vacuum wavelength lambda_i, index n_i (n0_i at its zero) and dead-path
correction D_i reports L_rep = C_i / n_i + D_i * (n0_i - n_i) / n_i, with C_i = C * lambda_i / lambda.
So from a report

    C       = (n_i * L_rep - D_i * (n0_i - n_i)) * lambda / lambda_i
    L_new   = C / n + D * (n0 - n) / n

Sign: a warmer (thinner) air after zeroing, n < n0, shortens the dead path's optical length;
uncorrected, the leg reads short by D * (n0 - n) / n, which the second term adds back.
The new `measured_mm` is L_new, `error_um` changes by (L_new - L_rep) * 1000. The index at the
zero (n0, n0_i) is taken at each leg's first recorded point (the sweep zeroes the laser just
before it); a resumed session's second zero is not modelled (its offset is constant and
analyses treat it as the session's reference).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from procedures.io.atomic_outputs import atomic_path
from procedures.vocabulary import InputError
from procedures.metrology import defaults as D
from procedures.metrology.air import EQUATIONS, refractive_index
from procedures.io.recording.columns import read_point_column, write_point_column
from procedures.io.recording.reader import read_session
from procedures.io.recording.writer import build_session_file, to_json_text

RECORD_KEY = "laser_air_compensation"
"""The devices entry holding how the instrument compensated (drivers.interferometer.protocol.
CompensationReply.to_json, or a re-correction's own record)."""
ORIGINAL_KEY = "laser_air_compensation_original"
"""A re-corrected file keeps the record it was re-corrected from here."""

# what a user may state for the air, refused outside (a typo or a unit mix-up, never a workshop)
LIMITS = {
    "air_temp_c": (-10.0, 50.0, "degC"),
    "air_temp_offset_c": (-10.0, 10.0, "K"),
    "pressure_pa": (50000.0, 110000.0, "Pa (1013.25 hPa = 101325 Pa)"),
    "humidity_pct": (0.0, 100.0, "%RH"),
    "co2_ppm": (0.0, 5000.0, "ppm"),
    "dead_path_mm": (0.0, 10000.0, "mm"),
    "wavelength_nm": (400.0, 1700.0, "nm (vacuum wavelength)"),
}


@dataclass(frozen=True)
class RecorrectOptions:
    """What the station's index is computed from. None = as recorded (air) / the default."""

    equation: str = "ciddor"
    wavelength_nm: float = D.WAVELENGTH_NM  # the laser's vacuum wavelength ([metrology] wavelength_nm)
    co2_ppm: float = D.CO2_PPM  # used where the session has no CO2 reading ([metrology] co2_ppm)
    dead_path_mm: float = D.DEAD_PATH_MM  # [metrology] dead_path_mm
    air_temp_offset_c: float = 0.0  # added to every recorded air temperature (a sensor found off)
    air_temp_c: float | None = None  # replaces the recorded air temperature
    pressure_pa: float | None = None  # replaces the recorded pressure
    humidity_pct: float | None = None  # replaces the recorded humidity

    def check(self) -> None:
        """InputError naming the option for a value outside LIMITS or an unknown equation."""
        if self.equation not in EQUATIONS:
            raise InputError(f"--equation {self.equation!r}: known equations are {', '.join(EQUATIONS)}")
        if self.air_temp_c is not None and self.air_temp_offset_c:
            raise InputError("--air-temp-c and --air-temp-offset-c exclude each other: state the temperature, "
                             "or the offset of the recorded one")
        for name, (lo, hi, unit) in LIMITS.items():
            v = getattr(self, name)
            if v is None:
                continue
            if not (isinstance(v, (int, float)) and math.isfinite(v) and lo <= v <= hi):
                raise InputError(f"--{name.replace('_', '-')} {v!r}: must be within {lo:g}..{hi:g} {unit}")


@dataclass
class Recorrection:
    """What `recorrect_points` did."""

    points: np.ndarray
    co2_ppm: np.ndarray  # per point, as used
    record: dict[str, Any]  # the new file's compensation record
    n_instrument: tuple[float, float]
    n_station: tuple[float, float]
    change_um: tuple[float, float]  # min, max of error_um new - old
    notes: list[str] = field(default_factory=list)


def instrument_record(session: Any) -> dict[str, Any]:
    """The instrument's compensation record of `session`; InputError when it has none."""
    text = (session.devices or {}).get(RECORD_KEY)
    if not isinstance(text, str) or not text.startswith("{"):
        why = f"its devices say {RECORD_KEY}: {text!r}" if text else f"it has no {RECORD_KEY} record"
        raise InputError(
            f"{session.path}: cannot re-correct: the session does not record how the interferometer compensated its "
            f"readings for the air ({why}). Sessions recorded before the station asked the instrument (COMP?), "
            "imported from CSV, or from an instrument that cannot say, lack the index it applied; nothing was written")
    try:
        rec = json.loads(text)
        mode = str(rec["mode"]).upper()
        equation = str(rec["equation"]).upper()
        wavelength = float(rec["wavelength_nm"])
    except (ValueError, KeyError, TypeError) as exc:
        raise InputError(f"{session.path}: devices/{RECORD_KEY} is not a valid compensation record ({exc}); "
                         "nothing was written") from None
    if mode not in ("AUTO", "MANUAL", "OFF", "STATION") or (mode != "OFF" and equation.lower() not in EQUATIONS) \
            or not 400.0 <= wavelength <= 1700.0:
        raise InputError(f"{session.path}: devices/{RECORD_KEY}: mode {mode!r}, equation {equation!r}, wavelength "
                         f"{wavelength!r} nm is not a compensation this station can redo; nothing was written")
    return rec


def _num(rec: dict, key: str, default: float) -> float:
    v = rec.get(key)
    return default if v is None else float(v)


def _air_arrays(points: np.ndarray, source: str, need: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t, p_hpa, h = (np.asarray(points[k], dtype=float) for k in ("air_temp_c", "air_pressure_hpa", "humidity_pct"))
    if need:
        for name, arr in (("air_temp_c", t), ("air_pressure_hpa", p_hpa), ("humidity_pct", h)):
            bad = np.flatnonzero(~np.isfinite(arr))
            if bad.size:
                raise InputError(f"{source}: /points row {int(bad[0])}, field {name}: not recorded "
                                 f"({bad.size} row(s)); the index the instrument applied from its sensors cannot be "
                                 "redone without it; nothing was written")
    return t, p_hpa * 100.0, h


def _zero_index(points: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Per point, the index at its leg's zeroing: n at the leg's first recorded point."""
    n0 = np.empty_like(n)
    for leg in np.unique(points["leg"]):
        rows = np.flatnonzero(points["leg"] == leg)
        first = rows[np.argmin(points["index"][rows])]
        n0[rows] = n[first]
    return n0


def recorrect_points(points: np.ndarray, record: dict[str, Any], options: RecorrectOptions,
                     co2_column: np.ndarray | None = None, source: str = "the session") -> Recorrection:
    """The re-corrected copy of `points` (module docstring for the model)."""
    options.check()
    mode = str(record["mode"]).upper()
    t_rec, p_rec, h_rec = _air_arrays(points, source, need=mode in ("AUTO", "STATION"))
    co2_rec = co2_column if co2_column is not None else np.full(len(points), np.nan)
    lam_i = float(record["wavelength_nm"])
    d_i = _num(record, "dead_path_mm", 0.0)
    # the index the instrument applied
    if mode == "OFF":
        n_i = np.ones(len(points))
    else:
        eq_i = str(record["equation"]).lower()
        co2_i = np.where(np.isfinite(co2_rec), co2_rec, _num(record, "co2_ppm", D.CO2_PPM)) if mode == "STATION" \
            else _num(record, "co2_ppm", D.CO2_PPM)
        if mode == "MANUAL":
            n_i = np.full(len(points), float(refractive_index(
                eq_i, lam_i, float(record["air_temp_c"]), float(record["air_pressure_hpa"]) * 100.0,
                float(record["humidity_pct"]), _num(record, "co2_ppm", D.CO2_PPM))))
        else:
            n_i = np.asarray(refractive_index(eq_i, lam_i, t_rec, p_rec, h_rec, co2_i), dtype=float)
    # the station's index, from the recorded air as corrected or replaced by the options
    t = np.full(len(points), options.air_temp_c) if options.air_temp_c is not None else t_rec + options.air_temp_offset_c
    p = np.full(len(points), options.pressure_pa) if options.pressure_pa is not None else p_rec
    h = np.full(len(points), options.humidity_pct) if options.humidity_pct is not None else h_rec
    co2 = np.where(np.isfinite(co2_rec), co2_rec, options.co2_ppm)
    for name, arr in (("air_temp_c", t), ("air_pressure_hpa", p), ("humidity_pct", h)):
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise InputError(f"{source}: /points row {int(bad[0])}, field {name}: not recorded ({bad.size} row(s)); "
                             f"state it (--{ {'air_temp_c': 'air-temp-c', 'air_pressure_hpa': 'pressure-pa', 'humidity_pct': 'humidity-pct'}[name]}); "
                             "nothing was written")
    n = np.asarray(refractive_index(options.equation, options.wavelength_nm, t, p, h, co2), dtype=float)
    l_rep = np.asarray(points["measured_mm"], dtype=float)
    c = (n_i * l_rep - d_i * (_zero_index(points, n_i) - n_i)) * options.wavelength_nm / lam_i
    l_new = c / n + options.dead_path_mm * (_zero_index(points, n) - n) / n
    out = points.copy()
    change_um = (l_new - l_rep) * 1000.0
    out["measured_mm"] = l_new
    out["error_um"] = points["error_um"] + change_um
    out["air_temp_c"], out["air_pressure_hpa"], out["humidity_pct"] = t, p / 100.0, h
    new_record = {"mode": "STATION", "equation": options.equation.upper(), "wavelength_nm": options.wavelength_nm,
                  "air_temp_c": None, "air_pressure_hpa": None, "humidity_pct": None,
                  "co2_ppm": options.co2_ppm, "dead_path_mm": options.dead_path_mm}
    finite = change_um[np.isfinite(change_um)]
    return Recorrection(out, co2, new_record, (float(np.min(n_i)), float(np.max(n_i))),
                        (float(np.min(n)), float(np.max(n))),
                        (float(finite.min()), float(finite.max())) if finite.size else (0.0, 0.0))


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def recorrect_session(src: str | os.PathLike, out: str | os.PathLike, options: RecorrectOptions) -> Recorrection:
    """Write `out`, a new session: `src` with its readings re-corrected (module docstring), the
    air values used, the new compensation record (and the instrument's kept as
    `laser_air_compensation_original`), and /meta attribute `recorrection` saying what was done
    (source path and SHA-256, equation, inputs). Atomic: a temporary file renamed at the end;
    `src` is only read."""
    src, out = Path(src), Path(out)
    options.check()
    if out.exists():
        raise InputError(f"{out}: exists; choose another --out (a re-correction is a new file)")
    if not out.parent.is_dir():
        raise InputError(f"{out}: directory {out.parent} does not exist")
    if out.resolve() == src.resolve():
        raise InputError(f"{out}: is the session itself; the original stays untouched, write a new file")
    session = read_session(src)
    record = instrument_record(session)
    if not len(session.points):
        raise InputError(f"{src}: the session has no points; nothing to re-correct")
    sha = _sha256(src)
    co2_column = read_point_column(src, "co2_ppm")
    result = recorrect_points(session.points, record, options, co2_column, str(src))
    devices = dict(session.devices)
    devices[ORIGINAL_KEY] = devices.get(ORIGINAL_KEY) or devices[RECORD_KEY]
    devices[RECORD_KEY] = json.dumps(result.record, sort_keys=True)
    what = {
        "source": {"path": str(src), "sha256": sha},
        "utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "equation": options.equation, "wavelength_nm": options.wavelength_nm, "dead_path_mm": options.dead_path_mm,
        "co2_ppm": options.co2_ppm, "co2_per_point": bool(co2_column is not None and np.isfinite(co2_column).any()),
        "air_temp_offset_c": options.air_temp_offset_c, "air_temp_c": options.air_temp_c,
        "pressure_pa": options.pressure_pa, "humidity_pct": options.humidity_pct,
        "instrument": record, "n_instrument_range": list(result.n_instrument), "n_station_range": list(result.n_station),
        "error_change_um": list(result.change_um),
        "formula": "C = (n_i*L_rep - D_i*(n0_i - n_i))*lambda/lambda_i; L_new = C/n + D*(n0 - n)/n (docs/metrology.md)",
    }
    with atomic_path(out) as tmp:
        with h5py.File(src, "r", swmr=True) as f:
            root = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
            meta = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f["meta"].attrs.items()}
            root["session_id"] = f"{root.get('session_id', '')}-recorrected"
            meta["devices"] = to_json_text("devices", devices)
            meta["recorrection"] = to_json_text("recorrection", what)
            build_session_file(tmp, root, meta, result.points, session.faults, copy_from=f)
        write_point_column(tmp, "co2_ppm", result.co2_ppm)
    return result
