"""The µLine-F1's time stamps (drivers/linef1/client.py, `_grid_stamps`), the virtual clock's
event stops (drivers/clock.py) and a traced move on the simulated rig (ModbusAxis.move_traced)."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from drivers.clock import VirtualClock
from drivers.linef1.client import LineF1Interferometer, _Sample
from drivers.modbus.client import connect_axes
from drivers.plant.leg import default_leg_configs
from drivers.sim.rig import SimRig

logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
T = 0.04


def samples(arrivals_s, numbers):
    return [_Sample(seq=i, t_s=t, raw_mm=0.0, overflow=False, stable=True, signal_good=True, level=200, frame_no=n)
            for i, (t, n) in enumerate(zip(arrivals_s, numbers))]


def grid(s):
    laser = LineF1Interferometer.__new__(LineF1Interferometer)  # the method needs the period only
    laser.period_s = T
    return np.array(laser._grid_stamps(s))


def test_late_arrivals_take_the_grid_of_the_earliest_arrival_ahead():
    n = np.arange(1, 11)
    due = 10.0 + n * T
    late = due + np.array([0.013, 0.02, 0.0, 0.031, 0.007, 0.0, 0.019, 0.0, 0.011, 0.0])
    assert np.allclose(grid(samples(late, n)), due, atol=1e-12)


def test_a_gap_in_the_stream_moves_only_the_frames_after_it():
    n = np.arange(1, 11)
    due = 10.0 + n * T
    due[5:] += 3 * T  # three frames never sent: not numbered, so the frames after come "late"
    stamps = grid(samples(due + np.r_[np.zeros(5), 0.01, 0.0, 0.02, 0.0, 0.0], n))
    assert np.allclose(stamps, due, atol=1e-12)


def test_the_virtual_clock_stops_at_every_event_within_a_jump_and_knows_who_asked_the_time():
    clock = VirtualClock(0.0)
    seen = []
    nxt = [0.25]

    def on_due(t):
        seen.append((t, clock.now()))
        nxt[0] += 0.25

    clock.add_events(lambda: nxt[0], on_due)
    clock.sleep(1.1)
    assert clock.now() == pytest.approx(1.1)
    assert [t for t, _ in seen] == [0.25, 0.5, 0.75, 1.0] and all(t == now for t, now in seen)
    mark = clock.reads()
    import threading

    assert not clock.read_since(mark, {threading.get_ident()})
    th = threading.Thread(target=clock.now)
    th.start()
    th.join()
    assert clock.read_since(mark, {threading.get_ident()})


def test_a_traced_move_is_seen_under_way_at_time_scale_0_and_is_one_pass_of_the_leg():
    cfgs = [c.with_leg_motion() for c in default_leg_configs(2, 1)]
    with SimRig(time_scale=0.0, seed=2, legs=1, configs=cfgs, laser_protocol="linef1") as rig:
        axis = connect_axes(rig.drive_url, [1], clock=rig.clock)[1]
        try:
            axis.enable()
            axis.move_to(-94.0)
            passes = rig.plants[1].pass_index
            t0 = rig.clock.now()
            status, trace = axis.move_traced(94.0, 10.0, 0.02)
            axis.status()  # the drive's next request
            t = np.array([a for a, _ in trace])
            x = np.array([b for _, b in trace])
        finally:
            axis.close()
    assert status.target_reached and x[-1] == pytest.approx(94.0, abs=1e-3)
    assert np.all(np.diff(t) > 0) and np.all(np.diff(x) >= 0)  # polled on the clock, never back
    cruise = (x > -85.0) & (x < 85.0)
    assert np.allclose(np.diff(x[cruise]) / np.diff(t[cruise]), 10.0, rtol=1e-3)  # at the pass speed
    assert 18.8 <= rig.clock.now() - t0 <= 19.3  # 188 mm at 10 mm/s, its ramps and the last poll
    # one reversal at its start (it came down to -94), none at its end (a new pass would mean
    # another offset, another wind-up of the lost motion)
    assert rig.plants[1].pass_index == passes + 1 and rig.plants[1].direction == 1
