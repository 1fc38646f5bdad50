"""Self-check sessions for the effect variants (issue 25): physics outside the plain library,
made with the project's own plant (drivers/plant/leg.py) and withheld from the twin.

Each session is one leg of 91 irregular targets, 5 cycles, the plant's lead, long-wave, wobble,
noise and pass offsets, a material temperature that changes (ambient cycling) and loads that
change from pass to pass (a confounder), with one physics:

- `backlash_temperature`: a reversal that changes with material temperature (um/K);
- `backlash_position`: a reversal larger over the most-used part of the stroke (nut wear);
- `windup`: lost motion winding up over a few millimetres after each reversal;
- `thermal_gradient`: thermal expansion growing along the screw (error ~ position^2 while warming);
- `clean`: none of them (and no other effect): nothing may be named;
- issue 35's situations (warm_reversal, stacked, reference_wobble, fleet_duplicates): made in
  station/services/selfcheck_stacked.py.

The twin is fitted on the session (even seeds) or the plant without the withheld effect (odd
seeds). The truth carries the effect's name, its variant and the checked parameters.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from station.services.selfcheck_stacked import SITUATIONS  # issue 35's situations (selfcheck_stacked.py)

if TYPE_CHECKING:
    from procedures.diagnosis.selfcheck import Trial


VARIANT_PHYSICS = ("backlash_temperature", "backlash_position", "windup", "thermal_gradient", "clean")
PHYSICS = VARIANT_PHYSICS + SITUATIONS
BASE_SOURCES = ("lead", "longwave", "wobble", "noise", "run_offset")
OVERRUN_MM = 2.0  # synth_session's overrun before each reversal: the wind-up's travel before the first target
VARIANT_RMS_UM = (0.3, 1.5)  # RMS of the variant's own part (beyond the plain effect), log-uniform


def _log_uniform(rng, lo, hi) -> float:
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def _centred(v: np.ndarray, x: np.ndarray, fitted: bool) -> np.ndarray:
    """What of a contribution a twin cannot absorb (per-position mean for a fitted twin, the
    overall mean for an external one)."""
    if not fitted:
        return v - v.mean()
    _, inv = np.unique(x, return_inverse=True)
    return v - (np.bincount(inv, v) / np.bincount(inv))[inv]


def _since_first_target_mm(points: np.ndarray) -> np.ndarray:
    """Travel since the first target of each run (one leg), mm."""
    out = np.zeros(points.size)
    for r in np.unique(points["run"]):
        sel = points["run"] == r
        out[sel] = np.abs(points["target_mm"][sel] - points["target_mm"][sel][0])
    return out


def _beyond(part: np.ndarray, cols: list[np.ndarray], x: np.ndarray, fitted: bool) -> float:
    """RMS of what a variant adds beyond its plain effect: `part` less its least-squares fit by
    the plain effect's `cols` and what the twin absorbs."""
    a = np.column_stack([_centred(c, x, fitted) for c in cols]) if cols else np.zeros((x.size, 0))
    p = _centred(part, x, fitted)
    if a.shape[1]:
        p = p - a @ np.linalg.lstsq(a, p, rcond=None)[0]
    return max(float(np.std(p)), 1e-9)


def variant_trial(seed: int, physics: str, n_targets: int = 91, cycles: int = 5) -> Trial:
    """One session with `physics` (PHYSICS) withheld from the twin; deterministic for the seed."""
    from procedures.diagnosis.selfcheck import Trial
    from drivers.plant.leg import default_leg_configs, systematic_error_um
    from station.services.synth import synth_session
    from station.services.twins import plant_twin

    if physics in SITUATIONS:
        from station.services.selfcheck_stacked import situation_trial

        return situation_trial(seed, physics, n_targets, cycles)
    if physics not in PHYSICS:
        raise ValueError(f"unknown physics {physics!r}; known: {', '.join(PHYSICS)}")
    rng = np.random.default_rng(20_000 + 7 * seed + PHYSICS.index(physics))
    fitted = seed % 2 == 0
    leg = int(rng.integers(1, 7))
    step = 180.0 / (n_targets - 1)
    targets = np.linspace(-90, 90, n_targets) + rng.uniform(-0.3, 0.3, n_targets) * step
    targets[0], targets[-1] = -90.0, 90.0
    dwell_s = 4.0
    session_s = 2 * cycles * n_targets * (dwell_s + step / 10.0)
    cfg = replace(
        default_leg_configs(int(rng.integers(0, 1000)), 6)[leg - 1], enabled=frozenset(BASE_SOURCES),
        drift_um_per_h=0.0, initial_temp_c=20.0 + float(rng.uniform(-1.0, 1.0)), tau_s=float(rng.uniform(900, 2400)),
        ambient_swing_k=float(rng.uniform(0.6, 1.2)) * float(rng.choice([-1, 1])),
        ambient_period_s=float(rng.uniform(0.5, 1.2)) * session_s,
        load_per_pass_n=tuple(float(v) for v in rng.uniform(0, 500, 2 * cycles + 2)) if rng.random() < 0.5 else (0.0,),
    )
    base = cfg
    dry = synth_session({leg: cfg}, targets, cycles, seed=seed, dwell_s=dwell_s)
    x, d, temp = dry["target_mm"], dry["direction"].astype(float), dry["material_temp_c"]
    m = _log_uniform(rng, *VARIANT_RMS_UM)
    truth: dict = {}
    if physics.startswith("backlash") or physics == "windup":
        r0 = _log_uniform(rng, 0.6, 3.0)
        cfg = replace(cfg, reversal_um=r0, enabled=cfg.enabled | {"backlash"})
        if physics == "backlash_temperature":
            dt = temp - cfg.temp_ref_c
            k = m / _beyond(-0.5 * d * dt, [-0.5 * d], x, fitted) * float(rng.choice([-1, 1]))
            cfg = replace(cfg, reversal_um_per_k=k)
            truth = {"backlash": {"variant": "temperature", "reversal_um_per_k": k}}
        elif physics == "backlash_position":
            c, h = float(rng.uniform(-60, 60)), 200.0  # the worn part: a parabola over the whole stroke
            unit = replace(cfg, reversal_um=0.0, reversal_wear_um=1.0, reversal_wear_centre_mm=c,
                           reversal_wear_half_width_mm=h).only("backlash")
            part = systematic_error_um(unit, x, d, temp, 0.0, 0.0)
            w = m / _beyond(part, [-0.5 * d], x, fitted)
            cfg = replace(cfg, reversal_wear_um=w, reversal_wear_centre_mm=c, reversal_wear_half_width_mm=h)
            xs = np.linspace(-90, 90, 361)
            rev = cfg.reversal_um + w * np.maximum(0.0, 1 - ((xs - c) / h) ** 2)
            truth = {"backlash": {"variant": "position", "reversal_change_um": float(np.ptp(rev)),
                                  "reversal_max_at_mm": float(xs[int(np.argmax(rev))])}}
        else:
            lw = float(rng.uniform(2.0, 8.0))
            first = _since_first_target_mm(dry)
            part = d * np.exp(-(first + OVERRUN_MM) / lw)  # per um of reversal
            cfg = replace(cfg, windup_mm=lw, reversal_um=m / _beyond(part, [-0.5 * d], x, fitted))
            truth = {"backlash": {"variant": "windup", "windup_mm": lw}}
    elif physics == "thermal_gradient":
        alpha = float(rng.uniform(8.0, 20.0))
        cfg = replace(cfg, expansion_ppm_per_k=alpha, bearing_mm=float(rng.choice([-1, 1])) * float(rng.uniform(120, 250)),
                      enabled=cfg.enabled | {"thermal"})
        unit = systematic_error_um(cfg.only("thermal"), x, 1, temp, 0, 0)
        k = _log_uniform(rng, 0.6, 3.0) / max(float(np.std(_centred(unit, x, fitted))), 1e-9)
        cfg = replace(cfg, initial_temp_c=20 + k * (cfg.initial_temp_c - 20), ambient_swing_k=k * cfg.ambient_swing_k,
                      heating_k_per_m=k * cfg.heating_k_per_m)
        base = replace(base, initial_temp_c=cfg.initial_temp_c, ambient_swing_k=cfg.ambient_swing_k,
                       heating_k_per_m=cfg.heating_k_per_m)
        dry = synth_session({leg: cfg}, targets, cycles, seed=seed, dwell_s=dwell_s)
        temp = dry["material_temp_c"]
        grad_unit = replace(cfg, expansion_ppm_per_k=0.0, expansion_gradient_ppm_per_k_per_m=1.0).only("thermal")
        part = systematic_error_um(grad_unit, x, 1, temp, 0, 0)
        dt = temp - cfg.temp_ref_c
        g = m / _beyond(part, [dt, dt * x], x, fitted) * float(rng.choice([-1, 1]))
        cfg = replace(cfg, expansion_gradient_ppm_per_k_per_m=g)
        truth = {"thermal": {"variant": "gradient", "expansion_gradient_ppm_per_k_per_m": g,
                             "expansion_ppm_per_k": alpha - g * cfg.bearing_mm / 1000.0}}
    points = synth_session({leg: cfg}, targets, cycles, seed=seed, dwell_s=dwell_s)
    true_um = np.zeros(points.size)
    if truth:
        (eff,) = truth
        first = _since_first_target_mm(points)
        true_um = systematic_error_um(cfg.only(eff), points["target_mm"], points["direction"], points["material_temp_c"],
                                      points["load_n"], points["time_s"], first + OVERRUN_MM)
    twin = None if fitted else plant_twin({leg: base}, "simulated plant without the withheld effect")
    return Trial(seed, points, twin, {leg: truth}, true_um, physics, {"legs": [leg], "physics": physics})
