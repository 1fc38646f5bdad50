"""The default bidirectional model: held-out residual at the noise floor with backlash, reversal
recovered, irregular spacing, small models on noise, the screw lead found in the data."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.plant.leg import PlantConfig, default_leg_configs
from procedures.synthetic import synth_session
from procedures.vocabulary import InputError
from procedures.fit import fit, model_to_json
from procedures.fit.crossval import cycle_folds
from procedures.fit.data import split_legs
from procedures.fit.noise import estimate_noise_floor
from procedures.acquisition.plans import irregular_targets

TARGETS = np.linspace(-90, 90, 121)  # 1.5 mm: the 5 mm lead is resolved, the fit stays quick


@pytest.fixture(scope="module")
def default_plant_points():
    """The simulated default plant (backlash, lead, long-wave, wobble, thermal, drift, noise,
    run offsets): one leg, six cycles like the paper's six sets."""
    cfg = default_leg_configs(seed=4)[0]
    assert "backlash" in cfg.enabled and cfg.reversal_um > 0.5
    return cfg, synth_session({1: cfg}, TARGETS, cycles=6, seed=4)


@pytest.fixture(scope="module")
def default_plant_fit(default_plant_points):
    return fit(default_plant_points[1])


def test_heldout_residual_within_10_percent_of_noise_floor_with_backlash(default_plant_fit):
    s = default_plant_fit.legs[1].stats
    assert s.folds == 6 and s.n_cycles == 6 and s.n_points == 121 * 12
    assert s.heldout_rms_um <= 1.1 * s.noise_floor_um
    # and it is at what a perfect static model would score in this cross-validation
    assert s.heldout_ratio <= 1.02 * s.ideal_heldout_ratio
    assert s.heldout_range_reduction_pct > 70


def test_paper_method_does_much_worse_on_the_same_data(default_plant_points, default_plant_fit):
    paper = fit(default_plant_points[1], "paper")
    assert paper.legs[1].stats.heldout_rms_um > 2 * default_plant_fit.legs[1].stats.heldout_rms_um


def test_noise_floor_is_the_pooled_scatter_of_repeat_passes(default_plant_points):
    data = split_legs(default_plant_points[1])[1]
    nf = estimate_noise_floor(data)
    # by hand for one cell: the 6 upward passes at the first target
    cell = data.error_um[(data.position_mm == TARGETS[0]) & (data.direction == 1)]
    assert cell.size == 6
    assert nf.cells == 2 * TARGETS.size and nf.dof == 2 * TARGETS.size * 5
    assert nf.noise_floor_um == pytest.approx(np.sqrt(np.mean([
        np.var(data.error_um[(data.position_mm == x) & (data.direction == d)], ddof=1)
        for x in TARGETS for d in (1, -1)])), rel=1e-12)
    # pass offsets (drift, warm-up, re-zeroing) are kept in the floor, removed in within_pass
    assert nf.within_pass_um < 0.5 * nf.noise_floor_um


@pytest.mark.parametrize("seed", [0, 1])
def test_recovers_the_reversal(seed):
    # white noise only: 0.03 um per point over 1210 points pins the reversal to ~0.002 um
    cfg = PlantConfig(reversal_um=1.7).only("backlash", "lead", "longwave", "noise")
    pts = synth_session({1: cfg}, TARGETS, cycles=5, seed=seed)
    leg = fit(pts, lead_mm=None).legs[1]
    assert leg.basis.reversal_degree >= 0
    assert leg.reversal_um == pytest.approx(1.7, abs=0.01)
    fwd, rev = leg.predict_um(0.0, 1), leg.predict_um(0.0, -1)
    assert float(rev - fwd) == pytest.approx(1.7, abs=0.01)  # downward approach reads longer


def test_irregular_spacing_is_fitted_at_the_real_positions():
    targets = irregular_targets(-90.0, 90.0, 41, seed=5)
    assert np.ptp(np.diff(targets)) > 1.0  # really irregular
    cfg = PlantConfig().only("backlash", "lead", "longwave", "noise", "run_offset")
    pts = synth_session({1: cfg}, targets, cycles=5, seed=5)
    leg = fit(pts, lead_mm=None).legs[1]
    # a new offset (0.04 um std) at every reversal: 5 + 5 passes give the reversal to
    # 0.04 * sqrt(2/5) = 0.025 um (1 sigma); allow 4 sigma
    assert leg.reversal_um == pytest.approx(cfg.reversal_um, abs=0.1)
    assert leg.stats.heldout_ratio < 1.25
    # the model follows the true screw error between the targets too
    from drivers.plant.leg import screw_error_um

    x = np.linspace(-85, 85, 200)
    truth = screw_error_um(cfg, x)
    pred = (leg.predict_um(x, 1) + leg.predict_um(x, -1)) / 2
    offset = np.mean(pred - truth)  # the zero of the interferometer is arbitrary
    assert np.sqrt(np.mean((pred - truth - offset) ** 2)) < 0.1


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_cv_picks_a_small_model_on_noise_and_trend(seed):
    cfg = PlantConfig().only("lead", "noise", "run_offset")
    pts = synth_session({1: cfg}, TARGETS, cycles=5, seed=seed)
    leg = fit(pts).legs[1]
    b = leg.basis
    assert b.trend_degree <= 2
    assert len(b.wavelengths_mm) <= 1 and b.lead_harmonics == 0
    assert b.n_params <= 5
    assert leg.selection["lead"] == "none found"
    assert abs(leg.reversal_um) < 0.05


def test_finds_the_screw_lead_in_the_data(default_plant_points, default_plant_fit):
    cfg = default_plant_points[0]
    leg = default_plant_fit.legs[1]
    assert leg.selection["lead"] == "detected in the data"
    assert leg.basis.lead_harmonics >= 1
    assert leg.basis.lead_mm == pytest.approx(cfg.lead_mm, rel=2e-3)
    without = fit(default_plant_points[1], lead_mm=None).legs[1]
    assert without.basis.lead_harmonics == 0
    assert without.stats.heldout_rms_um > 1.2 * leg.stats.heldout_rms_um  # the wobble stays in


def test_given_lead_is_used(default_plant_points):
    leg = fit(default_plant_points[1], lead_mm=5.0).legs[1]
    assert leg.basis.lead_mm == 5.0 and leg.basis.lead_harmonics >= 1
    assert leg.stats.heldout_ratio <= 1.1


def test_cycles_are_the_cross_validation_groups():
    cfg = PlantConfig().only("noise")
    data = split_legs(synth_session({1: cfg}, TARGETS[:10], cycles=3, seed=0))[1]
    assert data.n_cycles == 3
    folds = cycle_folds(data)
    for run in np.unique(data.run):
        assert np.unique(folds[data.run == run]).size == 1  # a pass is never split
    assert np.unique(folds[data.cycle == 2]).size == 1  # up and down pass of a cycle together


def test_one_cycle_cannot_choose_its_size_but_a_fixed_size_fits():
    cfg = PlantConfig().only("backlash", "lead", "noise")
    pts = synth_session({1: cfg}, TARGETS, cycles=1, seed=0)
    with pytest.raises(InputError, match="two cycles"):
        fit(pts)
    leg = fit(pts, lead_mm=None, trend_degree=1, reversal_degree=0, fourier_terms=0).legs[1]
    assert leg.stats.heldout_rms_um is None and "two cycles" in leg.stats.note
    assert leg.reversal_um == pytest.approx(cfg.reversal_um, abs=0.05)


def test_same_points_give_the_same_model(default_plant_points, default_plant_fit):
    again = fit(default_plant_points[1])
    assert model_to_json(again, "a.h5", "0" * 64, "T") == model_to_json(default_plant_fit, "a.h5", "0" * 64, "T")


def test_bad_points_are_refused_with_the_row():
    pts = synth_session({1: PlantConfig().only("noise")}, TARGETS[:5], cycles=2, seed=0)
    pts["direction"][7] = 0
    with pytest.raises(InputError, match="row 7: field direction"):
        fit(pts)
