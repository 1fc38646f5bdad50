"""Normalisation to 20 degC (procedures.metrology.thermal): sign and size against the plant's own
thermal expansion, the reference point, missing temperatures, the materials a session records."""

import numpy as np
import pytest

from drivers.plant.leg import PlantConfig
from procedures.metrology.thermal import Material, nde_correction_um, normalise_points, normalise_session
from procedures.synthetic import synth_session

TARGETS = np.linspace(-90.0, 90.0, 31)


def _warm_leg(initial_c: float, ambient_c: float, bearing_mm: float = -150.0) -> tuple[PlantConfig, np.ndarray]:
    cfg = PlantConfig(initial_temp_c=initial_c, ambient_temp_c=ambient_c, tau_s=300.0, heating_k_per_m=0.0,
                      bearing_mm=bearing_mm).only("lead", "thermal")
    return cfg, synth_session({1: cfg}, TARGETS, cycles=2)


def test_a_warm_leg_reads_longer_and_the_normalisation_removes_exactly_the_plants_expansion():
    cfg, pts = _warm_leg(20.0, 23.0)  # warms from 20 towards 23 degC during the sweep
    temp = pts["material_temp_c"]
    assert temp.max() - temp.min() > 1.5
    at_20 = cfg.lead_slope_um_per_m * pts["target_mm"] / 1000.0  # the leg's error at 20 degC
    # the sign: warm, the leg is longer, so the raw error is larger than at 20 degC above the bearing
    assert np.all(pts["error_um"] - at_20 > 0)
    n = normalise_points(pts, {1: Material(cfg.expansion_ppm_per_k, 1.0, cfg.bearing_mm)})
    assert n.normalised == (1,)
    assert np.max(np.abs(n.points["error_um"] - at_20)) < 1e-9
    assert pts["error_um"] is not n.points["error_um"] and np.any(pts["error_um"] != n.points["error_um"])  # raw kept
    lo, hi = n.temp_range_c[1]
    assert lo == pytest.approx(temp.min()) and hi == pytest.approx(temp.max())


def test_correction_figure_and_reference_point():
    steel = Material(11.5, 1.0, 0.0)
    # 1 K over 90 mm: 11.5 um/m/K * 1 K * 0.09 m = 1.035 um; nothing at the fixed point
    assert nde_correction_um(90.0, 21.0, steel) == pytest.approx(1.035)
    assert nde_correction_um(-90.0, 21.0, steel) == pytest.approx(-1.035)
    assert nde_correction_um(0.0, 25.0, steel) == 0.0
    assert nde_correction_um(-150.0, 25.0, Material(11.5, 1.0, -150.0)) == 0.0
    assert nde_correction_um(90.0, 20.0, steel) == 0.0  # at the reference temperature
    assert nde_correction_um(90.0, 19.0, steel, reference_temp_c=19.0) == 0.0


def test_a_wrong_fixed_point_leaves_only_a_position_independent_part():
    cfg, pts = _warm_leg(21.0, 21.0)  # a steady 1 K above reference
    n = normalise_points(pts, {1: Material(cfg.expansion_ppm_per_k, 1.0, 0.0)})  # fixed point wrong by 150 mm
    left = n.points["error_um"] - cfg.lead_slope_um_per_m * pts["target_mm"] / 1000.0
    assert np.ptp(left) < 1e-9 and left[0] == pytest.approx(11.5 * 1.0 * 0.150)


def test_missing_material_temperature():
    _, pts = _warm_leg(20.0, 22.0)
    none = pts.copy()
    none["material_temp_c"] = np.nan
    n = normalise_points(none, {1: Material()})
    assert n.normalised == () and "no material temperature" in n.raw[1]
    assert np.array_equal(n.points["error_um"], none["error_um"]) and "raw" in n.lines()[0]
    gaps = pts.copy()
    gaps["material_temp_c"][5:9] = np.nan
    n = normalise_points(gaps, {1: Material()})
    full = normalise_points(pts, {1: Material()})
    assert n.filled == {1: 4} and "4 point(s) without a reading interpolated" in "\n".join(n.lines())
    assert np.max(np.abs(n.points["error_um"] - full.points["error_um"])) < 0.01


def test_a_session_that_recorded_no_materials_is_normalised_with_the_defaults():
    """(The materials a station config records: tests/station/services/test_config_for_procedures.py.)"""
    # a session that recorded none: the defaults, and the output says so
    _, pts = _warm_leg(21.0, 21.0)
    n = normalise_session(pts, {})
    assert n.normalised == (1,) and "defaults" in n.lines()[0]


def test_temperature_between_sensor_readings_is_interpolated_in_time():
    """The sweep records the last sensor reading (taken at most every 10 s) with every point: the
    normalisation interpolates between the readings, so a leg warming steadily is normalised
    with its temperature at each point's time, not the last reading's."""
    _, pts = _warm_leg(20.0, 23.0)
    true_temp = pts["material_temp_c"].copy()
    held = pts.copy()
    for start in range(0, len(held), 4):  # a reading every 4th point, held for the next three
        held["material_temp_c"][start:start + 4] = true_temp[start]
    mat = {1: Material(11.5, 1.0, -150.0)}
    exact = normalise_points(pts, mat).points["error_um"]
    got = normalise_points(held, mat).points["error_um"]
    stale = held["error_um"] - nde_correction_um(held["target_mm"], held["material_temp_c"], mat[1])
    last = ((len(held) - 1) // 4) * 4  # the last reading: after it the temperature is held
    assert np.max(np.abs(got[:last] - exact[:last])) < 0.2 * np.max(np.abs(stale[:last] - exact[:last]))
