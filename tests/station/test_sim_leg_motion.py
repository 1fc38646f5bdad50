"""The station's simulated rig moves like a leg (a real leg's jerk limit, `[sim] jerk_mm_s3`),
recorded in the session; the sample recordings pin the setting they were made with (0); the
adaptive stopping rule of an on-the-fly sweep normalises with the legs' materials of the
station config (station/services/jobs.py), not the default. Sweeps over the real Modbus TCP server on
127.0.0.1 and the interferometer on a pty."""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np
import pytest

import procedures.acquisition.adaptive as adaptive
from drivers.plant.leg import LEG_JERK_MM_S3
from procedures.vocabulary import InputError
from procedures.acquisition.plans import iso230_plan, onthefly_plan
from procedures.io.recording.reader import read_session
from station.services import samples as recordings
from station.services.config import LegMaterial, SimConfig, StationConfig, load_config
from station.services.jobs import run_sweep
from station.services.wiring import open_rig

logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def test_sim_config_defaults_to_a_real_legs_jerk_and_applies_it_to_every_leg():
    assert SimConfig().jerk_mm_s3 == LEG_JERK_MM_S3 > 0
    assert all(c.jerk_mm_s3 == LEG_JERK_MM_S3 for c in SimConfig().leg_configs())
    assert all(c.jerk_mm_s3 == 0.0 for c in SimConfig(jerk_mm_s3=0.0).leg_configs())
    # only the jerk differs: the legs themselves are the same plants
    a, b = SimConfig(seed=3).leg_configs(), SimConfig(seed=3, jerk_mm_s3=0.0).leg_configs()
    assert [replace(x, jerk_mm_s3=0.0) for x in a] == b


def test_sim_jerk_key_is_read_and_validated_naming_file_and_key(tmp_path):
    p = tmp_path / "station.toml"
    p.write_text('[drive]\nurl = "sim"\n[interferometer]\nport = "sim"\n[sim]\njerk_mm_s3 = 500\n')
    assert load_config(p).sim.jerk_mm_s3 == 500.0
    p.write_text('[sim]\njerk_mm_s3 = 0\n')
    assert load_config(p).sim.jerk_mm_s3 == 0.0
    for bad in ("-1", "nan", '"fast"'):
        p.write_text(f"[sim]\njerk_mm_s3 = {bad}\n")
        with pytest.raises(InputError) as exc:
            load_config(p)
        msg = str(exc.value)
        assert str(p) in msg and "[sim] jerk_mm_s3" in msg


def _iso_rig_time(cfg: StationConfig, out) -> tuple[float, dict]:
    """Rig time (s) of a small ISO 230-2 sweep of leg 1 on the station's simulated rig, and the
    session's recorded station config."""
    plan = iso230_plan((1,), n_targets=6, cycles=1, irregular=False)
    with open_rig(cfg, legs=(1,), time_scale=0.0) as rig:
        assert rig.sim.plants[1].cfg.jerk_mm_s3 == cfg.sim.jerk_mm_s3
        t0 = rig.clock.now()
        res = run_sweep(rig, plan, out, cfg)
        rig_s = rig.clock.now() - t0
    assert res.outcome == "completed"
    return rig_s, read_session(out).station_config


def test_the_station_sim_rig_is_jerk_limited_and_the_session_records_it(tmp_path):
    limited_s, recorded = _iso_rig_time(StationConfig(operator="test"), tmp_path / "limited.h5")
    free_s, recorded_free = _iso_rig_time(StationConfig(operator="test", sim=SimConfig(jerk_mm_s3=0.0)),
                                          tmp_path / "free.h5")
    assert recorded["sim"]["jerk_mm_s3"] == LEG_JERK_MM_S3
    assert recorded_free["sim"]["jerk_mm_s3"] == 0.0
    # every move takes longer under a jerk limit (about accel/jerk seconds per move)
    assert limited_s > free_s


def test_the_sample_recordings_pin_no_jerk_limit():
    from procedures.synthetic import SAMPLE_JERK_MM_S3, sample_plant_configs

    assert SAMPLE_JERK_MM_S3 == 0.0 and recordings.sample_config().sim.jerk_mm_s3 == 0.0
    assert all(c.jerk_mm_s3 == 0.0 for c in sample_plant_configs())
    with recordings.open_sample_rig() as rig:
        assert all(p.cfg.jerk_mm_s3 == 0.0 for p in rig.sim.plants.values())


def test_leg_figures_depend_on_the_material_given():
    """A leg whose material temperature changes between passes, fixed far from 0 mm: normalised
    with its own fixed point, the noise floor is smaller than with the default one (fixed at 0 mm),
    whose wrong normalisation adds a per-pass offset."""
    from drivers.plant.leg import PlantConfig
    from procedures.synthetic import synth_session

    plant = PlantConfig(bearing_mm=-400.0, ambient_ramp_k_per_h=4.0, tau_s=60.0)
    points = synth_session({1: plant}, np.linspace(-90, 90, 37), cycles=4, seed=2, dwell_s=5.0)
    own = adaptive.leg_figures(points, 1, LegMaterial(expansion_um_m_k=plant.expansion_ppm_per_k, fixed_point_mm=-400.0))
    default = adaptive.leg_figures(points, 1)
    assert own.noise_floor_um is not None and default.noise_floor_um is not None
    assert own.noise_floor_um < default.noise_floor_um


def test_run_sweep_gives_the_adaptive_rule_the_configs_material(tmp_path, monkeypatch):
    """The job composing the sweep gives the rule StationConfig.material_of(leg) (here a leg
    fixed far from 0 mm), the material the session records as station_config.leg_materials."""
    seen = []
    original = adaptive.leg_figures

    def spy(points, leg, material=None):
        seen.append((leg, material))
        return original(points, leg, material)

    monkeypatch.setattr(adaptive, "leg_figures", spy)
    far = LegMaterial(expansion_um_m_k=12.0, fixed_point_mm=-450.0)
    cfg = StationConfig(operator="test", leg_overrides={1: far})
    plan = onthefly_plan((1,), cycles=4, step_mm=2.0, adaptive=True)
    out = tmp_path / "adaptive.h5"
    with open_rig(cfg, legs=(1,), time_scale=0.0) as rig:
        res = run_sweep(rig, plan, out, cfg)
    assert res.outcome == "completed"
    assert seen and all(leg == 1 and material == far for leg, material in seen)
    recorded = read_session(out).station_config["leg_materials"]["1"]
    assert recorded["fixed_point_mm"] == -450.0 and recorded["expansion_um_m_k"] == 12.0
