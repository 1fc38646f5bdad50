"""The diagnosis self-check's sessions: simulated recordings with known effects present in the
plant but withheld from the twin (`station diagnose --self-check`, tests, benches). Made with the
simulated plant here, so procedures/diagnosis never imports the simulator."""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from procedures.diagnosis.selfcheck import Trial


FITTED_TWIN_EFFECTS = ("backlash", "thermal", "load", "drift")
SIM_TWIN_EFFECTS = FITTED_TWIN_EFFECTS + ("scale", "cyclic")
SELF_CHECK_CONTRIBUTION_UM = (0.3, 3.0)  # RMS of a withheld effect against the twin, log-uniform
BASE_SOURCES = ("lead", "longwave", "wobble", "noise", "run_offset")
SEPARABLE_MAX_CORRELATION = 0.9  # |correlation| of pass temperature with pass time, else drawn again


def _removed(v: np.ndarray, x: np.ndarray, fitted: bool) -> np.ndarray:
    """What of a contribution the baseline cannot absorb: minus the per-position mean (a twin
    fitted on the session) or minus the overall mean (an external twin's free zero)."""
    if not fitted:
        return v - v.mean()
    ux, inv = np.unique(x, return_inverse=True)
    return v - (np.bincount(inv, v) / np.bincount(inv))[inv]


def selfcheck_trial(seed: int, n_targets: int = 91, cycles: int = 5,
                    contribution_um: tuple[float, float] | None = None) -> Trial:
    """One self-check session: 1-2 legs of a realistic plant (lead, long-wave, wobble, noise,
    pass offsets, a material temperature that changes, sometimes varying load) with none, one or
    two effects present in the plant but withheld from the twin, at a random magnitude (RMS
    contribution log-uniform in SELF_CHECK_CONTRIBUTION_UM). Odd seeds use the simulated plant
    as twin, even seeds the twin fitted on the session."""
    from procedures.diagnosis.selfcheck import Trial
    from station.services.twins import plant_twin
    from drivers.plant.leg import default_leg_configs
    from station.services.synth import synth_session

    rng = np.random.default_rng(10_000 + seed)
    fitted = seed % 2 == 0
    eligible = FITTED_TWIN_EFFECTS if fitted else SIM_TWIN_EFFECTS
    n_legs = int(rng.integers(1, 3))
    legs = sorted(int(v) for v in rng.choice(np.arange(1, 7), n_legs, replace=False))
    u = rng.random()
    n_eff = 0 if u < 0.2 else (1 if u < 0.6 else 2)
    chosen = [str(e) for e in rng.choice(eligible, n_eff, replace=False)]
    where = {e: int(rng.choice(legs)) for e in chosen}
    # irregular targets (ISO 230-2): a regular grid with jitter
    step = 180.0 / (n_targets - 1)
    targets = np.linspace(-90, 90, n_targets) + rng.uniform(-0.3, 0.3, n_targets) * step
    targets[0], targets[-1] = -90.0, 90.0
    dwell_s = 4.0
    pass_s = n_targets * (dwell_s + step / 10.0)
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
    from station.services.synth import synth_session

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
    from drivers.plant.leg import systematic_error_um

    x, t_h = dry["target_mm"], dry["time_s"] / 3600.0
    temp, load_n = dry["material_temp_c"], dry["load_n"]
    if eff == "backlash":
        return replace(cfg, reversal_um=2 * m), {"reversal_um": 2 * m}
    if eff == "drift":
        d = m / float(np.std(_removed(t_h, x, fitted))) * float(rng.choice([-1, 1]))
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
        k = m / max(float(np.std(_removed(unit, x, fitted))), 1e-9)
        # scale the temperature excursion (not the steel) to reach the drawn magnitude
        cfg = replace(cfg, expansion_ppm_per_k=e_ppm, initial_temp_c=20 + k * (cfg.initial_temp_c - 20),
                      ambient_swing_k=k * cfg.ambient_swing_k, heating_k_per_m=k * cfg.heating_k_per_m)
        return cfg, {"expansion_ppm_per_k": e_ppm}
    if eff == "load":
        cfg = replace(cfg, bearing_compliance_um_per_kn=float(rng.uniform(1.0, 3.0)),
                      screw_compliance_um_per_kn_per_m=float(rng.uniform(10.0, 20.0)))
        unit = systematic_error_um(cfg.only("load"), x, 1, 20.0, load_n, 0)
        k = m / max(float(np.std(_removed(unit, x, fitted))), 1e-9)
        cfg = replace(cfg, load_per_pass_n=tuple(k * v for v in cfg.load_per_pass_n))
        return cfg, {"compliance_um_per_kn": cfg.compliance_um_per_kn}
    raise ValueError(f"unknown effect {eff!r}")


def _true_contribution(points, truth: dict[int, dict], real: dict, base: dict) -> np.ndarray:
    """The true contribution (um) of the withheld effects at every point."""
    from drivers.plant.leg import systematic_error_um

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
