"""Synthetic sessions straight from the plant (drivers/plant), without devices or protocol: every
session the station makes from the leg's physics alone is made here.

- `synth_session`: a bidirectional sweep of each leg, the motion sequence of the sweep procedure
  (an overrun before each reversal), so backlash, heating and pass offsets come out as on the rig.
  For analysis tests, benchmarks and the diagnosis self-check, where thousands of sessions are
  needed and the Modbus/serial path is covered by the integration tests.
- `sample_plant_configs`: the legs of the sample recordings (recordings/), which
  station/services/samples.py sweeps on the simulated rig (real Modbus and pty: it needs the
  devices, so it stays in the station layer).
- The diagnosis self-check's sessions (`station diagnose --self-check`, tests, benches): effects
  present in the plant but withheld from the twin. `selfcheck_trial` (1-2 legs, the library's
  effects), `variant_trial` (issue 25's variants: VARIANT_PHYSICS) and `situation_trial` (issue
  35's situations: SITUATIONS; `variant_trial` dispatches to it). Odd seeds use the plant without
  the withheld effects as twin, even seeds the twin fitted on the session.

Deterministic for a seed. Signs as in the plant: `error_um` is measured minus target.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from drivers.plant.leg import LegPlant, PlantConfig, default_leg_configs, systematic_error_um
from procedures.io.recording.schema import POINT_DTYPE

if TYPE_CHECKING:
    from procedures.diagnosis.selfcheck import Trial  # scipy: imported where a Trial is made


def synth_session(
    configs: dict[int, PlantConfig],
    targets_mm,
    cycles: int = 5,
    seed: int = 0,
    dwell_s: float = 2.0,
    velocity_mm_s: float = 10.0,
    overrun_mm: float = 2.0,
    air=(20.0, 1013.25, 45.0),
) -> np.ndarray:
    """Simulate a bidirectional sweep of each leg in `configs` (leg number -> plant config).

    Returns a POINT_DTYPE array: one row per point, runs numbered per leg (odd runs upward,
    even runs downward), `error_um` = measured - target, `time_s` since the leg's start.
    """
    targets = np.sort(np.asarray(targets_mm, dtype=float))
    rows = []
    index = 0
    for leg in sorted(configs):
        plant = LegPlant(configs[leg], seed=seed * 1000 + leg)
        t = 0.0
        # approach the first target from below, as the sweep procedure does
        start = targets[0] - overrun_mm
        t += abs(start - plant.x_mm) / velocity_mm_s
        plant.move(start, t)
        run = 0
        for _cycle in range(cycles):
            for direction, seq in ((1, targets), (-1, targets[::-1])):
                run += 1
                for target in seq:
                    t += abs(target - plant.x_mm) / velocity_mm_s
                    plant.move(float(target), t)
                    t += dwell_s
                    measured = plant.measured_position_mm(t)
                    rows.append(
                        (
                            index, leg, run, direction, target, target, target, measured,
                            (measured - target) * 1000.0, t, air[0], air[1], air[2],
                            plant.material_temp_c(t), plant.load_n, 90.0, 0, float("nan"),  # speed: read at rest
                        )
                    )
                    index += 1
                # overrun beyond the end before reversing
                end = seq[-1] + direction * overrun_mm
                t += abs(end - plant.x_mm) / velocity_mm_s
                plant.move(end, t)
    return np.array(rows, dtype=POINT_DTYPE)


# -- the legs of the sample recordings ----------------------------------------------------------------
SAMPLE_SEED = 1
SAMPLE_LOADS_N = (150.0, 150.0, 450.0, 450.0)  # axial load per pass: changes between bidirectional cycles
SAMPLE_AMBIENT_SWING_K = 0.3
SAMPLE_AMBIENT_PERIOD_S = 2.0 * 3600.0
# the drives' jerk limit the samples were made with (0 = not limited): pinned, not the station's
# sim default (a real leg's, station.services.config.SimConfig.jerk_mm_s3), so recordings/*.h5 regenerate
# point for point; recorded in each sample's station_config as sim.jerk_mm_s3
SAMPLE_JERK_MM_S3 = 0.0


def sample_plant_configs(seed: int = SAMPLE_SEED) -> list[PlantConfig]:
    """The six legs of the sample recordings: the simulator's default legs with the load and the
    room temperature changing during the session, so that thermal, load and drift effects are all
    present and separable."""
    base = replace(PlantConfig(), load_per_pass_n=SAMPLE_LOADS_N, ambient_swing_k=SAMPLE_AMBIENT_SWING_K,
                   ambient_period_s=SAMPLE_AMBIENT_PERIOD_S, jerk_mm_s3=SAMPLE_JERK_MM_S3)
    return default_leg_configs(seed, 6, base)


# -- the diagnosis self-check's sessions --------------------------------------------------------------
FITTED_TWIN_EFFECTS = ("backlash", "thermal", "load", "drift")
SIM_TWIN_EFFECTS = FITTED_TWIN_EFFECTS + ("scale", "cyclic")
SELF_CHECK_CONTRIBUTION_UM = (0.3, 3.0)  # RMS of a withheld effect against the twin, log-uniform
BASE_SOURCES = ("lead", "longwave", "wobble", "noise", "run_offset")  # every self-check leg's plant
SEPARABLE_MAX_CORRELATION = 0.9  # |correlation| of pass temperature with pass time, else drawn again
SITUATIONS = ("warm_reversal", "stacked", "reference_wobble", "fleet_duplicates")
VARIANT_PHYSICS = ("backlash_temperature", "backlash_position", "windup", "thermal_gradient", "clean")
PHYSICS = VARIANT_PHYSICS + SITUATIONS  # what `station diagnose --self-check --variants` accepts
OVERRUN_MM = 2.0  # synth_session's overrun before each reversal: the wind-up's travel before the first target
VARIANT_RMS_UM = (0.3, 1.5)  # RMS of the variant's own part (beyond the plain effect), log-uniform


def _centred(v: np.ndarray, x: np.ndarray, fitted: bool) -> np.ndarray:
    """What of a contribution the twin cannot absorb: minus the per-position mean (a twin fitted on
    the session) or minus the overall mean (an external twin's free zero)."""
    if not fitted:
        return v - v.mean()
    _, inv = np.unique(x, return_inverse=True)
    return v - (np.bincount(inv, v) / np.bincount(inv))[inv]


def _targets(rng, n_targets: int) -> np.ndarray:
    """Irregular targets over +/-90 mm (ISO 230-2): a regular grid with jitter, the ends exact."""
    step = 180.0 / (n_targets - 1)
    t = np.linspace(-90, 90, n_targets) + rng.uniform(-0.3, 0.3, n_targets) * step
    t[0], t[-1] = -90.0, 90.0
    return t


def _log_uniform(rng, lo, hi) -> float:
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def selfcheck_trial(seed: int, n_targets: int = 91, cycles: int = 5,
                    contribution_um: tuple[float, float] | None = None) -> Trial:
    """One self-check session: 1-2 legs of a realistic plant (lead, long-wave, wobble, noise,
    pass offsets, a material temperature that changes, sometimes varying load) with none, one or
    two effects present in the plant but withheld from the twin, at a random magnitude (RMS
    contribution log-uniform in SELF_CHECK_CONTRIBUTION_UM). Odd seeds use the plant as twin, even
    seeds the twin fitted on the session."""
    from procedures.diagnosis.selfcheck import Trial
    from procedures.diagnosis.twin import plant_twin

    rng = np.random.default_rng(10_000 + seed)
    fitted = seed % 2 == 0
    eligible = FITTED_TWIN_EFFECTS if fitted else SIM_TWIN_EFFECTS
    n_legs = int(rng.integers(1, 3))
    legs = sorted(int(v) for v in rng.choice(np.arange(1, 7), n_legs, replace=False))
    u = rng.random()
    n_eff = 0 if u < 0.2 else (1 if u < 0.6 else 2)
    chosen = [str(e) for e in rng.choice(eligible, n_eff, replace=False)]
    where = {e: int(rng.choice(legs)) for e in chosen}
    targets = _targets(rng, n_targets)
    dwell_s = 4.0
    pass_s = n_targets * (dwell_s + 180.0 / (n_targets - 1) / 10.0)
    session_s = 2 * cycles * pass_s
    lib = default_leg_configs(int(rng.integers(0, 1000)), 6)
    loaded = {leg for e, leg in where.items() if e == "load"}
    base = {leg: _base_leg(rng, lib[leg - 1], leg, leg in loaded, targets, cycles, seed, dwell_s, session_s)
            for leg in legs}
    dry = synth_session(base, targets, cycles, seed=seed, dwell_s=dwell_s)
    truth: dict[int, dict] = {leg: {} for leg in legs}
    real = dict(base)
    for eff in chosen:
        leg = where[eff]
        sel = dry["leg"] == leg
        m = float(np.exp(rng.uniform(*np.log(contribution_um or SELF_CHECK_CONTRIBUTION_UM))))
        cfg, truth[leg][eff] = _withhold(rng, eff, real[leg], dry[sel], m, fitted)
        real[leg] = replace(cfg, enabled=cfg.enabled | ({"longwave"} if eff == "cyclic" else {eff}))
    points = synth_session(real, targets, cycles, seed=seed, dwell_s=dwell_s)
    true_um = _true_contribution(points, truth, real, base)
    twin = None if fitted else plant_twin(base, "simulated plant without the withheld effects")
    label = ", ".join(f"{e}@leg{where[e]}" for e in chosen) or "no effect"
    return Trial(seed, points, twin, truth, true_um, label, {"legs": legs, "targets": n_targets, "cycles": cycles})


def _base_leg(rng, lib_cfg, leg: int, has_load: bool, targets, cycles: int, seed: int, dwell_s: float,
              session_s: float):
    """One leg of the plant without withheld effects: the base sources, a material temperature
    that changes, sometimes a load varying per pass; drawn again (up to 50 times) until its pass
    temperatures do not follow time linearly (thermal and drift stay separable)."""
    vary_load = has_load or rng.random() < 0.5
    loads = tuple(float(v) for v in rng.uniform(0, 500, 2 * cycles + 2)) if vary_load else (0.0,)
    for _attempt in range(50):
        cfg = replace(
            lib_cfg, enabled=frozenset(BASE_SOURCES), drift_um_per_h=0.0,
            # the material temperature changes in every session (a confounder for drift and scale)
            initial_temp_c=20.0 + float(rng.uniform(-1.0, 1.0)), tau_s=float(rng.uniform(900, 2400)),
            ambient_swing_k=float(rng.uniform(0.3, 1.0)) * float(rng.choice([-1, 1])),
            ambient_period_s=float(rng.uniform(0.5, 1.2)) * session_s,
            load_per_pass_n=loads,
            # the plant's compliance grows from the bearing up to the nut: with a load effect the
            # bearing is below the stroke; else it may be at either end (thermal works both ways)
            bearing_mm=(-1.0 if has_load else float(rng.choice([-1, 1]))) * float(rng.uniform(120, 250)),
        )
        # keep thermal and drift separable: the pass temperatures must not follow time linearly
        trial_pts = synth_session({leg: cfg}, targets, cycles, seed=seed, dwell_s=dwell_s)
        run = trial_pts["run"]
        t_pass = np.array([trial_pts["time_s"][run == r].mean() for r in np.unique(run)])
        temp_pass = np.array([trial_pts["material_temp_c"][run == r].mean() for r in np.unique(run)])
        if abs(np.corrcoef(t_pass, temp_pass)[0, 1]) <= SEPARABLE_MAX_CORRELATION:
            break
    return cfg


def _withhold(rng, eff: str, cfg, dry, m: float, fitted: bool):
    """`cfg` with effect `eff` added at RMS contribution `m` um against the twin (measured on the
    leg's points `dry` of the plant without it), and the effect's true parameters."""
    x, t_h = dry["target_mm"], dry["time_s"] / 3600.0
    temp, load_n = dry["material_temp_c"], dry["load_n"]
    if eff == "backlash":
        return replace(cfg, reversal_um=2 * m), {"reversal_um": 2 * m}
    if eff == "drift":
        d = m / float(np.std(_centred(t_h, x, fitted))) * float(rng.choice([-1, 1]))
        return replace(cfg, drift_um_per_h=d), {"drift_um_per_h": d}
    if eff == "scale":
        ppm = m / float(np.std(x / 1000.0)) * float(rng.choice([-1, 1]))
        return replace(cfg, scale_ppm=ppm), {"scale_ppm": ppm}
    if eff == "cyclic":
        lam = float(rng.uniform(8.0, 38.0))
        while any(abs(lam - w) < 0.15 * w for w in (cfg.lead_mm, 2 * cfg.lead_mm)):
            lam = float(rng.uniform(8.0, 38.0))
        amp = m * np.sqrt(2.0)
        cfg = replace(cfg, longwave=cfg.longwave + ((lam, amp, float(rng.uniform(0, 2 * np.pi))),))
        return cfg, {"wavelength_mm": lam, "amplitude_um": float(amp)}
    if eff == "thermal":
        e_ppm = float(rng.uniform(8.0, 20.0))
        unit = systematic_error_um(replace(cfg, expansion_ppm_per_k=e_ppm).only("thermal"), x, 1, temp, 0, 0)
        k = m / max(float(np.std(_centred(unit, x, fitted))), 1e-9)
        # scale the temperature excursion (not the steel) to reach the drawn magnitude
        cfg = replace(cfg, expansion_ppm_per_k=e_ppm, initial_temp_c=20 + k * (cfg.initial_temp_c - 20),
                      ambient_swing_k=k * cfg.ambient_swing_k, heating_k_per_m=k * cfg.heating_k_per_m)
        return cfg, {"expansion_ppm_per_k": e_ppm}
    if eff == "load":
        cfg = replace(cfg, bearing_compliance_um_per_kn=float(rng.uniform(1.0, 3.0)),
                      screw_compliance_um_per_kn_per_m=float(rng.uniform(10.0, 20.0)))
        unit = systematic_error_um(cfg.only("load"), x, 1, 20.0, load_n, 0)
        k = m / max(float(np.std(_centred(unit, x, fitted))), 1e-9)
        cfg = replace(cfg, load_per_pass_n=tuple(k * v for v in cfg.load_per_pass_n))
        return cfg, {"compliance_um_per_kn": cfg.compliance_um_per_kn}
    raise ValueError(f"unknown effect {eff!r}")


def _true_contribution(points, truth: dict[int, dict], real: dict, base: dict) -> np.ndarray:
    """The true contribution (um) of the withheld effects at every point."""
    true_um = np.zeros(points.size)
    for leg, effects in truth.items():
        sel = points["leg"] == leg
        p = points[sel]
        for eff in effects:
            cfg = real[leg]
            if eff == "cyclic":
                extra = replace(cfg, longwave=cfg.longwave[len(base[leg].longwave):]).only("longwave")
            else:
                extra = cfg.only(eff)
            true_um[sel] += systematic_error_um(extra, p["target_mm"], p["direction"], p["material_temp_c"],
                                                p["load_n"], p["time_s"])
    return true_um


# -- issue 25's variants: physics outside the plain library --------------------------------------------
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
    """One session with `physics` (PHYSICS) withheld from the twin; deterministic for the seed.

    One leg of 91 irregular targets, 5 cycles, the plant's lead, long-wave, wobble, noise and pass
    offsets, a material temperature that changes (ambient cycling) and loads that change from pass
    to pass (a confounder), with one physics: `backlash_temperature` (a reversal that changes with
    material temperature), `backlash_position` (a reversal larger over the most-used part of the
    stroke: nut wear), `windup` (lost motion winding up over a few millimetres after each reversal),
    `thermal_gradient` (thermal expansion growing along the screw: error ~ position^2 while
    warming) or `clean` (none of them, and no other effect: nothing may be named); issue 35's
    SITUATIONS are made by `situation_trial`. The truth carries the effect's name, its variant and
    the checked parameters."""
    if physics in SITUATIONS:
        return situation_trial(seed, physics, n_targets, cycles)
    if physics not in PHYSICS:
        raise ValueError(f"unknown physics {physics!r}; known: {', '.join(PHYSICS)}")
    from procedures.diagnosis.selfcheck import Trial
    from procedures.diagnosis.twin import plant_twin

    rng = np.random.default_rng(20_000 + 7 * seed + PHYSICS.index(physics))
    fitted = seed % 2 == 0
    leg = int(rng.integers(1, 7))
    targets = _targets(rng, n_targets)
    dwell_s = 4.0
    session_s = 2 * cycles * n_targets * (dwell_s + 180.0 / (n_targets - 1) / 10.0)
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


# -- issue 35's situations -----------------------------------------------------------------------------
def situation_trial(seed: int, physics: str, n_targets: int = 91, cycles: int = 5) -> Trial:
    """One session of `physics` (SITUATIONS); deterministic for the seed. One leg:

    - `warm_reversal`: a leg warming 2-4 K nearly linearly in time (drift and thermal look alike)
      with its reversal growing with the temperature: thermal and backlash / temperature, no drift;
    - `stacked`: the same warming leg whose nut is also worn over a stretch: thermal and backlash /
      temperature+position;
    - `reference_wobble`: a session diagnosed against a reference recording of the same leg
      (noisier, drifting) that shares its 5 mm lead wobble: nothing may be named;
    - `fleet_duplicates`: a clean leg against a fleet of clean siblings, one of them filed three
      times under different serials: the copies must be counted once and no feature of the leg may
      stand out from its siblings (the leg's own reversal and wobble differ from the fleet's mean,
      so effects against the fleet may be named: the fleet comparison is what is checked).

    The twin is fitted on the session (even seeds) or the plant without the withheld effects (odd
    seeds) where it applies (warm_reversal, stacked)."""
    from procedures.diagnosis.selfcheck import Trial  # scipy: not for `station diagnose --help`
    from procedures.diagnosis.twin import plant_twin

    if physics not in SITUATIONS:
        raise ValueError(f"unknown situation {physics!r}; known: {', '.join(SITUATIONS)}")
    rng = np.random.default_rng(35_000 + 11 * seed + SITUATIONS.index(physics))
    leg = int(rng.integers(1, 7))
    lib = default_leg_configs(int(rng.integers(0, 1000)), 8)
    cfg = replace(lib[leg - 1], enabled=frozenset(BASE_SOURCES), drift_um_per_h=0.0)
    dwell_s = 4.0
    if physics in ("warm_reversal", "stacked"):
        fitted = seed % 2 == 0
        targets = _targets(rng, n_targets)
        session_s = 2 * cycles * n_targets * (dwell_s + 180.0 / (n_targets - 1) / 10.0)
        rise_k, tau_s = float(rng.uniform(2.0, 4.0)), float(rng.uniform(6000.0, 12000.0))
        # a slow warm-up: the material temperature follows time nearly linearly (drift looks alike)
        base = replace(cfg, initial_temp_c=20.0, heating_k_per_m=0.0, tau_s=tau_s,
                       ambient_temp_c=20.0 + rise_k / (1.0 - np.exp(-session_s / tau_s)))
        alpha = float(rng.uniform(10.0, 13.0))
        k = float(rng.uniform(0.3, 0.7)) * float(rng.choice([-1, 1]))
        real = replace(base, enabled=base.enabled | {"thermal", "backlash"}, expansion_ppm_per_k=alpha,
                       bearing_mm=float(rng.choice([-1, 1])) * float(rng.uniform(120, 250)),
                       reversal_um=float(rng.uniform(1.0, 2.5)), reversal_um_per_k=k)
        truth = {"thermal": {"expansion_ppm_per_k": alpha},
                 "backlash": {"variant": "temperature", "reversal_um_per_k": k}}
        if physics == "stacked":
            # the worn part as the library's position variant sees it: a parabola over the stroke (a
            # stretch worn more than the rest; a local bump narrower than that is only partly followed)
            c, h = float(rng.uniform(-60, 60)), 200.0
            xs = np.linspace(-90, 90, 361)
            shape = np.maximum(0.0, 1 - ((xs - c) / h) ** 2)
            # the reversal 0.6-2 um larger over the worn part than at the least worn end (a nut's wear)
            w = float(rng.uniform(0.6, 2.0)) / float(np.ptp(shape))
            real = replace(real, reversal_wear_um=w, reversal_wear_centre_mm=c, reversal_wear_half_width_mm=h)
            wear = w * shape
            truth["backlash"] = {"variant": "temperature+position", "reversal_um_per_k": k,
                                 "reversal_change_um": float(np.ptp(wear)), "reversal_max_at_mm": float(xs[np.argmax(wear)])}
        points = synth_session({leg: real}, targets, cycles, seed=seed, dwell_s=dwell_s)
        true_um = np.zeros(points.size)
        for eff in ("thermal", "backlash"):
            true_um += systematic_error_um(real.only(eff), points["target_mm"], points["direction"],
                                           points["material_temp_c"], points["load_n"], points["time_s"])
        twin = None if fitted else plant_twin({leg: base}, "simulated plant without the withheld effects")
        info = {"legs": [leg], "physics": physics, "rise_k": float(np.ptp(points["material_temp_c"]))}
        return Trial(seed, points, twin, {leg: truth}, true_um, physics, info)
    if physics == "reference_wobble":
        from procedures.diagnosis.reference_twin import twin_from_recording

        targets = _targets(rng, 181)  # 1 mm apart: the 5 mm lead resolved
        here_cfg = replace(cfg, wobble_amplitude_um=float(rng.uniform(0.08, 0.3)))
        ref_cfg = replace(here_cfg, enabled=here_cfg.enabled | {"drift"}, drift_um_per_h=float(rng.uniform(1.0, 4.0)),
                          noise_um=float(rng.uniform(0.1, 0.35)))
        ref = synth_session({leg: ref_cfg}, targets, 4, seed=seed + 100_000, dwell_s=1.0)
        points = synth_session({leg: here_cfg}, targets, cycles, seed=seed, dwell_s=1.0)
        twin = twin_from_recording(ref, "the reference recording")
        return Trial(seed, points, twin, {leg: {}}, np.zeros(points.size), physics, {"legs": [leg], "physics": physics})
    # fleet_duplicates
    from procedures.diagnosis.fleet import error_map, fleet_leg, fleet_twin, independent_maps

    targets = np.linspace(-88.0, 88.0, 45)
    maps = {}
    for i in range(5):
        sib = synth_session({1: replace(lib[i], enabled=frozenset(BASE_SOURCES) | {"backlash"}, drift_um_per_h=0.0)},
                            targets, 3, seed=seed * 10 + i, dwell_s=1.0)
        maps[f"SN-{i}"] = error_map(sib, 1)
    for k in (1, 2):  # SN-4's session filed again under two more serials
        maps[f"SN-4-copy{k}"] = maps["SN-4"]
    unique, duplicates = independent_maps(maps)
    points = synth_session({1: replace(lib[6], enabled=frozenset(BASE_SOURCES) | {"backlash"}, drift_um_per_h=0.0)},
                           targets, 3, seed=seed * 10 + 7, dwell_s=1.0)
    twin = fleet_twin({1: fleet_leg(points["target_mm"], unique)}, "SIM", "fleet of simulated siblings", False,
                      {"duplicates": duplicates})
    twin.comparison(1, error_map(points, 1), 5.0)  # made first, as station diagnose does (the scale guard)
    info = {"legs": [1], "physics": physics, "expected_duplicates": {"SN-4-copy1": "SN-4", "SN-4-copy2": "SN-4"}}
    return Trial(seed, points, twin, {1: {}}, np.zeros(points.size), physics, info)
