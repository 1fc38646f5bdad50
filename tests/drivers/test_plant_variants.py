"""The plant's variant physics (issue 25): off by default, each as its docstring says."""

import numpy as np
import pytest

from drivers.plant.leg import LegPlant, PlantConfig, systematic_error_um


def test_the_variants_are_off_by_default_and_change_nothing():
    cfg = PlantConfig()
    assert cfg.reversal_um_per_k == cfg.reversal_wear_um == cfg.windup_mm == cfg.expansion_gradient_ppm_per_k_per_m == 0
    x = np.linspace(-90, 90, 7)
    a = systematic_error_um(cfg, x, -1, 23.0, 300.0, 100.0)
    b = systematic_error_um(cfg, x, -1, 23.0, 300.0, 100.0, since_reversal_mm=0.5)
    assert np.array_equal(a, b)


def test_the_reversal_grows_with_temperature_in_um_per_k():
    cfg = PlantConfig(reversal_um=1.0, reversal_um_per_k=0.2).only("backlash")
    rev = [float(systematic_error_um(cfg, 0.0, -1, t, 0, 0) - systematic_error_um(cfg, 0.0, 1, t, 0, 0)) for t in (20.0, 23.0)]
    assert rev == pytest.approx([1.0, 1.6])


def test_nut_wear_makes_the_reversal_larger_over_the_worn_part():
    cfg = PlantConfig(reversal_um=1.0, reversal_wear_um=0.5, reversal_wear_centre_mm=30.0,
                      reversal_wear_half_width_mm=40.0).only("backlash")
    x = np.array([30.0, 50.0, -30.0])
    rev = systematic_error_um(cfg, x, -1, 20, 0, 0) - systematic_error_um(cfg, x, 1, 20, 0, 0)
    assert rev == pytest.approx([1.5, 1.0 + 0.5 * 0.75, 1.0])


def test_lost_motion_winds_up_over_its_length_after_a_reversal():
    cfg = PlantConfig(reversal_um=2.0, windup_mm=3.0).only("backlash")
    plant = LegPlant(cfg)
    plant.move(50.0, 1.0)  # up, no reversal yet: wound up
    assert plant.error_um(1.0) == pytest.approx(-1.0)
    plant.move(47.0, 2.0)  # down: a reversal at 50, 3 mm of travel since
    assert plant.since_reversal_mm == pytest.approx(3.0)
    assert plant.error_um(2.0) == pytest.approx(1.0 - 2.0 * np.exp(-1.0))
    plant.move(10.0, 3.0)
    assert plant.error_um(3.0) == pytest.approx(1.0, abs=1e-4)


def test_a_thermal_gradient_adds_an_error_growing_with_the_square_of_position():
    cfg = PlantConfig(bearing_mm=-100.0, expansion_ppm_per_k=0.0, expansion_gradient_ppm_per_k_per_m=50.0).only("thermal")
    e = systematic_error_um(cfg, np.array([-100.0, 0.0, 100.0]), 1, cfg.temp_ref_c + 2.0, 0, 0)
    assert e == pytest.approx([0.0, 50.0 * 0.01 / 2 * 2.0, 50.0 * 0.04 / 2 * 2.0])
