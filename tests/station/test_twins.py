"""The diagnosis twins both front ends build (station.services.twins): `station diagnose --twin` and the
terminal UI's Diagnosis page use the same functions."""

import pytest

from procedures.diagnosis.twin import ExternalTwin
from procedures.vocabulary import InputError
from station.services import twins
from tests.tooling import defines, imported_names


def test_the_command_and_the_self_check_use_the_shared_twins():
    # by their imports (inside the functions: `station diagnose --help` loads no diagnosis), no copy of their own:
    # the command and the UI's page fill a request of the diagnosis job, which loads the twin
    assert imported_names("station.services.diagnosis_jobs")["load_twin"] == "station.services.twins.load_twin"
    assert "load_twin" not in imported_names("station.commands.diagnose")
    assert imported_names("procedures.synthetic")["plant_twin"] == "procedures.diagnosis.twin.plant_twin"
    assert imported_names("station.services.twins")["plant_twin"] == "procedures.diagnosis.twin.plant_twin"
    assert not defines("station.commands.diagnose", "load_twin") and not defines("station.services.diagnosis_jobs", "load_twin") and not defines("procedures.synthetic", "plant_twin")
    assert twins.load_twin.__module__ == "station.services.twins"
    assert twins.plant_twin.__module__ == "procedures.diagnosis.twin"


def test_the_simulated_plant_as_a_twin(tmp_path):
    twin = twins.load_twin("sim:default")
    assert isinstance(twin, ExternalTwin) and twin.kind == "sim" and twin.legs == frozenset(range(1, 7))
    assert twin.description == "simulated plant (default)"
    config = tmp_path / "plant.toml"
    config.write_text("[leg.2]\nbogus = 1\n")
    with pytest.raises(InputError, match=r"\[leg.2\] bogus: not a plant parameter"):
        twins.load_twin(f"sim:{config}")
    with pytest.raises(InputError, match="no such file"):
        twins.load_twin(str(tmp_path / "none.json"))


def test_a_reference_3_k_warmer_is_compared_normalised_to_20_c(tmp_path):
    """Two sessions of the same simulated leg (thermal expansion on, no heating), one at 20 C, the
    reference at 23 C: raw, the reference shows as a scale of about -3 K x 11.5 ppm/K; both
    normalised to 20 C (both carry the material temperature), no scale is left."""
    from dataclasses import replace

    import numpy as np

    from drivers.plant.leg import default_leg_configs
    from procedures.diagnosis import diagnose
    from procedures.diagnosis.reference_twin import twin_from_recording
    from procedures.io.recording.reader import read_session
    from station.services.diagnosis_jobs import diagnose_session
    from procedures.synthetic import synth_session
    from tests.tooling import write_points_session

    cfg = replace(default_leg_configs(3)[0], heating_k_per_m=0.0)
    targets = np.linspace(-90, 90, 61)
    at = {t: synth_session({1: replace(cfg, initial_temp_c=t, ambient_temp_c=t)}, targets, 4, seed=int(t), dwell_s=2.0)
          for t in (20.0, 23.0)}
    here = read_session(write_points_session(tmp_path / "at20.h5", at[20.0]))
    ref_path = write_points_session(tmp_path / "at23.h5", at[23.0])

    raw = diagnose(here.points, twin_from_recording(at[23.0], "at23.h5"))
    (scale,) = [f for f in raw["findings"] if f["effect"] == "scale"]
    expected = -cfg.expansion_ppm_per_k * 3.0
    assert abs(scale["parameters"]["scale_ppm"] - expected) < 0.1 * abs(expected)
    assert "3.00 K warmer" in scale["temperature_difference"]["note"]  # the words stay where no normalising is done

    report, lines = diagnose_session(here, tmp_path / "at20.h5", twins.load_twin(str(ref_path)))
    assert report["twin"]["normalised_legs"] == [1]
    assert not [f for f in report["findings"] if f["effect"] == "scale"]
    (cand,) = [c for c in report["legs"]["1"]["candidates"] if c["effect"] == "scale"]
    assert cand["status"] != "named"
    assert "normalised to 20 degC (NDE) like the twin" in lines[0]

    # a reference without material temperature: raw, the scale tied to nothing it could name
    no_temp = at[23.0].copy()
    no_temp["material_temp_c"] = np.nan
    bare = write_points_session(tmp_path / "bare.h5", no_temp)
    report, _ = diagnose_session(here, tmp_path / "at20.h5", twins.load_twin(str(bare)))
    assert "normalised_legs" not in report["twin"]
    assert [f for f in report["findings"] if f["effect"] == "scale"]
