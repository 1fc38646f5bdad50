"""The sections of the station config (station.services.config) that procedures use, read from a file
and named by file, section and key when wrong: [tolerances] (procedures.reporting.decision), [limits]
(procedures.acquisition.plan_size) and the legs' materials (procedures.metrology.thermal)."""

from __future__ import annotations

import pytest

from procedures.acquisition.plan_size import PlanLimits, check_plan_size
from procedures.acquisition.plan_spec import PlanSpec
from procedures.metrology.thermal import Material, recorded_materials
from procedures.reporting import decision as dec
from procedures.vocabulary import InputError, PlanError
from station.services.config import load_config


def _cfg(tmp_path, text):
    p = tmp_path / "station.toml"
    p.write_text(text)
    return p


def test_tolerances_from_the_config(tmp_path):
    p = _cfg(tmp_path, "[tolerances.HX300]\nE_um = 6.0\nB_um = 2\n[tolerances.HX300.as_left]\nE_um = 3.0\n"
                       "[tolerances.HX300.as_found]\nR_um = 4.0\n")
    cfg = load_config(p)
    t = cfg.tolerances["HX300"]
    assert t.limits("as_found") == {"E": 6.0, "B": 2.0, "R": 4.0}
    assert t.limits("as_left") == {"E": 3.0, "B": 2.0}
    assert t.source == f"{p} [tolerances.HX300]"
    # recorded in sessions and read back
    back = dec.tolerances_from_json(cfg.to_dict()["tolerances"])
    assert back["HX300"].limits("as_left") == {"E": 3.0, "B": 2.0}


@pytest.mark.parametrize("text, says", [
    ("[tolerances.HX300]\nE = 6.0\n", "[tolerances.HX300] E: unknown key"),
    ("[tolerances.HX300]\nE_um = -1\n", "[tolerances.HX300] E_um = -1: must be a finite number > 0"),
    ("[tolerances.HX300]\nE_um = \"6\"\n", "[tolerances.HX300] E_um: expected a number"),
    ("[tolerances.HX300.as_left]\nQ_um = 1\n", "[tolerances.HX300.as_left] Q_um: unknown key"),
    ("[tolerances.HX300]\n", "[tolerances.HX300]: states no limit"),
    ("tolerances = 3\n", "[tolerances] must hold one section per leg type"),
])
def test_bad_tolerances_named_by_file_section_key(tmp_path, text, says):
    p = _cfg(tmp_path, text)
    with pytest.raises(InputError) as exc:
        load_config(p)
    assert str(p) in str(exc.value) and says in str(exc.value)


def test_the_limits_are_the_configs(tmp_path):
    toml = tmp_path / "station.toml"
    toml.write_text('[limits]\nmax_points = 100\nmax_rig_hours = 0.5\n')
    cfg = load_config(toml)
    assert cfg.limits == PlanLimits(max_points=100, max_rig_hours=0.5)
    with pytest.raises(PlanError, match="max_points = 100"):
        check_plan_size(PlanSpec(), cfg.limits)
    toml.write_text('[limits]\nmax_points = -3\n')
    with pytest.raises(ValueError, match=r"\[limits\] max_points"):
        load_config(toml)


def test_materials_recorded_by_the_station_config(tmp_path):
    p = tmp_path / "station.toml"
    p.write_text('[drive]\nurl = "tcp://127.0.0.1:5020"\n[interferometer]\nport = "/dev/null"\n'
                 '[metrology]\nreference_temp_c = 20.0\n[legs]\nfixed_point_mm = -140\n[legs.2]\nexpansion_um_m_k = 23.0\n')
    rec = recorded_materials(load_config(p).to_dict())
    assert rec is not None
    ref, mats = rec
    assert ref == 20.0 and mats[1] == Material(11.5, 1.0, -140.0) and mats[2] == Material(23.0, 1.0, -140.0)
    # the simulated rig without [legs]: every leg's material is the simulated plant's own
    sim = load_config(None)
    mats_sim = recorded_materials(sim.to_dict())[1]
    plant = sim.sim.leg_configs()
    assert [mats_sim[k].fixed_point_mm for k in range(1, 7)] == [c.bearing_mm for c in plant]
