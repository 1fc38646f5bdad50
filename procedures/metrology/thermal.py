"""Normalisation of a leg's error to the reference temperature (20 degC, ISO 1): the nominal
differential expansion (NDE) correction of ISO 230-2.

Physics and sign. The laser measures the real displacement of the leg end; the drive's position
(the target, `target_mm`) is counted on the screw, which expands with its temperature. A leg
whose material is warmer than the reference by dT is longer, between the point where it is fixed
(`fixed_point_mm`, in the station's target_mm coordinate) and the nut, by

    expansion_um_m_k * dT * (target_mm - fixed_point_mm) * 1e-3   um

(um/m/K x K x m; 1e-3 turns mm into m). `error_um` = measured - commanded, so a warm leg reads
that much MORE error. The error the leg would have at the reference temperature is therefore

    error_20_um = error_um - expansion_um_m_k * (material_temp_c - reference_temp_c)
                             * (target_mm - fixed_point_mm) * 1e-3

Steel (11.5 um/m/K) over a +/-90 mm stroke: about +/-1 um per kelvin. The position-independent
part (the fixed point's distance to the laser's zero) only shifts every reading of a pass alike:
analyses treat it like the zero of the session, so a fixed point set a few mm off matters little,
one at the wrong end of the leg shows up as drift when the temperature changes.

Computed on read: the session keeps the raw `error_um`; `normalise_points` returns a copy of the
points whose `error_um` is the normalised error, for fit, table, ISO 230-2 and verify, which use
it by default (`--raw` opts out). Diagnosis works on the raw error (thermal is one of its effects).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from procedures.metrology import defaults as D
from procedures.metrology.defaults import REFERENCE_TEMP_C  # noqa: F401  (re-exported)

LEG_NUMBERS = (1, 2, 3, 4, 5, 6)


@dataclass(frozen=True)
class Material:
    """A leg's thermal expansion: `expansion_um_m_k` (um per metre per kelvin, steel 11.5) with
    its standard uncertainty `expansion_u_um_m_k`, and `fixed_point_mm`, the position in the
    station's target_mm coordinate where the leg is fixed, so that its thermal expansion is
    zero there (docs/metrology.md). The station config's [legs] (station.services.config.LegMaterial is
    this class); a session records every leg's."""

    expansion_um_m_k: float = D.EXPANSION_UM_M_K
    expansion_u_um_m_k: float = D.EXPANSION_U_UM_M_K
    fixed_point_mm: float = D.FIXED_POINT_MM


def nde_correction_um(target_mm, material_temp_c, material: Any, reference_temp_c: float = REFERENCE_TEMP_C):
    """The thermal expansion of the leg at `target_mm`, um (positive = longer than at the
    reference temperature): what normalising an error to it subtracts. Vectorised."""
    return (float(material.expansion_um_m_k) * (np.asarray(material_temp_c, dtype=float) - reference_temp_c)
            * (np.asarray(target_mm, dtype=float) - float(material.fixed_point_mm)) * 1e-3)


def _material(d: Any) -> Material | None:
    if not isinstance(d, Mapping):
        return None
    try:
        m = Material(float(d.get("expansion_um_m_k", D.EXPANSION_UM_M_K)),
                     float(d.get("expansion_u_um_m_k", D.EXPANSION_U_UM_M_K)),
                     float(d.get("fixed_point_mm", D.FIXED_POINT_MM)))
    except (TypeError, ValueError):
        return None
    return m if all(math.isfinite(v) for v in (m.expansion_um_m_k, m.expansion_u_um_m_k, m.fixed_point_mm)) else None


def recorded_materials(station_config: Mapping[str, Any] | None) -> tuple[float, dict[int, Material]] | None:
    """(reference_temp_c, leg -> Material) a session recorded in its station config
    (`leg_materials`, `metrology.reference_temp_c`); None when it recorded none (older sessions,
    imports)."""
    if not isinstance(station_config, Mapping):
        return None
    per_leg = station_config.get("leg_materials")
    if not isinstance(per_leg, Mapping) or not per_leg:
        return None
    out = {}
    for key, d in per_leg.items():
        m = _material(d)
        if m is not None and str(key).isdigit():
            out[int(key)] = m
    if not out:
        return None
    metrology = station_config.get("metrology")
    ref = REFERENCE_TEMP_C
    if isinstance(metrology, Mapping):
        try:
            ref = float(metrology.get("reference_temp_c", REFERENCE_TEMP_C))
        except (TypeError, ValueError):
            ref = REFERENCE_TEMP_C
    return ref, out


@dataclass
class Normalisation:
    """The outcome of `normalise_points`. `points` is a copy whose `error_um` is the normalised
    error on the normalised legs and the raw error elsewhere."""

    points: np.ndarray
    reference_temp_c: float
    materials: dict[int, Material]
    normalised: tuple[int, ...] = ()
    raw: dict[int, str] = field(default_factory=dict)  # leg -> why its error stayed raw
    temp_range_c: dict[int, tuple[float, float]] = field(default_factory=dict)  # leg -> material min, max
    correction_range_um: dict[int, tuple[float, float]] = field(default_factory=dict)
    filled: dict[int, int] = field(default_factory=dict)  # leg -> points whose temperature was interpolated
    source: str = ""  # where the materials came from

    @property
    def any(self) -> bool:
        return bool(self.normalised)

    def lines(self) -> list[str]:
        """What was done, for a command's output."""
        if not self.normalised:
            why = "; ".join(f"leg {k}: {v}" for k, v in sorted(self.raw.items())) or "nothing to do"
            return [f"error: raw (not normalised to {self.reference_temp_c:g} degC: {why})"]
        out = [f"error: normalised to {self.reference_temp_c:g} degC material temperature (NDE; raw error_um "
               f"kept in the file; --raw to use it; materials from {self.source})"]
        for leg in self.normalised:
            m = self.materials[leg]
            lo, hi = self.temp_range_c[leg]
            clo, chi = self.correction_range_um[leg]
            fill = f", {self.filled[leg]} point(s) without a reading interpolated" if self.filled.get(leg) else ""
            out.append(f"  leg {leg}: material {lo:.2f} .. {hi:.2f} degC, {m.expansion_um_m_k:g} um/m/K fixed at "
                       f"{m.fixed_point_mm:g} mm, correction {clo:+.3f} .. {chi:+.3f} um{fill}")
        for leg, why in sorted(self.raw.items()):
            out.append(f"  leg {leg}: raw error ({why})")
        return out

    def to_json(self) -> dict[str, Any]:
        return {
            "reference_temp_c": self.reference_temp_c, "source": self.source,
            "normalised_legs": list(self.normalised), "raw_legs": {str(k): v for k, v in self.raw.items()},
            "material_temp_range_c": {str(k): list(v) for k, v in self.temp_range_c.items()},
            "correction_range_um": {str(k): list(v) for k, v in self.correction_range_um.items()},
            "materials": {str(k): vars(m) for k, m in self.materials.items() if k in self.normalised},
        }


def material_temp_ranges(points: np.ndarray) -> dict[int, tuple[float, float]]:
    """Per leg, the (min, max) recorded material temperature, degC; legs without one left out."""
    out = {}
    for leg in np.unique(points["leg"]) if len(points) else ():
        t = points["material_temp_c"][points["leg"] == leg]
        t = t[np.isfinite(t)]
        if t.size:
            out[int(leg)] = (float(t.min()), float(t.max()))
    return out


def _between_readings(temp_c: np.ndarray, time_s: np.ndarray) -> np.ndarray:
    """The material temperature at each point's time, interpolated linearly between sensor
    readings. The sweep reads the sensors at most every 10 s and records the last reading with
    every point; a reading is taken where the recorded value changes (at that point's time), so
    the value is known exactly there and is interpolated in between (held after the last
    reading). Without times, or when every point has its own reading, nothing changes."""
    if len(temp_c) < 3 or not np.all(np.isfinite(time_s)):
        return temp_c
    order = np.argsort(time_s, kind="stable")
    t, v = time_s[order], temp_c[order]
    knots = np.flatnonzero(np.r_[True, v[1:] != v[:-1]])
    if len(knots) == len(v) or len(knots) < 2 or np.any(np.diff(t[knots]) <= 0):
        return temp_c
    out = np.empty_like(temp_c)
    out[order] = np.interp(t, t[knots], v[knots])
    return out


def normalise_points(points: np.ndarray, materials: Mapping[int, Any], reference_temp_c: float = REFERENCE_TEMP_C,
                     source: str = "") -> Normalisation:
    """Normalise each leg's `error_um` to `reference_temp_c` from its `material_temp_c`.

    A leg without any material temperature keeps its raw error (said in `raw`); points of a leg
    missing a reading between others get the temperature interpolated in recording order (the
    sweep reads the environment every few seconds, so gaps are short), counted in `filled`.
    """
    out = points.copy()
    mats = {int(k): (v if isinstance(v, Material) else Material(float(v.expansion_um_m_k),
                                                             float(getattr(v, "expansion_u_um_m_k", 1.0)),
                                                             float(v.fixed_point_mm)))
            for k, v in materials.items()}
    result = Normalisation(out, float(reference_temp_c), mats, source=source)
    normalised = []
    for leg in (np.unique(points["leg"]) if len(points) else ()):
        leg = int(leg)
        rows = np.flatnonzero(points["leg"] == leg)
        temp = np.asarray(points["material_temp_c"][rows], dtype=float)
        known = np.isfinite(temp)
        if leg not in mats:
            result.raw[leg] = "no material configured for it"
            continue
        if not known.any():
            result.raw[leg] = "no material temperature recorded"
            continue
        if not known.all():
            order = np.argsort(points["index"][rows], kind="stable")
            t_sorted = temp[order]
            k_sorted = known[order]
            pos = np.arange(len(order))
            t_sorted = np.interp(pos, pos[k_sorted], t_sorted[k_sorted])
            temp = np.empty_like(temp)
            temp[order] = t_sorted
            result.filled[leg] = int(np.count_nonzero(~known))
        temp = _between_readings(temp, np.asarray(points["time_s"][rows], dtype=float))
        corr = nde_correction_um(points["target_mm"][rows], temp, mats[leg], reference_temp_c)
        out["error_um"][rows] = points["error_um"][rows] - corr
        result.temp_range_c[leg] = (float(np.min(temp)), float(np.max(temp)))
        finite = corr[np.isfinite(corr)]
        result.correction_range_um[leg] = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 0.0)
        normalised.append(leg)
    result.normalised = tuple(normalised)
    return result


def normalise_session(points: np.ndarray, station_config: Mapping[str, Any] | None,
                      fallback: tuple[float, Mapping[int, Any], str] | None = None) -> Normalisation:
    """Normalise a session's points with the materials it recorded; a session that recorded none
    uses `fallback` = (reference_temp_c, leg -> material, where from), else steel 11.5 um/m/K
    fixed at 0 mm (the station's defaults), which the result's `source` says."""
    rec = recorded_materials(station_config)
    if rec is not None:
        ref, mats = rec
        return normalise_points(points, mats, ref, source="the session's recorded station config")
    if fallback is not None:
        ref, mats, where = fallback
        return normalise_points(points, mats, ref, source=where)
    return normalise_points(points, {leg: Material() for leg in LEG_NUMBERS}, REFERENCE_TEMP_C,
                            source="defaults (steel 11.5 um/m/K fixed at 0 mm; the session recorded none)")


def error_basis(session: Any, raw: bool = False) -> tuple[np.ndarray, list[str], dict[str, Any]]:
    """The points an analysis of `session` (as procedures.io.recording.reader reads it) uses, the
    lines saying which error that is, and the same as JSON: normalised to 20 degC by default,
    raw when `raw` (the `--raw` option of fit, iso230 and verify)."""
    if raw:
        return session.points, ["error: raw, not normalised to 20 degC (--raw)"], {"normalised": False}
    n = normalise_session(session.points, getattr(session, "station_config", None))
    return n.points, n.lines(), {"normalised": n.any, **n.to_json()}


def diagnosis_temperature_note(points: np.ndarray, station_config: Mapping[str, Any] | None = None
                               ) -> tuple[list[str], dict]:
    """For `station diagnose`, which works on the raw error (thermal expansion stays an effect it
    can find): per leg the material temperature range that the normalisation to 20 degC (the
    reference the session recorded) has to cover in the other analyses, as lines and as JSON."""
    rec = recorded_materials(station_config)
    reference_temp_c = rec[0] if rec is not None else REFERENCE_TEMP_C
    ranges = material_temp_ranges(points)
    doc = {"error": "raw", "reference_temp_c": reference_temp_c,
           "legs": {str(k): {"min_c": lo, "max_c": hi, "span_k": hi - lo,
                             "max_from_reference_k": max(abs(lo - reference_temp_c), abs(hi - reference_temp_c))}
                    for k, (lo, hi) in ranges.items()}}
    if not ranges:
        return ["error: raw; no material temperature recorded (fit, iso230 and verify cannot normalise it to "
                f"{reference_temp_c:g} degC either)"], doc
    lines = [f"error: raw (diagnosis does not normalise: thermal expansion stays a diagnosable effect); material "
             f"temperature that the normalisation to {reference_temp_c:g} degC of fit, iso230 and verify covers:"]
    for k, v in doc["legs"].items():
        lines.append(f"  leg {k}: {v['min_c']:.2f} .. {v['max_c']:.2f} degC (span {v['span_k']:.2f} K, up to "
                     f"{v['max_from_reference_k']:.2f} K from {reference_temp_c:g} degC)")
    return lines, doc
