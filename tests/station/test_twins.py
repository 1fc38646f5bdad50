"""The diagnosis twins both front ends build (station.services.twins): `station diagnose --twin` and the
terminal UI's Diagnosis page use the same functions."""

import pytest

from procedures.diagnosis.twin import ExternalTwin
from procedures.errors import InputError
from station.services import selfcheck, twins
from station.commands import diagnose as diagnose_command


def test_the_command_and_the_self_check_use_the_shared_twins():
    assert diagnose_command.load_twin is twins.load_twin
    assert selfcheck.plant_twin is twins.plant_twin


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
