"""The Interferometer conformance suite, run against the serial client talking to the simulated
instrument over a real pty."""

from __future__ import annotations

import pytest

from drivers.clock import VirtualClock
from drivers.interferometer.client import SerialInterferometer
from drivers.sim.interferometer_server import SimInterferometer
from drivers.plant.leg import LegPlant, default_leg_configs

import interferometer_conformance as conformance


@pytest.fixture(scope="module")
def sim_port():
    clock = VirtualClock(time_scale=0.0)
    plants = {leg: LegPlant(cfg, seed=leg) for leg, cfg in enumerate(default_leg_configs(seed=3), start=1)}
    with SimInterferometer(plants, clock, seed=3) as sim:
        yield sim.port
        assert not sim.failures, f"simulated instrument raised: {sim.failures!r}"


@pytest.mark.parametrize("check", conformance.ALL_CHECKS, ids=lambda c: c.__name__)
def test_serial_client_on_simulated_instrument(check, sim_port):
    check(lambda: SerialInterferometer(sim_port, timeout_s=0.5, retries=1), axes=(1, 2, 3, 4, 5, 6))
