"""The µLine-F1's latched flags as an on-the-fly pass meets them (drivers/linef1/client.py): a
broken beam sets the small-signal flag, which every later frame carries until the host clears it,
so a pass's span after the beam came back still fails until `clear_signal_latch`; a velocity
overflow loses the count, which clearing the small signal does not recover and only `zero` (the
origin set again) does. Real pty, the simulated instrument's frames."""

from __future__ import annotations

import logging

import pytest

from drivers.errors import BeamBreak, CountLost
from drivers.interfaces import LatchingInterferometer
from drivers.linef1.client import LineF1Interferometer
from drivers.modbus.client import connect_axes
from drivers.plant.leg import default_leg_configs
from drivers.sim.rig import SimRig

logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


@pytest.fixture(scope="module")
def rig_laser():
    cfgs = [c.without("noise", "run_offset", "thermal") for c in default_leg_configs(2, 1)]
    with SimRig(time_scale=0.0, seed=2, legs=1, configs=cfgs, laser_protocol="linef1") as rig:
        axis = connect_axes(rig.drive_url, [1], clock=rig.clock)[1]
        laser = LineF1Interferometer(rig.laser_port, clock=rig.clock)
        try:
            axis.enable()
            laser.zero(1)
            yield rig, laser
        finally:
            laser.close()
            axis.close()


def _span(rig, laser, seconds: float = 0.4):
    """The samples of the next `seconds` of the stream (at rest)."""
    t0 = rig.clock.now()
    rig.clock.sleep(seconds)
    return laser.stream_samples(1, t0, rig.clock.now() - 0.05)


@pytest.mark.timeout(30)
def test_a_beam_break_stays_latched_in_the_stream_until_cleared(rig_laser):
    rig, laser = rig_laser
    assert isinstance(laser, LatchingInterferometer)
    good = _span(rig, laser)
    rig.laser_server.inject("beam", duration_s=0.1)
    rig.clock.sleep(0.3)  # the beam is back
    with pytest.raises(BeamBreak, match="small signal"):
        _span(rig, laser)  # its frames still carry the latch
    laser.clear_signal_latch(1)
    after = _span(rig, laser)
    assert len(after) >= 8 and abs(after[-1].position_mm - good[-1].position_mm) < 1e-6  # the count kept


@pytest.mark.timeout(30)
def test_a_lost_count_is_not_cleared_with_the_small_signal_only_by_the_origin(rig_laser):
    rig, laser = rig_laser
    rig.laser_server.inject("overflow")
    rig.clock.sleep(0.2)
    with pytest.raises(CountLost):
        _span(rig, laser)
    laser.clear_signal_latch(1)
    with pytest.raises(CountLost):
        _span(rig, laser)
    laser.zero(1)
    after = _span(rig, laser)
    assert len(after) >= 8 and all(abs(s.position_mm) < 1e-3 for s in after)  # at the new origin, at rest
