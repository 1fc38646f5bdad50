"""The µLine-F1's time stamps (drivers/linef1/client.py, `_grid_stamps`), the virtual clock's
event stops (drivers/clock.py) and a traced move on the simulated rig (ModbusAxis.move_traced)."""

from __future__ import annotations

import logging

import numpy as np
import pytest

import math
import time

from drivers.clock import VirtualClock
from drivers.modbus.profile import DriveProfile
from drivers.linef1.client import LineF1Interferometer, _Sample
from drivers.modbus.client import connect_axes
from drivers.plant.leg import LegPlant, default_leg_configs
from drivers.sim.drive_server import DriveModel
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


class _SetClock:
    """A clock set by the test, to the float."""
    time_scale = 1.0
    t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, dt_s: float) -> None:
        self.t += dt_s


def test_the_drives_nut_never_steps_back_within_a_move_asked_at_two_instants_a_rounding_apart():
    """The jerk-limited closed form, a difference of two large integrals, goes back 1e-12 mm
    between two instants a rounding apart near a move's end (a traced pass's poll and a frame,
    both 'at 63.24 s'); the plant took that for a reversal: a new pass offset and the lost motion
    wound up again between an on-the-fly pass and its anchor."""
    clock = _SetClock()
    plant = LegPlant(default_leg_configs(2, 1)[0].with_leg_motion(), seed=3)
    model = DriveModel(1, plant, clock, DriveProfile.load())
    model._set("profile_velocity", 20.0)
    model._start_move(-94.0)
    clock.t = 100.0
    model.refresh()
    model._start_move(94.0)
    m = model.motion
    pairs = []  # (t, t2 a few ulps later) where the closed form goes back
    for t in np.linspace(m.t_end - 0.1, m.t_end - 1e-6, 2001):
        t2 = float(t)
        for _ in range(8):
            t2 = math.nextafter(t2, math.inf)
            if m.position(t2) < m.position(float(t)):
                pairs.append((float(t), t2))
                break
    assert len(pairs) >= 5  # the rounding this guards against is there
    passes = plant.pass_index
    for t, t2 in pairs[:5]:
        for at in (t, t2):
            clock.t = at
            model.refresh()
    clock.t = m.t_end + 1.0
    model.refresh()
    assert plant.x_mm == 94.0 and plant.direction == 1
    assert plant.pass_index == passes + 1  # the reversal at the move's start, none after


def test_a_frame_due_while_another_source_holds_the_clock_at_its_instant_measures_the_leg_there():
    """The simulated µLine-F1's serving thread (which wakes every 2 ms, real time) writes no frame
    that is the clock's to write: held at a frame's instant, before the instrument's own stop ran
    (here by another source of the same instant, 5 ms of real time), it once wrote the frame itself
    with the leg where the drive was last brought, a poll 10 ms before: 0.2 mm short at 20 mm/s."""
    cfgs = [c.with_leg_motion().without("noise", "run_offset", "thermal") for c in default_leg_configs(2, 1)]
    rig = SimRig(time_scale=0.0, seed=2, legs=1, configs=cfgs, laser_protocol="linef1")
    hold = [False]

    def next_due():  # the instrument's next frame, while held
        t = rig.laser_server._next_t
        return t if hold[0] and t is not None and t > rig.clock.now() else None

    rig.clock.add_events(next_due, lambda t: time.sleep(0.005))  # before the instrument's (rig.start)
    with rig:
        axis = connect_axes(rig.drive_url, [1], clock=rig.clock)[1]
        laser = LineF1Interferometer(rig.laser_port, clock=rig.clock)
        try:
            axis.enable()
            laser.zero(1)
            axis.move_to(-94.0)
            hold[0] = True
            _, trace = axis.move_traced(94.0, 20.0, 0.02)
            hold[0] = False
            rig.clock.sleep(0.5)
            stream = laser.stream_samples(1, trace[0][0], trace[-1][0])
        finally:
            laser.close()
            axis.close()
    t_tr = np.array([t for t, _ in trace])
    x_tr = np.array([x for _, x in trace])
    t_s = np.array([s.t_s for s in stream])
    # the laser's reading less the drive's traced position at each sample's stamp: a constant (the
    # origin), the leg's error (a few um) and lag (2.4 um at 20 mm/s), the path between polls
    off_mm = np.array([s.position_mm for s in stream]) - np.interp(t_s, t_tr, x_tr)
    assert t_s.size > 200  # the pass's frames, 188 mm at 20 mm/s
    assert np.max(np.abs(off_mm - np.median(off_mm))) < 0.02, f"worst {np.max(np.abs(off_mm - np.median(off_mm))):.4f} mm"


def test_another_thread_asking_the_time_does_not_let_the_clock_past_an_unstamped_frame():
    """The simulated µLine-F1 holds the clock at a frame's instant until its client's reader has
    stamped it; another thread asking the time meanwhile (here every 0.2 ms; on a loaded machine
    e.g. the drive's server answering a late request) once counted as that stamp: the clock went
    on, frames were stamped late, readings and anchors moved, a pass read tens of um off."""
    import threading

    cfgs = [c.with_leg_motion().without("noise", "run_offset", "thermal") for c in default_leg_configs(2, 1)]
    with SimRig(time_scale=0.0, seed=2, legs=1, configs=cfgs, laser_protocol="linef1") as rig:
        axis = connect_axes(rig.drive_url, [1], clock=rig.clock)[1]
        laser = LineF1Interferometer(rig.laser_port, clock=rig.clock)
        stop = threading.Event()

        def ask():
            while not stop.is_set():
                rig.clock.now()
                time.sleep(0.0002)

        asker = threading.Thread(target=ask, daemon=True)
        try:
            axis.enable()
            laser.zero(1)
            axis.move_to(-94.0)
            asker.start()
            t_start = rig.clock.now()
            _, trace = axis.move_traced(94.0, 20.0, 0.02)
            rig.clock.sleep(0.5)
            stream = laser.stream_samples(1, trace[0][0], trace[-1][0])
            raw = [s.t_s for s in laser._samples if s.t_s >= t_start]  # the arrival stamps themselves
        finally:
            stop.set()
            asker.join()
            laser.close()
            axis.close()
    k = np.array(raw) / T
    assert len(raw) > 200 and np.max(np.abs(k - np.round(k))) < 1e-6  # every frame stamped at its instant
    t_tr = np.array([t for t, _ in trace])
    x_tr = np.array([x for _, x in trace])
    off_mm = np.array([s.position_mm for s in stream]) - np.interp([s.t_s for s in stream], t_tr, x_tr)
    assert np.max(np.abs(off_mm - np.median(off_mm))) < 0.02
