"""The Interferometer conformance suite, run against the µLine-F1 client talking to the simulated
µLine-F1 over a real pty (one beam: axis 1, zeroed as the factory opens it)."""

from __future__ import annotations

import pytest

from drivers.clock import VirtualClock
from drivers.linef1 import LineF1Interferometer
from drivers.sim.linef1_server import SimLineF1
from drivers.plant.leg import LegPlant, default_leg_configs

import interferometer_conformance as conformance


@pytest.fixture(scope="module")
def sim():
    clock = VirtualClock(time_scale=0.0)
    plants = {leg: LegPlant(cfg, seed=leg) for leg, cfg in enumerate(default_leg_configs(seed=3), start=1)}
    with SimLineF1(plants, clock, seed=3) as sim:
        yield sim
        assert not sim.failures, f"simulated instrument raised: {sim.failures!r}"


@pytest.mark.parametrize("check", conformance.ALL_CHECKS, ids=lambda c: c.__name__)
def test_linef1_client_on_simulated_instrument(check, sim):
    def factory():
        laser = LineF1Interferometer(sim.port, clock=sim.clock, timeout_s=0.5, retries=1)
        laser.zero(1)  # one beam, on leg 1 (the simulated operator's default)
        return laser

    check(factory, axes=(1,))
