"""The plant's error sources behave physically and can be switched off."""

import numpy as np
import pytest

from drivers.clock import VirtualClock
from drivers.plant.leg import PlantConfig, LegPlant, systematic_error_um, default_leg_configs
from procedures.synthetic import synth_session


def test_all_sources_off_gives_a_perfect_leg():
    plant = LegPlant(PlantConfig(enabled=frozenset()), seed=1)
    plant.move(37.5, 10.0)
    assert plant.measured_position_mm(10.0) == pytest.approx(37.5, abs=1e-12)


def test_backlash_sign_convention_reversal_is_negative_minus_positive():
    cfg = PlantConfig().only("backlash")
    e_up = systematic_error_um(cfg, 0.0, +1, 20.0, 0.0, 0.0)
    e_down = systematic_error_um(cfg, 0.0, -1, 20.0, 0.0, 0.0)
    assert e_down - e_up == pytest.approx(cfg.reversal_um)


def test_lead_slope_is_um_per_metre():
    cfg = PlantConfig().only("lead")
    e = systematic_error_um(cfg, np.array([-90.0, 90.0]), 1, 20.0, 0.0, 0.0)
    assert e[1] - e[0] == pytest.approx(cfg.lead_slope_um_per_m * 0.180)


def test_thermal_expansion_grows_from_the_fixed_bearing():
    cfg = PlantConfig(bearing_mm=-150.0).only("thermal")
    e = systematic_error_um(cfg, np.array([-150.0, 50.0]), 1, cfg.temp_ref_c + 2.0, 0.0, 0.0)
    assert e[0] == pytest.approx(0.0)
    assert e[1] == pytest.approx(cfg.expansion_ppm_per_k * 0.2 * 2.0)


def test_load_compression_shortens_and_compliance_matches_definition():
    cfg = PlantConfig().only("load")
    e0 = systematic_error_um(cfg, 0.0, 1, 20.0, 0.0, 0.0)
    e1 = systematic_error_um(cfg, 0.0, 1, 20.0, 1000.0, 0.0)
    assert e1 - e0 == pytest.approx(-cfg.compliance_um_per_kn)


def test_motion_heats_the_screw_and_it_cools_back_with_tau():
    cfg = PlantConfig(heating_k_per_m=1.0, tau_s=100.0)
    plant = LegPlant(cfg)
    for i in range(10):
        plant.move(90.0 if i % 2 == 0 else -90.0, float(i))  # ~1.7 m of travel, quickly
    t_hot = plant.material_temp_c(10.0)
    assert t_hot > cfg.ambient_temp_c + 1.0
    t_later = plant.material_temp_c(10.0 + 100.0)
    assert (t_later - cfg.ambient_temp_c) == pytest.approx((t_hot - cfg.ambient_temp_c) * np.exp(-1), rel=1e-6)


def test_new_pass_offset_and_load_schedule_at_reversal():
    cfg = PlantConfig(load_per_pass_n=(0.0, 500.0), run_offset_um=1.0)
    plant = LegPlant(cfg, seed=3)
    plant.move(10.0, 1.0)
    assert plant.pass_index == 0 and plant.load_n == 0.0
    plant.move(5.0, 2.0)
    assert plant.pass_index == 1 and plant.load_n == 500.0 and plant.direction == -1


def test_noise_is_seeded_and_averaging_reduces_it():
    cfg = PlantConfig().only("noise")
    a = LegPlant(cfg, seed=5)
    b = LegPlant(cfg, seed=5)
    ra = [a.measured_position_mm(0.0) for _ in range(200)]
    rb = [b.measured_position_mm(0.0) for _ in range(200)]
    assert ra == rb
    std_1 = np.std(ra) * 1000
    std_avg = np.std([a.measured_position_mm(0.0, averaging_s=1.0) for _ in range(400)]) * 1000
    assert std_1 == pytest.approx(cfg.noise_um, rel=0.25)
    assert std_avg == pytest.approx(cfg.noise_um / np.sqrt(10), rel=0.25)


def test_unknown_source_refused():
    with pytest.raises(ValueError, match="unknown error sources"):
        PlantConfig(enabled=frozenset({"magic"}))


def test_virtual_clock_scale_zero_advances_only_by_sleep():
    clock = VirtualClock(0.0)
    assert clock.now() == 0.0
    clock.sleep(3600.0)
    assert clock.now() == 3600.0
    with pytest.raises(ValueError):
        VirtualClock(-1)


def test_synth_session_structure_and_reversal():
    cfgs = {1: PlantConfig().only("backlash", "noise")}
    pts = synth_session(cfgs, np.linspace(-90, 90, 13), cycles=3, seed=0)
    assert len(pts) == 13 * 6
    assert set(pts["run"]) == {1, 2, 3, 4, 5, 6}
    assert set(pts["direction"][pts["run"] % 2 == 1]) == {1}
    rev = pts["error_um"][pts["direction"] == -1].mean() - pts["error_um"][pts["direction"] == 1].mean()
    assert rev == pytest.approx(cfgs[1].reversal_um, abs=0.05)


def test_default_legs_look_alike_but_differ():
    cfgs = default_leg_configs(0)
    assert len(cfgs) == 6
    slopes = [c.lead_slope_um_per_m for c in cfgs]
    assert len(set(slopes)) == 6 and 0.75 * 9 < min(slopes) and max(slopes) < 1.25 * 9
