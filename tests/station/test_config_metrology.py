"""[metrology] and [legs] in the station config: defaults, per-leg overrides, refusals naming
file and key, and the session recording them."""

import json

import pytest

from procedures.vocabulary import InputError
from station.services.config import LegMaterial, MetrologyConfig, load_config


def _write(tmp_path, text):
    p = tmp_path / "station.toml"
    p.write_text(text)
    return p


def test_defaults_without_file():
    cfg = load_config(None)
    assert cfg.metrology == MetrologyConfig()
    assert cfg.metrology.reference_temp_c == 20.0 and cfg.metrology.wavelength_nm == 632.991
    assert cfg.metrology.co2_ppm == 450.0 and cfg.metrology.dead_path_mm == 0.0
    assert cfg.legs == LegMaterial(11.5, 1.0, 0.0)
    # the built-in config is the simulated rig: without [legs], each leg is the simulated plant's
    plants = cfg.sim.leg_configs()
    for leg in range(1, 7):
        assert cfg.material_of(leg) == LegMaterial(plants[leg - 1].expansion_ppm_per_k, 1.0, plants[leg - 1].bearing_mm)
        assert -175.0 < cfg.material_of(leg).fixed_point_mm < -125.0


def test_real_rig_defaults_to_steel_fixed_at_mid_stroke(tmp_path):
    cfg = load_config(_write(tmp_path, '[drive]\nurl = "tcp://127.0.0.1:502"\n[interferometer]\nport = "/dev/ttyUSB1"\n'))
    assert all(cfg.material_of(leg) == LegMaterial(11.5, 1.0, 0.0) for leg in range(1, 7))


def test_values_and_per_leg_override(tmp_path):
    p = _write(tmp_path, """
[metrology]
wavelength_nm = 632.8
co2_ppm = 500
dead_path_mm = 120
model = "Renishaw XL-80"
serial = "A1234"
calibration_date = 2026-03-14
humidity_u_pct = 2.5
[legs]
expansion_um_m_k = 11.0
fixed_point_mm = -150
[legs.3]
expansion_um_m_k = 23.0
expansion_u_um_m_k = 0.5
""")
    cfg = load_config(p)
    m = cfg.metrology
    assert (m.wavelength_nm, m.co2_ppm, m.dead_path_mm, m.humidity_u_pct) == (632.8, 500.0, 120.0, 2.5)
    assert (m.model, m.serial, m.calibration_date) == ("Renishaw XL-80", "A1234", "2026-03-14")
    assert cfg.material_of(1) == LegMaterial(11.0, 1.0, -150.0)
    # an override inherits what it does not set from [legs]
    assert cfg.material_of(3) == LegMaterial(23.0, 0.5, -150.0)
    rec = json.loads(json.dumps(cfg.to_dict()))
    assert rec["metrology"]["wavelength_nm"] == 632.8 and rec["leg_overrides"]["3"]["expansion_um_m_k"] == 23.0
    assert rec["leg_materials"]["3"]["expansion_u_um_m_k"] == 0.5  # every leg's effective material


@pytest.mark.parametrize("text, key", [
    ("[legs]\nexpansion_um_m_k = -1.0", "[legs] expansion_um_m_k"),
    ("[legs]\nexpansion_um_m_k = 60.0", "[legs] expansion_um_m_k"),
    ("[legs.2]\nexpansion_um_m_k = 51", "[legs.2] expansion_um_m_k"),
    ("[legs]\nexpansion_u_um_m_k = -0.1", "[legs] expansion_u_um_m_k"),
    ("[legs.7]\nexpansion_um_m_k = 11", "[legs.7]"),
    ("[legs]\ncte = 11", "[legs] cte"),
    ("[metrology]\nwavelength_nm = 399.0", "[metrology] wavelength_nm"),
    ("[metrology]\nwavelength_nm = 1701", "[metrology] wavelength_nm"),
    ("[metrology]\nwavelength_nm = 0.633", "[metrology] wavelength_nm"),
    ("[metrology]\nhumidity_u_pct = 101", "[metrology] humidity_u_pct"),
    ("[metrology]\nhumidity_u_pct = -1", "[metrology] humidity_u_pct"),
    ("[metrology]\nco2_ppm = -5", "[metrology] co2_ppm"),
    ("[metrology]\nair_temp_u_c = nan", "[metrology] air_temp_u_c"),
    ("[metrology]\ncalibration_date = \"14/03/2026\"", "[metrology] calibration_date"),
    ("[metrology]\ncalibration_date = \"2026-02-30\"", "[metrology] calibration_date"),
    ("[metrology]\nlaser_accuracy_ppm = \"0.5\"", "[metrology] laser_accuracy_ppm"),
    ("[metrology]\nwavelenght_nm = 633", "[metrology] wavelenght_nm"),
])
def test_bad_values_refused_naming_file_and_key(tmp_path, text, key):
    p = _write(tmp_path, text)
    with pytest.raises(InputError) as exc:
        load_config(p)
    msg = str(exc.value)
    assert str(p) in msg and key in msg, msg
