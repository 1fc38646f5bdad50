"""The ServoAxis conformance suite against the Modbus client on the simulated drive, over
Modbus TCP (127.0.0.1) and Modbus RTU (pty)."""

from __future__ import annotations

import pytest
from servo_conformance import CHECKS, AxisUnderTest

LEG = 4


@pytest.fixture(params=["tcp", "rtu"])
def make_axis(request, sim_drives):
    transport = request.param

    def make() -> AxisUnderTest:
        sd = sim_drives(rtu=transport == "rtu")
        plant = sd.plants[LEG]

        def true_position_mm() -> float:
            with sd.lock:
                return plant.true_position_mm(sd.clock.now())

        return AxisUnderTest(
            axis=sd.axis(LEG),
            true_position_mm=true_position_mm,
            inject_fault=lambda code: sd.server.inject_fault(LEG, code),
        )

    return make


@pytest.mark.parametrize("check", CHECKS, ids=[c.__name__.removeprefix("check_") for c in CHECKS])
def test_servo_conformance(check, make_axis):
    check(make_axis)
