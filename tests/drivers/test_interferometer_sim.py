"""The serial client against the simulated interferometer over a real pty: readings follow the
plant, and faults (beam break, weak signal, line noise, silence, refused commands) come out as
clear errors within the configured timeout."""

from __future__ import annotations

import math
import os
import threading
import time

import numpy as np
import pytest
import serial

from drivers.clock import VirtualClock
from drivers.errors import BeamBreak, CommTimeout, DriverError, FramingError
from drivers.interferometer.client import SerialInterferometer
from drivers.interferometer.protocol import ERR_BAD_AXIS, InstrumentError
from drivers.sim.interferometer_server import SimInterferometer
from drivers.plant.leg import LegPlant, PlantConfig

# quiet legs: the error sources stay, noise and run-to-run offsets are small
QUIET = PlantConfig(noise_um=0.005, run_offset_um=0.0)


class Rig:
    def __init__(self, configs: dict[int, PlantConfig], timeout_s: float = 0.2, retries: int = 2, **sim_kw):
        self.clock = VirtualClock(time_scale=0.0)
        self.lock = threading.RLock()
        self.plants = {axis: LegPlant(cfg, seed=axis) for axis, cfg in configs.items()}
        self.sim = SimInterferometer(self.plants, self.clock, lock=self.lock, **sim_kw)
        self.port = self.sim.start()
        self.laser = SerialInterferometer(self.port, timeout_s=timeout_s, retries=retries)

    def move(self, axis: int, to_mm: float, duration_s: float = 2.0) -> None:
        """Move a leg the way the simulated drive does: under the rig lock, on the clock."""
        with self.lock:
            self.clock.advance(duration_s)
            self.plants[axis].move(to_mm, self.clock.now())

    def close(self) -> None:
        self.laser.close()
        self.sim.stop()
        assert not self.sim.failures, f"simulated instrument raised: {self.sim.failures!r}"


@pytest.fixture
def rig():
    r = Rig({axis: QUIET for axis in range(1, 7)})
    yield r
    r.close()


def test_identity_names_the_simulated_instrument(rig):
    assert rig.laser.identity() == "StationSim,LI-6,SIM-0001,1.0"


def test_reading_tracks_plant_motion_within_the_plants_errors(rig):
    axis = 2
    plant = rig.plants[axis]
    errors_um = []
    for target_mm in (-80.0, -12.5, 0.0, 33.3, 85.0, 40.0):
        rig.move(axis, target_mm)
        r = rig.laser.read(axis)
        with rig.lock:
            error_um = plant.error_um(r.t_s)  # the leg's systematic error there, now
        assert r.axis == axis and r.beam_ok and r.t_s == pytest.approx(rig.clock.now())
        # the reading is the true leg position: commanded + error, within the 5 nm noise
        assert (r.position_mm - target_mm) * 1000.0 == pytest.approx(error_um, abs=0.03), target_mm
        errors_um.append(error_um)
    assert max(errors_um) - min(errors_um) > 0.5  # so the check above does see the error
    assert rig.laser.read(np.int64(axis)).axis == axis  # numpy integers from plans are fine
    assert rig.laser.read(5).position_mm == pytest.approx(0.0, abs=5e-3)  # other legs did not move


def test_averaging_reduces_scatter_and_takes_time_on_the_rig_clock():
    noisy = PlantConfig(noise_um=1.0).only("noise")
    r = Rig({1: noisy})
    try:
        def scatter_um(n: int = 40) -> tuple[float, float]:
            t0 = r.clock.now()
            values = [r.laser.read(1).position_mm * 1000.0 for _ in range(n)]
            return float(np.std(values, ddof=1)), (r.clock.now() - t0) / n

        r.laser.set_averaging(0.0)
        raw_um, raw_dt_s = scatter_um()
        r.laser.set_averaging(1.0)
        assert r.laser.averaging() == pytest.approx(1.0)
        avg_um, avg_dt_s = scatter_um()
    finally:
        r.close()
    assert 0.7 < raw_um < 1.3  # the plant's 1 um noise comes through unaveraged
    # 1 s of averaging = 10 plant samples: sqrt(10) less scatter
    assert avg_um == pytest.approx(raw_um / math.sqrt(10.0), rel=0.35)
    assert raw_dt_s == 0.0 and avg_dt_s == pytest.approx(1.0)


def test_environment_reports_air_and_each_legs_material_temperature():
    r = Rig({1: QUIET, 3: QUIET}, air=(21.5, 990.0, 55.0))
    try:
        for _ in range(10):  # heat leg 3 by running it up and down
            r.move(3, 85.0, duration_s=10.0)
            r.move(3, -85.0, duration_s=10.0)
        env = r.laser.environment()
        with r.lock:
            leg3_c = r.plants[3].material_temp_c(r.clock.now())
            leg1_c = r.plants[1].material_temp_c(r.clock.now())
    finally:
        r.close()
    assert leg3_c > leg1_c + 0.5  # the heating is real
    assert env.material_temp_of(3) == pytest.approx(leg3_c, abs=5e-4)
    assert env.material_temp_of(1) == pytest.approx(leg1_c, abs=5e-4)
    assert len(env.material_temp_c) == 6
    assert all(math.isnan(env.material_temp_of(leg)) for leg in (2, 4, 5, 6))  # no plant, no sensor
    assert env.air_temp_c == pytest.approx(21.5, abs=0.1)
    assert env.air_pressure_hpa == pytest.approx(990.0, abs=1.0)
    assert env.humidity_pct == pytest.approx(55.0, abs=2.0)


def test_zero_makes_readings_displacements_from_that_point(rig):
    axis = 4
    rig.move(axis, 30.0)
    before = rig.laser.read(axis).position_mm
    assert before == pytest.approx(30.0, abs=0.01)
    rig.laser.zero(axis)
    assert rig.laser.read(axis).position_mm == pytest.approx(0.0, abs=3e-5)
    rig.move(axis, 35.0)
    # 5 mm further on, plus the change of the leg's error over those 5 mm (well under 2 um)
    assert rig.laser.read(axis).position_mm == pytest.approx(5.0, abs=2e-3)


def test_beam_break_is_a_clear_error_and_clears_when_the_beam_is_back(rig):
    rig.sim.set_beam_break(3, True)
    with pytest.raises(BeamBreak, match=r"axis 3 on .*beam interrupted.*status BEAM") as info:
        rig.laser.read(3)
    assert "re-align" in str(info.value)  # the hint says what to do
    assert rig.sim.commands["POS?"] == 1  # no retry inside the driver: the sweep decides
    assert rig.laser.read(2).beam_ok  # other beams unaffected
    rig.sim.set_beam_break(3, False)
    assert rig.laser.read(3).beam_ok


def test_weak_signal_is_reported_as_beam_break(rig):
    rig.sim.set_signal_pct(1, 10.0)
    with pytest.raises(BeamBreak, match=r"signal too weak \(status LOW, signal 1\d\.\d %"):
        rig.laser.read(1)


def test_axis_without_a_plant_reports_beam():
    r = Rig({1: QUIET})
    try:
        with pytest.raises(BeamBreak, match="axis 6"):
            r.laser.read(6)
    finally:
        r.close()


@pytest.mark.parametrize("kind", ["checksum", "truncated", "noise", None])
def test_line_noise_up_to_the_retry_count_is_recovered(rig, kind):
    rig.move(1, 12.0)
    rig.laser.read(1)  # the first read also asks the averaging time: keep it out of the count
    sent = rig.sim.commands["POS?"]
    rig.sim.inject_garbage(2, kind)  # retries=2: the third attempt gets through
    r = rig.laser.read(1)
    assert r.position_mm == pytest.approx(12.0, abs=0.01)
    assert rig.laser.retried == 2
    assert rig.sim.commands["POS?"] - sent == 3


@pytest.mark.parametrize("kind", ["checksum", "truncated", "noise"])
def test_persistent_line_noise_is_a_framing_error_showing_the_line(rig, kind):
    rig.laser.set_averaging(0.0)
    rig.sim.inject_garbage(3, kind)
    t0 = time.monotonic()
    with pytest.raises(FramingError, match=r"malformed reply to 'POS\? 1' after 3 attempts.*last line b") as info:
        rig.laser.read(1)
    assert time.monotonic() - t0 < 0.2  # detected at once, no timeouts involved
    assert "baud rate" in str(info.value)  # the hint
    assert len(str(info.value)) < 400  # the offending line is shown truncated
    rig.sim.inject_garbage(0)
    assert rig.laser.read(1).beam_ok  # and the line works again


def test_unterminated_reply_costs_one_timeout_and_is_recovered():
    r = Rig({1: QUIET}, timeout_s=0.1, retries=1)
    try:
        r.sim.inject_garbage(1, "unterminated")
        t0 = time.monotonic()
        r.laser.read(1)
        elapsed_s = time.monotonic() - t0
        r.sim.inject_garbage(2, "unterminated")
        with pytest.raises(FramingError, match=r"not terminated"):
            r.laser.read(1)
    finally:
        r.close()
    assert 0.1 <= elapsed_s < 0.1 + 0.1


def test_silent_port_times_out_within_the_configured_bound_naming_the_port():
    timeout_s, retries = 0.1, 2
    r = Rig({1: QUIET}, timeout_s=timeout_s, retries=retries)
    try:
        r.laser.read(1)
        r.sim.set_silent(True)
        t0 = time.monotonic()
        with pytest.raises(CommTimeout) as info:
            r.laser.read(1)
        elapsed_s = time.monotonic() - t0
        r.sim.set_silent(False)
        assert r.laser.read(1).beam_ok  # recovers when the instrument speaks again
    finally:
        r.close()
    message = str(info.value)
    assert r.port in message and "0.1 s" in message and "3 attempts" in message
    bound_s = timeout_s * (retries + 1)
    assert bound_s <= elapsed_s < bound_s + 0.15  # 20 ms poll slice per attempt + scheduling


def test_axis_the_instrument_lacks_is_an_instrument_error_naming_it():
    # client set up for six axes, instrument with four: the instrument refuses axis 5
    r = Rig({1: QUIET}, axes=4)
    try:
        with pytest.raises(InstrumentError) as info:
            r.laser.read(5)
        assert r.sim.commands["POS?"] == 1  # a refusal is not retried
        message = str(info.value)
        assert info.value.code == ERR_BAD_AXIS and isinstance(info.value, DriverError)
        assert f"on {r.port} refused 'POS? 5': bad axis" in message and "1..4; got 5" in message
        # the ENV reply then has 4 material temperatures: clear message, not an index error
        with pytest.raises(FramingError, match="4 material temperatures, expected 6"):
            r.laser.environment()
    finally:
        r.close()


def test_instrument_refuses_unknown_commands_and_bad_arguments(rig):
    # a raw terminal on the line (what a technician with a terminal program would see)
    rig.laser.close()
    with serial.Serial(rig.port, timeout=1.0) as raw:
        for command, expected in (
            (b"FOO 1\n", b"ERR,1,unknown command FOO*3D\r\n"),
            (b"AVG 12\r\n", b"ERR,4,AVG must be 0..10 s; got 12*3F\r\n"),
            (b"POS?\n", b"ERR,2,expected one axis number*2D\r\n"),
            (b"pos? x\n", b"ERR,2,axis must be an integer; got x*3A\r\n"),
            (b"avg?\n", b"AVG,0.000*52\r\n"),
        ):
            raw.write(command)
            assert raw.read_until(b"\r\n") == expected, command
        raw.write(b"X" * 300)
        assert raw.read_until(b"\r\n").startswith(b"ERR,5,no terminator within 256 bytes*")


def test_client_refuses_out_of_range_values_before_sending(rig):
    with pytest.raises(ValueError, match=r"0..10 s, got 12"):
        rig.laser.set_averaging(12.0)
    with pytest.raises(ValueError, match=r"axis must be an integer in 1..6, got 7"):
        rig.laser.read(7)
    with pytest.raises(ValueError, match=r"axis must be an integer in 1..6, got 2.0"):
        rig.laser.zero(2.0)
    assert sum(rig.sim.commands.values()) == 0


def test_port_is_exclusive(rig):
    with pytest.raises(DriverError, match=rf"cannot open .*{rig.port}.*Another program holds the port"):
        SerialInterferometer(rig.port)
    assert rig.laser.read(1).beam_ok  # the owner is undisturbed


def test_missing_port_is_a_clear_error():
    with pytest.raises(DriverError, match=r"cannot open the interferometer serial port '/dev/does-not-exist'.*port name"):
        SerialInterferometer("/dev/does-not-exist")


def test_from_url_takes_port_and_settings(rig):
    rig.laser.close()
    laser = SerialInterferometer.from_url(f"serial://{rig.port}?baud=57600&timeout_s=0.3&retries=4&axes=6")
    try:
        assert (laser.port, laser.baudrate, laser.timeout_s, laser.retries) == (rig.port, 57600, 0.3, 4)
        assert laser.read(1).beam_ok
    finally:
        laser.close()
    with pytest.raises(ValueError, match="unknown parameter 'speed'"):
        SerialInterferometer.from_url(f"serial://{rig.port}?speed=9600")


def test_stop_joins_the_thread_and_leaks_no_descriptors():
    def open_fds() -> int:
        return len(os.listdir("/proc/self/fd"))

    before = open_fds()
    threads_before = threading.active_count()
    for _ in range(3):
        r = Rig({1: QUIET})
        r.laser.read(1)
        r.close()
    assert open_fds() == before
    assert threading.active_count() == threads_before


def test_client_counts_the_bytes_of_each_exchange_for_the_wire_model(rig):
    from drivers.interferometer import protocol as proto

    laser = rig.laser
    out0, in0, tx0 = laser.bytes_out, laser.bytes_in, laser.transactions
    assert laser.identity() == "StationSim,LI-6,SIM-0001,1.0"
    reply = proto.frame_reply("IDN", "StationSim", "LI-6", "SIM-0001", "1.0")
    assert laser.transactions - tx0 == 1
    assert laser.bytes_out - out0 == len(proto.cmd_identity())
    assert laser.bytes_in - in0 == len(reply)
