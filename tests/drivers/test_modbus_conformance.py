"""The ServoAxis conformance suite against the Modbus client on the simulated drive, over
Modbus TCP (127.0.0.1) and Modbus RTU (pty), for every drive profile shipped: the simulated
drive serves each profile with its line rules (request lengths, silence between frames,
set-point latch, unit ids), so the real client is tested against each."""

from __future__ import annotations

from pathlib import Path

import pytest
from servo_conformance import CHECKS, AxisUnderTest

from drivers.modbus.profile import DriveProfile

LEG = 4
PROFILES = sorted((Path(__file__).resolve().parents[2] / "drivers" / "modbus" / "profiles").glob("*.toml"))


@pytest.fixture(scope="module", params=PROFILES, ids=[p.stem for p in PROFILES])
def profile(request) -> DriveProfile:
    """Overrides tests/drivers/conftest.py's `profile`: sim_drives serves this one."""
    return DriveProfile.load(request.param)


def test_the_real_drive_profiles_are_shipped():
    assert {"default", "kinco_fd", "delta_asda_a2"} <= {p.stem for p in PROFILES}


@pytest.fixture(params=["tcp", "rtu"])
def make_axis(request, sim_drives, profile):
    transport = request.param
    made = []

    def make() -> AxisUnderTest:
        sd = sim_drives(rtu=transport == "rtu")
        made.append(sd)
        plant = sd.plants[LEG]

        def true_position_mm() -> float:
            with sd.lock:
                return plant.true_position_mm(sd.clock.now())

        return AxisUnderTest(
            axis=sd.axis(LEG),
            true_position_mm=true_position_mm,
            inject_fault=lambda code: sd.server.inject_fault(LEG, code),
            supports_tables=profile.has_table,
            reports_fault_code=profile.has("fault_code"),
        )

    yield make
    for sd in made:  # whatever the check did, the client kept the drive's line rules
        f = sd.server.frame_stats()
        assert f.requests > 0
        assert f.oversize == 0 and f.gap_violations == 0, f"{profile.name}: the client broke the line rules: {f}"
        assert f.longest_read_words <= profile.protocol.max_read_words
        assert f.longest_write_words <= profile.protocol.max_write_words


@pytest.mark.parametrize("check", CHECKS, ids=[c.__name__.removeprefix("check_") for c in CHECKS])
def test_servo_conformance(check, make_axis):
    check(make_axis)
