"""The candidate effects: each a few-parameter physical extension of the twin.

Every effect adds columns to the regression of the gap (measured minus twin, um). Parameter names
and meanings (shared/docs/domain.md section 4; the JSON report uses exactly these):

- backlash  `reversal_um`: mean error on negative-direction passes minus on positive ones.
            Column -direction/2.
- thermal   `expansion_ppm_per_k`: change of d(error)/d(position) per kelvin of material
            temperature, um per metre per kelvin; also `offset_um_per_k` (error change at
            mid-stroke per kelvin) and `bearing_mm` (where the thermal error vanishes: the fixed
            bearing). Columns dT and dT * x/1000, dT = material temperature - 20 C (lengths are
            normalised to 20 C).
- load      `compliance_um_per_kn`: minus d(error)/d(load) at mid-stroke (x = 0), um per kN;
            also `screw_compliance_um_per_kn_per_m` (minus the change of that with position).
            Columns L and L * x/1000, L = axial load in kN (compression positive).
- drift     `drift_um_per_h`: error growing with time, independent of position. Column t in h
            (without recorded time: pass order, `drift_um_per_pass`).
- scale     `scale_ppm`: slope against the twin, um per metre of position. Column x/1000.
- speed     `lag_up_ms`, `lag_down_ms`: on-the-fly readings lag by lag x speed (error = -lag x
            speed, um = ms x mm/s). Columns speed x (direction > 0), speed x (direction < 0).
- cyclic    `wavelength_mm`, `amplitude_um` (and `phase_rad`: error = A sin(2 pi x/wavelength +
            phase), x in mm from mid-stroke). Columns sin, cos at a wavelength found by a
            least-squares sinusoid scan of the remaining gap.

Scale and cyclic are only testable against an external twin: a twin fitted on the same
recording already contains every position-only shape the data support.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from procedures.diagnosis.legdata import LegData

TEMP_REF_C = 20.0
MIN_TEMP_RANGE_K = 0.05  # below this the material temperature hardly changed (sensor steps)
MIN_LOAD_RANGE_KN = 0.02
MIN_TIME_RANGE_H = 1.0 / 60.0
MIN_TARGETS_CYCLIC = 8


@dataclass(frozen=True)
class Effect:
    name: str
    n_params: int
    position_only: bool = False  # absorbed by a twin fitted on the same recording

    def applicable(self, leg: LegData, external_twin: bool) -> str | None:
        """None when the effect can be tested on this leg, else the reason why not."""
        return None

    def columns(self, leg: LegData, spec=None) -> np.ndarray:
        raise NotImplementedError

    def parameters(self, coef: np.ndarray, cov: np.ndarray, spec=None, leg: LegData | None = None,
                   resid_um: np.ndarray | None = None) -> tuple[dict, dict]:
        """(parameters, standard errors) from the fitted coefficients of `columns`."""
        raise NotImplementedError


def _se(cov: np.ndarray, i: int) -> float:
    return float(np.sqrt(max(cov[i, i], 0.0)))


class Backlash(Effect):
    def applicable(self, leg, external_twin):
        up, down = leg.passes_of_direction(1), leg.passes_of_direction(-1)
        if up == 0 or down == 0:
            return "passes in only one direction"
        if min(up, down) < 2:
            return f"only {min(up, down)} pass in one direction; the reversal cannot be told from pass scatter"
        return None

    def columns(self, leg, spec=None):
        return (-0.5 * leg.direction)[:, None]

    def parameters(self, coef, cov, spec=None, leg=None, resid_um=None):
        return {"reversal_um": float(coef[0])}, {"reversal_um": _se(cov, 0)}


class Thermal(Effect):
    def applicable(self, leg, external_twin):
        if not leg.has_temp:
            return "no material temperature recorded"
        rng = float(np.ptp(leg.temp_c))
        if rng < MIN_TEMP_RANGE_K:
            return f"material temperature changed by only {rng:.3f} K; thermal expansion needs a temperature change"
        return None

    def columns(self, leg, spec=None):
        dt = leg.temp_c - TEMP_REF_C
        return np.column_stack([dt, dt * leg.x_mm / 1000.0])

    def parameters(self, coef, cov, spec=None, leg=None, resid_um=None):
        a, b = float(coef[0]), float(coef[1])
        params = {"expansion_ppm_per_k": b, "offset_um_per_k": a}
        se = {"expansion_ppm_per_k": _se(cov, 1), "offset_um_per_k": _se(cov, 0)}
        # bearing = -1000 a / b, delta method; only meaningful when the slope is clearly nonzero
        if abs(b) > 3 * se["expansion_ppm_per_k"] and b != 0:
            g = np.array([-1000.0 / b, 1000.0 * a / b**2])
            params["bearing_mm"] = -1000.0 * a / b
            se["bearing_mm"] = float(np.sqrt(max(g @ cov[:2, :2] @ g, 0.0)))
        return params, se


class Load(Effect):
    def applicable(self, leg, external_twin):
        if not leg.has_load:
            return "no axial load recorded"
        rng = float(np.ptp(leg.load_kn))
        if rng < MIN_LOAD_RANGE_KN:
            return f"axial load varied by only {1000 * rng:.0f} N; compliance needs passes at different loads"
        return None

    def columns(self, leg, spec=None):
        return np.column_stack([leg.load_kn, leg.load_kn * leg.x_mm / 1000.0])

    def parameters(self, coef, cov, spec=None, leg=None, resid_um=None):
        return (
            {"compliance_um_per_kn": -float(coef[0]), "screw_compliance_um_per_kn_per_m": -float(coef[1])},
            {"compliance_um_per_kn": _se(cov, 0), "screw_compliance_um_per_kn_per_m": _se(cov, 1)},
        )


class Drift(Effect):
    """Without recorded time, pass order stands in for time (sweeps run passes back to back):
    the parameter is then `drift_um_per_pass`."""

    def applicable(self, leg, external_twin):
        if leg.has_time:
            if float(np.ptp(leg.time_h)) < MIN_TIME_RANGE_H:
                return "the session lasted under a minute"
        elif leg.n_passes < 4:
            return "no time recorded and too few passes to use pass order instead"
        return None

    def columns(self, leg, spec=None):
        return (leg.time_h if leg.has_time else leg.pass_id.astype(float))[:, None]

    def parameters(self, coef, cov, spec=None, leg=None, resid_um=None):
        name = "drift_um_per_h" if leg is None or leg.has_time else "drift_um_per_pass"
        return {name: float(coef[0])}, {name: _se(cov, 0)}


class Scale(Effect):
    def applicable(self, leg, external_twin):
        if not external_twin:
            return "a twin fitted on this recording already holds the slope (use --twin)"
        if leg.n_targets < 3:
            return f"only {leg.n_targets} distinct targets"
        return None

    def columns(self, leg, spec=None):
        return (leg.x_mm / 1000.0)[:, None]

    def parameters(self, coef, cov, spec=None, leg=None, resid_um=None):
        return {"scale_ppm": float(coef[0])}, {"scale_ppm": _se(cov, 0)}


MIN_SPEED_RANGE_MM_S = 0.5


class Speed(Effect):
    """The error of on-the-fly readings that grows with the speed (the leg end lagging the
    encoder): columns speed x (direction > 0) and speed x (direction < 0), mm/s, so the lag may
    differ by direction. Separable from backlash only when the speed changes between passes of a
    direction (at one speed per direction it is a constant per direction: a reversal)."""

    def applicable(self, leg, external_twin):
        if not leg.has_speed:
            return "no speed recorded (readings at rest, or not an on-the-fly session)"
        for d in (1.0, -1.0):
            sel = leg.direction == d
            if sel.any() and float(np.ptp(np.abs(leg.speed_mm_s[sel]))) >= MIN_SPEED_RANGE_MM_S:
                return None
        return ("the speed did not change between passes: a speed-dependent error cannot be told from a reversal "
                "(record passes at two or more speeds)")

    def columns(self, leg, spec=None):
        v = leg.speed_mm_s
        return np.column_stack([v * (leg.direction > 0), v * (leg.direction < 0)])

    def parameters(self, coef, cov, spec=None, leg=None, resid_um=None):
        # error = -lag * speed: um = -(ms) * (mm/s)
        return ({"lag_up_ms": -float(coef[0]), "lag_down_ms": -float(coef[1])},
                {"lag_up_ms": _se(cov, 0), "lag_down_ms": _se(cov, 1)})


def cyclic_grid(leg: LegData, oversample: int = 4) -> np.ndarray:
    """Frequencies (cycles/mm) scanned for a cyclic error: from one wavelength over the stroke
    to the Nyquist frequency of the target spacing, `oversample` points per 1/span."""
    lo, hi = leg.span_mm
    span = hi - lo
    if leg.n_targets < MIN_TARGETS_CYCLIC or span <= 0:
        return np.zeros(0)
    f_nyq = 0.5 / leg.spacing_mm
    df = 1.0 / (oversample * span)
    return np.arange(1.0 / span, f_nyq + 0.5 * df, df)


class Cyclic(Effect):
    def applicable(self, leg, external_twin):
        if not external_twin:
            return "a twin fitted on this recording already holds every periodic shape the data support (use --twin)"
        if leg.n_targets < MIN_TARGETS_CYCLIC:
            return f"only {leg.n_targets} distinct targets; a periodic error cannot be resolved"
        return None

    def independent_frequencies(self, leg: LegData) -> int:
        """How many independent wavelengths the scan tries (for the look-elsewhere correction)."""
        return max(1, cyclic_grid(leg).size // 4)

    def columns(self, leg, spec=None):
        ang = 2 * np.pi * leg.x_mm / spec
        return np.column_stack([np.sin(ang), np.cos(ang)])

    def parameters(self, coef, cov, spec=None, leg=None, resid_um=None):
        a, b = float(coef[0]), float(coef[1])
        amp = float(np.hypot(a, b))
        params = {"wavelength_mm": float(spec), "amplitude_um": amp, "phase_rad": float(np.arctan2(b, a))}
        se = {"amplitude_um": float(np.sqrt(max((a * a * cov[0, 0] + 2 * a * b * cov[0, 1] + b * b * cov[1, 1]) / max(amp * amp, 1e-300), 0.0)))}
        se["phase_rad"] = float(np.sqrt(max((b * b * cov[0, 0] - 2 * a * b * cov[0, 1] + a * a * cov[1, 1]) / max(amp**4, 1e-300), 0.0)))
        # wavelength: linearised (Gauss-Newton) uncertainty from the derivative column, with the
        # residual scatter of the final model
        if leg is not None and resid_um is not None and amp > 0:
            x = leg.x_mm
            ang = 2 * np.pi * x / spec
            d_dlam = (a * np.cos(ang) - b * np.sin(ang)) * (-2 * np.pi * x / spec**2)
            j = np.column_stack([np.sin(ang), np.cos(ang), d_dlam])
            s2 = float(np.mean(resid_um**2))
            try:
                cj = s2 * np.linalg.inv(j.T @ j)
                se["wavelength_mm"] = float(np.sqrt(max(cj[2, 2], 0.0)))
            except np.linalg.LinAlgError:
                pass
        return params, se


EFFECTS: dict[str, Effect] = {
    "backlash": Backlash("backlash", 1),
    "thermal": Thermal("thermal", 2),
    "load": Load("load", 2),
    "drift": Drift("drift", 1),
    "scale": Scale("scale", 1, position_only=True),
    "cyclic": Cyclic("cyclic", 3, position_only=True),
    "speed": Speed("speed", 2),
}
"""The candidate library, by name. `n_params` counts free parameters (cyclic: wavelength too)."""
