"""Acceptance of issue 13 (uncertainty): the analytical budget (procedures.metrology.uncertainty,
GUM linear propagation, k = 2) agrees with a Monte Carlo propagation (GUM Supplement 1) within
10 % for U(E), U(B) and U(A) on a sample session.

The Monte Carlo here is written on its own, from the measurement chain, not from the budget's
linear forms: it draws every input from the distribution docs/uncertainty.md assigns to it,
rebuilds every reading of the session (laser scale, the refractive index recomputed with the
Ciddor equation from the disturbed air readings, cosine error, normalisation to 20 degC with a
disturbed material temperature and coefficient, Abbe angle per position, dead-path drift,
resolution, and a fresh repeatability draw of n approaches per target and direction), evaluates
ISO 230-2 on every trial (vectorised here; checked against procedures.reporting.iso230 on a trial), and
takes the probabilistically symmetric 95 % coverage interval: U_MC = (q97.5 - q2.5) / 2.

The sample session: leg 1 of the simulator's default leg (lead error, screw waves, reversal,
travel heating, noise), the ISO 230-2 plan (11 irregular targets, 5 cycles), seed 0, with the air
temperature drifting 0.4 K over the test and a misaligned, Abbe-offset, dead-path set-up so every
contribution is at work.
"""

from __future__ import annotations

import numpy as np
import pytest

from drivers.plant.leg import PlantConfig
from procedures.reporting import iso230
from procedures.acquisition import plans
from procedures.metrology import air
from procedures.metrology.uncertainty import UncertaintyInputs, leg_budget
from procedures.synthetic import synth_session

N_TRIALS = 20000
INPUTS = UncertaintyInputs(laser_accuracy_ppm=0.5, laser_resolution_nm=1.0, air_temp_u_c=0.2,
                           pressure_u_pa=80.0, humidity_u_pct=5.0, material_temp_u_c=0.1,
                           misalignment_mm=0.5, abbe_offset_mm=20.0, abbe_angle_u_urad=3.0,
                           dead_path_mm=200.0, expansion_um_m_k=11.5, expansion_u_um_m_k=1.0,
                           fixed_point_mm=-100.0)


def sample_session(seed: int = 0) -> np.ndarray:
    plan = plans.iso230_plan()
    pts = synth_session({1: PlantConfig()}, plan.targets_mm, cycles=5, seed=seed)
    # the room drifts during the test: 0.4 K, 60 Pa, 4 %RH from start to end
    f = (pts["time_s"] - pts["time_s"].min()) / np.ptp(pts["time_s"])
    pts["air_temp_c"] = 20.3 + 0.4 * f
    pts["air_pressure_hpa"] = 1012.0 + 0.6 * f
    pts["humidity_pct"] = 42.0 + 4.0 * f
    return pts


def _cells(pts: np.ndarray):
    """Readings arranged as (cell, approach): cells = up targets ascending, then down ascending."""
    cells = []
    for d in (1, -1):
        sel = pts[pts["direction"] == d]
        for t in np.unique(sel["target_mm"]):
            cells.append((d, t, sel[sel["target_mm"] == t]))
    n = min(len(c[2]) for c in cells)
    P = np.array([c[1] for c in cells])
    D = np.array([c[0] for c in cells])
    mean = np.array([c[2]["error_um"].mean() for c in cells])
    s = np.array([c[2]["error_um"].std(ddof=1) for c in cells])
    Tm = np.array([c[2]["material_temp_c"][:n] for c in cells])  # (cell, approach)
    return P, D, mean, s, Tm, n


def iso_vectorised(x: np.ndarray, D: np.ndarray) -> dict[str, np.ndarray]:
    """ISO 230-2 E, A, B over trials: x (trials, cell, approach) -> arrays (trials,)."""
    m = x.mean(axis=2)
    s = x.std(axis=2, ddof=1)
    up, down = D > 0, D < 0
    b = m[:, up] - m[:, down]
    return {"E": m.max(axis=1) - m.min(axis=1),
            "A": (m + 2 * s).max(axis=1) - (m - 2 * s).min(axis=1),
            "B": np.abs(b).max(axis=1)}


def monte_carlo(pts: np.ndarray, inp: UncertaintyInputs, trials: int, seed: int) -> dict[str, float]:
    rng = np.random.default_rng(seed)
    P, D, mean, s, Tm, n = _cells(pts)
    shape = (trials, len(P), n)
    t_air = float(np.mean(pts["air_temp_c"]))
    p_air = float(np.mean(pts["air_pressure_hpa"])) * 100.0
    h_air = float(np.mean(pts["humidity_pct"]))
    # repeatability: n fresh approaches per target and direction about the session's means
    x = mean[None, :, None] + s[None, :, None] * rng.standard_normal(shape)
    # laser: stated accuracy is an expanded uncertainty (k = 2), normal
    eps = rng.normal(0.0, inp.laser_accuracy_ppm / 2, trials)
    # air sensors: n recomputed with Ciddor from the disturbed readings; n too small -> reads long
    dT = rng.normal(0.0, inp.air_temp_u_c, trials)
    dp = rng.normal(0.0, inp.pressure_u_pa, trials)
    dh = rng.normal(0.0, inp.humidity_u_pct, trials)
    n0 = air.ciddor(inp.wavelength_nm, t_air, p_air, h_air, inp.co2_ppm)
    n1 = air.ciddor(inp.wavelength_nm, t_air + dT, p_air + dp, h_air + dh, inp.co2_ppm)
    eps = eps - 1e6 * (n1 - n0)
    # cosine: bound s^2 / (8 D^2) over the stroke, rectangular +/- bound
    stroke = float(np.ptp(P))
    bound = 1e6 * inp.misalignment_mm ** 2 / (8 * stroke ** 2)
    eps = eps + rng.uniform(-bound, bound, trials)
    x += 1e-3 * eps[:, None, None] * P[None, :, None]
    # normalisation to 20 degC with a disturbed sensor and coefficient, minus the nominal one
    dTm = rng.normal(0.0, inp.material_temp_u_c, trials)[:, None, None]
    alpha = inp.expansion_um_m_k + rng.normal(0.0, inp.expansion_u_um_m_k, trials)[:, None, None]
    ref = inp.reference_temp_c
    lever = (P - inp.fixed_point_mm)[None, :, None]
    x -= 1e-3 * (alpha * (Tm[None] + dTm - ref) - inp.expansion_um_m_k * (Tm[None] - ref)) * lever
    # Abbe: one angle per target position (the same in both directions and every approach)
    positions, pos_index = np.unique(P, return_inverse=True)
    theta = rng.normal(0.0, inp.abbe_angle_u_urad, (trials, len(positions)))
    x += 1e-3 * inp.abbe_offset_mm * theta[:, pos_index][:, :, None]
    # dead path: the air's drift over it, an offset per target and direction, rectangular over the range
    rng_ppm = 1e6 * float(np.ptp(air.ciddor(inp.wavelength_nm, pts["air_temp_c"], 100 * pts["air_pressure_hpa"],
                                            pts["humidity_pct"], inp.co2_ppm)))
    x += 1e-3 * inp.dead_path_mm * rng.uniform(-rng_ppm / 2, rng_ppm / 2, (trials, len(P)))[:, :, None]
    # resolution: each reading rounded
    res = 1e-3 * inp.laser_resolution_nm
    x += rng.uniform(-res / 2, res / 2, shape)
    values = iso_vectorised(x, D)
    # the vectorised evaluation is ISO 230-2's: checked on one trial against procedures.reporting.iso230
    one = pts[np.argsort(pts["index"])].copy()
    k = 0
    for c, (d, t) in enumerate(zip(D, P)):
        rows = np.flatnonzero((one["direction"] == d) & (one["target_mm"] == t))[:n]
        one["error_um"][rows] = x[0, c]
    ref_iso = iso230.evaluate(one)[1]
    for name in ("E", "A", "B"):
        assert values[name][k] == pytest.approx(ref_iso.values[name], abs=1e-9)
    return {name: float((np.quantile(v, 0.975) - np.quantile(v, 0.025)) / 2) for name, v in values.items()}


@pytest.mark.parametrize("seed, inputs", [(0, INPUTS), (3, UncertaintyInputs())], ids=["full-setup", "config-defaults"])
def test_budget_agrees_with_monte_carlo(seed, inputs):
    """Two sample sessions (plant seeds 0 and 3): every contribution at work, and the station's
    config defaults (no misalignment, Abbe or dead path)."""
    pts = sample_session(seed=seed)
    budget = leg_budget(iso230.evaluate(pts)[1], pts, inputs)
    mc = monte_carlo(pts, inputs, N_TRIALS, seed=20261124)
    print()
    for name in ("E", "A", "B"):
        an = budget.values[name].U_um
        print(f"U({name}) analytical {an:.4f} um, Monte Carlo {mc[name]:.4f} um ({N_TRIALS} trials), "
              f"ratio {an / mc[name]:.3f}")
    for name in ("E", "A", "B"):
        assert budget.values[name].U_um == pytest.approx(mc[name], rel=0.10), name
        assert mc[name] > 0.05  # a spread worth comparing (um), not a degenerate case
