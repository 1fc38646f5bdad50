"""The fault tools themselves (drivers/sim/faults.py): each kind does to the link what it says,
seen by the station's real clients over 127.0.0.1 and a pty, and the schedules count it."""

from __future__ import annotations

import logging
import os

import pytest

from drivers.clock import VirtualClock
from drivers.errors import CommTimeout, DriverError, FramingError
from drivers.interferometer.client import SerialInterferometer
from drivers.modbus.client import connect_axes
from drivers.sim.faults import MBAP_BYTES, FaultSchedule, ModbusFaultProxy, SerialLineFaults, corrupt_frame
from drivers.sim.rig import SimRig


@pytest.fixture(scope="module")
def sim():
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    with SimRig(time_scale=0.0, seed=3, legs=2) as rig:
        yield rig


def _proxy(sim, kind: str, **kw) -> ModbusFaultProxy:
    schedule = FaultSchedule((kind,), seed=1, rate=1.0)
    schedule.enabled = False
    proxy = ModbusFaultProxy(sim.drive_url, schedule, **kw)
    proxy.start()
    return proxy


def test_a_clean_proxy_passes_every_frame_unchanged(sim):
    proxy = _proxy(sim, "drop")
    try:
        direct = connect_axes(sim.drive_url, (1, 2), sim.profile, timeout_s=1.0, clock=sim.clock)
        via = connect_axes(proxy.url, (1, 2), sim.profile, timeout_s=1.0, clock=sim.clock)
        for leg in (1, 2):
            assert via[leg].identity() == direct[leg].identity()
            assert via[leg].limits() == direct[leg].limits()
        assert proxy.schedule.frames >= 8 and proxy.schedule.total == 0
    finally:
        for axes in (direct, via):
            for a in axes.values():
                a.close()
        proxy.stop()


@pytest.mark.parametrize("kind", ["drop", "reset", "half_open"])
def test_a_lost_frame_or_connection_is_a_timeout_then_the_client_reconnects(sim, kind):
    proxy = _proxy(sim, kind)
    try:
        axis = connect_axes(proxy.url, (1,), sim.profile, timeout_s=0.3, clock=sim.clock)[1]
        proxy.schedule.enabled = True
        with pytest.raises(CommTimeout, match="unit id 1"):
            axis.status()
        assert proxy.counts[kind] >= 1
        proxy.schedule.enabled = False
        assert axis.status().position_mm == pytest.approx(sim.plants[1].x_mm, abs=1e-3)  # a new connection
        assert proxy.connections >= 2
        axis.close()
    finally:
        proxy.stop()


def test_a_delay_within_the_timeout_passes_and_one_beyond_it_times_out(sim):
    short = _proxy(sim, "delay", delay_s=(0.02, 0.05))
    long = _proxy(sim, "delay", delay_s=(0.8, 0.9))
    try:
        a = connect_axes(short.url, (1,), sim.profile, timeout_s=0.6, retries=0, clock=sim.clock)[1]
        b = connect_axes(long.url, (1,), sim.profile, timeout_s=0.6, retries=0, clock=sim.clock)[1]
        short.schedule.enabled = long.schedule.enabled = True
        assert a.identity().startswith(sim.profile.identity["vendor"])
        with pytest.raises(CommTimeout, match="no answer"):
            b.identity()
        assert short.counts["delay"] >= 1 and long.counts["delay"] >= 1
        a.close()
        b.close()
    finally:
        short.stop()
        long.stop()


def test_corruption_flips_one_to_three_bytes_in_the_header_or_in_the_pdu():
    frame = bytes(range(1, 20))  # 7 header bytes + 12 PDU bytes
    schedule = FaultSchedule(("corrupt",), seed=5, rate=1.0)
    where = set()
    for _ in range(500):
        bad = corrupt_frame(frame, schedule)
        diff = [i for i, (x, y) in enumerate(zip(frame, bad)) if x != y]
        assert len(bad) == len(frame) and 1 <= len(diff) <= 3
        header = [i < MBAP_BYTES for i in diff]
        assert all(header) or not any(header), "one region per corruption"
        where.add(header[0])
    assert where == {True, False}


def test_a_schedule_on_the_rig_clock_injects_every_few_minutes():
    clock = VirtualClock(0.0)
    schedule = FaultSchedule(("drop", "delay"), seed=2, every_s=120.0, clock=clock)
    for _ in range(6000):
        clock.sleep(2.0)  # 200 rig minutes, a frame every 2 s
        schedule.decide()
    assert 70 <= schedule.total <= 130, schedule.total  # about 100 at one per 2 rig minutes
    assert set(schedule.counts) == {"drop", "delay"}


def _line(sim, kind: str, **kw) -> SerialLineFaults:
    schedule = FaultSchedule((kind,), seed=4, rate=1.0)
    schedule.enabled = False
    line = SerialLineFaults(sim.laser_port, schedule, **kw)
    line.start()
    return line


def test_line_noise_is_caught_by_the_client_and_retried(sim):
    line = _line(sim, "noise")
    try:
        laser = SerialInterferometer(line.path, timeout_s=0.3, retries=2)
        ident = laser.identity()
        line.schedule.enabled = True
        with pytest.raises((FramingError, CommTimeout)):
            laser.identity()  # every reply noisy: malformed on each attempt
        line.schedule.enabled = False
        assert laser.identity() == ident and laser.retried >= 2
        laser.close()
    finally:
        line.stop()


def test_silence_swallows_replies(sim):
    line = _line(sim, "silence", silence_lines=(1, 1))
    try:
        laser = SerialInterferometer(line.path, timeout_s=0.2, retries=1)
        line.schedule.enabled = True
        with pytest.raises(CommTimeout, match="did not answer"):
            laser.identity()
        assert line.counts["silence"] == 2
        laser.close()
    finally:
        line.stop()


def test_an_unplugged_port_vanishes_comes_back_under_its_name_and_the_client_reopens_it(sim):
    line = _line(sim, "unplug", unplug_s=(0.2, 0.2))
    try:
        laser = SerialInterferometer(line.path, timeout_s=0.3, retries=2)
        ident = laser.identity()
        line.schedule.enabled = True
        with pytest.raises(DriverError):  # each reply unplugs the port again: no answer ever
            laser.identity()
        line.schedule.enabled = False
        assert laser.identity() == ident  # plugged back in: the client opened it again
        assert laser.reopened >= 1 and line.plugs >= 2 and line.counts["unplug"] >= 1
        assert os.path.exists(line.path)
        laser.close()
    finally:
        line.stop()


def test_a_status_garbled_into_an_impossible_load_is_refused_as_framing_not_recorded(sim):
    # found by the link faults: a corrupted status reply held -1.7e7 N, the sweep recorded it and
    # the reader then refused the whole session file as damaged
    axis = connect_axes(sim.drive_url, (1,), sim.profile, timeout_s=1.0, clock=sim.clock)[1]
    try:
        good = axis._read_block("status")  # noqa: SLF001 - the decoded registers, then garbled
        assert axis._status_from(good).load_n == pytest.approx(good["axial_load"])  # noqa: SLF001
        with pytest.raises(FramingError, match="impossible status"):
            axis._status_from({**good, "axial_load": -1.74483e7})  # noqa: SLF001
    finally:
        axis.close()
