"""Self-check sessions for issue 35's situations, made with the project's plant and withheld from
the twin (`station diagnose --self-check --variants PHYSICS`; station/services/selfcheck_variants.py
dispatches here):

- `warm_reversal`: a leg warming 2-4 K nearly linearly in time (drift and thermal look alike)
  with its reversal growing with the temperature: thermal and backlash / temperature, no drift;
- `stacked`: the same warming leg whose nut is also worn over a stretch: thermal and backlash /
  temperature+position;
- `reference_wobble`: a session diagnosed against a reference recording of the same leg (noisier,
  drifting) that shares its 5 mm lead wobble: nothing may be named;
- `fleet_duplicates`: a clean leg against a fleet of clean siblings, one of them filed three times
  under different serials: the copies must be counted once and no feature of the leg may stand
  out from its siblings (the leg's own reversal and wobble differ from the fleet's mean, so effects
  against the fleet may be named: the fleet comparison is what is checked).

One leg; the twin is fitted on the session (even seeds) or the plant without the withheld effects
(odd seeds) where it applies (warm_reversal, stacked).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from procedures.diagnosis.selfcheck import Trial

SITUATIONS = ("warm_reversal", "stacked", "reference_wobble", "fleet_duplicates")
BASE_SOURCES = ("lead", "longwave", "wobble", "noise", "run_offset")


def _targets(rng, n_targets: int) -> np.ndarray:
    step = 180.0 / (n_targets - 1)
    t = np.linspace(-90, 90, n_targets) + rng.uniform(-0.3, 0.3, n_targets) * step
    t[0], t[-1] = -90.0, 90.0
    return t


def situation_trial(seed: int, physics: str, n_targets: int = 91, cycles: int = 5) -> Trial:
    from procedures.diagnosis.selfcheck import Trial  # scipy: not for `station diagnose --help`

    """One session of `physics` (SITUATIONS); deterministic for the seed."""
    from drivers.plant.leg import default_leg_configs, systematic_error_um
    from station.services.synth import synth_session
    from station.services.twins import plant_twin

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
