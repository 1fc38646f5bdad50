"""Motion dynamics of the simulated leg and on-the-fly capture over the real protocols: the
drive's position compare (Modbus TCP on 127.0.0.1) triggers the interferometer's capture (a pty)."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from drivers.errors import BeamBreak
from drivers.interferometer import protocol as p
from drivers.interferometer.client import SerialInterferometer
from drivers.interferometer.protocol import InstrumentError
from drivers.modbus.client import connect_axes
from drivers.sim.motion import SmoothedMove
from drivers.plant.leg import LEG_JERK_MM_S3, LegPlant, PlantConfig, default_leg_configs
from drivers.sim.rig import SimRig

logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


# -- motion dynamics ------------------------------------------------------------------------------

def test_jerk_limited_move_is_an_s_curve_lasting_accel_over_jerk_longer():
    trap = SmoothedMove(0.0, 50.0, 0.0, 10.0, 100.0)
    s = SmoothedMove(0.0, 50.0, 0.0, 10.0, 100.0, jerk=2000.0)
    assert s.duration == pytest.approx(trap.duration + 100.0 / 2000.0)
    t = np.linspace(0.0, s.duration, 4001)
    x = np.array([s.position(u) for u in t])
    v = np.array([s.velocity(u) for u in t])
    assert x[0] == 0.0 and x[-1] == pytest.approx(50.0, abs=1e-12)
    assert np.all(np.diff(x) >= -1e-12)  # monotone
    assert v.max() == pytest.approx(10.0, abs=1e-9)
    acc = np.diff(v) / np.diff(t)
    jerk = np.diff(acc) / np.diff(t)[1:]
    assert np.abs(acc).max() <= 100.0 + 1e-6  # the acceleration limit holds
    assert np.abs(jerk).max() <= 2000.0 * 1.01  # and the jerk limit: no step in acceleration
    # velocity is the derivative of position
    assert np.allclose(np.gradient(x, t), v, atol=0.05)
    # a short (triangular) move too
    short = SmoothedMove(0.0, -0.5, 1.0, 10.0, 100.0, jerk=2000.0)
    assert short.position(short.t_end) == pytest.approx(-0.5, abs=1e-12)
    assert short.time_at(-0.25) == pytest.approx(1.0 + short.duration / 2, abs=1e-9)  # symmetric


def test_plant_dynamic_error_is_proportional_to_speed_per_direction_and_rings_out_after_a_stop():
    cfg = PlantConfig().only()  # no static error: only the dynamics
    plant = LegPlant(cfg)
    plant.set_velocity(10.0)
    assert plant.dynamic_error_um(1.0) == pytest.approx(-cfg.dynamic_lag_up_s * 10.0 * 1000.0)
    plant.set_velocity(-20.0)
    assert plant.dynamic_error_um(1.0) == pytest.approx(cfg.dynamic_lag_down_s * 20.0 * 1000.0)
    assert cfg.dynamic_lag_up_s != cfg.dynamic_lag_down_s  # direction-dependent
    plant.stopped(2.0, -1, 100.0)
    first = plant.dynamic_error_um(2.0)
    assert first == pytest.approx(-cfg.settle_um_per_mm_s2 * 100.0)  # overshoot in the direction of motion
    assert abs(plant.dynamic_error_um(2.0 + cfg.settling_tau_s)) == pytest.approx(abs(first) / math.e)
    assert plant.dynamic_error_um(2.0 + cfg.settling_time_s + 1e-9) == 0.0  # settled: exactly static


def test_drive_reports_a_direction_dependent_following_error_while_moving():
    cfg = PlantConfig()
    assert cfg.following_lag_s(5.0) != cfg.following_lag_s(-5.0)
    assert cfg.following_lag_s(5.0) * 10.0 * 1000.0 == pytest.approx(20.0)  # 20 um at 10 mm/s


# -- capture over the real protocols -----------------------------------------------------------------

@pytest.fixture
def rig():
    cfgs = [c.with_leg_motion() for c in default_leg_configs(3, 2)]
    with SimRig(time_scale=0.0, legs=2, configs=cfgs) as r:
        axes = connect_axes(r.drive_url, [1, 2], clock=r.clock)
        laser = SerialInterferometer(r.laser_port)
        try:
            yield r, axes, laser
        finally:
            laser.close()
            for a in axes.values():
                a.close()


def test_position_compare_triggers_the_laser_at_every_target_with_the_dynamic_offset(rig):
    r, axes, laser = rig
    ax = axes[1]
    ax.enable()
    ax.move_to(-2.0)
    ax.move_to(0.0)
    laser.zero(1)
    ax.move_to(-94.0)
    ax.arm_position_compare(-90.0, 1.0, 181)
    laser.arm_capture(1, 181)
    for speed in (10.0, 20.0):
        if speed == 20.0:
            ax.move_to(-94.0)
            ax.arm_position_compare(-90.0, 1.0, 181)
            laser.arm_capture(1, 181)
        ax.move_to(94.0, velocity_mm_s=speed)
        assert laser.capture_count(1) == (181, 181)
        s = [laser.capture_sample(1, i) for i in range(181)]
        t = np.array([x.t_s for x in s])
        assert np.allclose(np.diff(t), 1.0 / speed, atol=2e-6)  # constant speed through every target
        pos = np.array([x.position_mm for x in s])
        err_um = (pos - np.arange(-90.0, 91.0, 1.0)) * 1000.0
        if speed == 10.0:
            slow = err_um
    # the speed-dependent part: 10 mm/s more makes the leg lag by 10 * dynamic_lag_up more
    cfg = r.plants[1].cfg
    diff = float(np.mean(err_um - slow))
    assert diff == pytest.approx(-cfg.dynamic_lag_up_s * 10.0 * 1000.0, abs=0.15)


def test_capture_refusals_and_a_beam_break_during_a_pass(rig):
    r, axes, laser = rig
    with pytest.raises(InstrumentError, match="not captured"):
        laser.capture_sample(2, 0)
    with pytest.raises(ValueError, match="capture count"):
        laser.arm_capture(2, p.MAX_CAPTURE + 1)
    ax = axes[2]
    ax.enable()
    ax.move_to(-10.0)
    ax.arm_position_compare(0.0, 2.0, 3)
    laser.arm_capture(2, 3)
    r.laser_server.set_beam_break(2, True)
    ax.move_to(10.0, velocity_mm_s=5.0)
    r.laser_server.set_beam_break(2, False)
    assert laser.capture_count(2) == (3, 3)
    with pytest.raises(BeamBreak, match="capture sample 0"):
        laser.capture_sample(2, 0)
    # the compare counts one direction only: a downward move gives no pulse for an upward list
    ax.arm_position_compare(0.0, 2.0, 3)
    laser.arm_capture(2, 3)
    ax.move_to(-10.0, velocity_mm_s=5.0)
    assert laser.capture_count(2) == (0, 3)


def test_capture_line_protocol_round_trip():
    reply = p.format_capture_sample(3, 7, "+1.000000001", "OK", "91.5", "12.500000")
    fields = p.split_reply(reply)
    s = p.parse_capture_sample(fields, 3, 7)
    assert (s.axis, s.index, s.position_mm, s.status, s.signal_pct, s.t_s) == (3, 7, 1.000000001, "OK", 91.5, 12.5)
    with pytest.raises(p.ProtocolError, match="asked for axis 3 sample 8"):
        p.parse_capture_sample(fields, 3, 8)
    assert p.parse_capture_count(p.split_reply(p.format_capture_count(2, 5, 9)), 2) == (5, 9)
    with pytest.raises(p.ProtocolError):
        p.parse_capture_count(p.split_reply(p.format_capture_count(2, 10, 9)), 2)
    assert LEG_JERK_MM_S3 > 0


def test_block_read_gives_the_samples_one_by_one_reads_give_in_fewer_exchanges(rig):
    r, axes, laser = rig
    ax = axes[1]
    ax.enable()
    ax.move_to(-94.0)
    ax.arm_position_compare(-90.0, 1.0, 181)
    laser.arm_capture(1, 181)
    ax.move_to(94.0, velocity_mm_s=10.0)
    tx = laser.transactions
    one_by_one = [laser.capture_sample(1, i) for i in range(181)]
    tx_single, tx = laser.transactions - tx, laser.transactions
    blocks = laser.capture_samples(1, 0, 181)
    tx_block = laser.transactions - tx
    assert blocks == one_by_one
    assert tx_single == 181 and tx_block <= 181 // 4  # about five samples per reply line
    assert laser.capture_samples(1, 179, 2) == one_by_one[179:]
    # a block stops at the first sample taken without beam, naming it, like one by one
    ax.move_to(-94.0)
    ax.arm_position_compare(-90.0, 1.0, 20)
    laser.arm_capture(1, 20)
    ax.move_to(-80.5, velocity_mm_s=10.0)  # 10 pulses: -90 .. -81
    r.laser_server.set_beam_break(1, True)
    ax.move_to(94.0, velocity_mm_s=10.0)
    r.laser_server.set_beam_break(1, False)
    assert laser.capture_count(1) == (20, 20)
    with pytest.raises(BeamBreak, match="capture sample 10"):
        laser.capture_samples(1, 0, 20)


def test_an_instrument_without_block_reads_is_read_one_sample_per_exchange(rig, monkeypatch):
    r, axes, laser = rig
    server = r.laser_server
    plain = type(server)._handle

    def without_capb(self, line):
        if line.upper().startswith(b"CAPB?"):
            return p.format_error(p.ERR_UNKNOWN_COMMAND, "unknown command CAPB?")
        return plain(self, line)

    monkeypatch.setattr(type(server), "_handle", without_capb)
    ax = axes[2]
    ax.enable()
    ax.move_to(-10.0)
    ax.arm_position_compare(0.0, 1.0, 8)
    laser.arm_capture(2, 8)
    ax.move_to(10.0, velocity_mm_s=5.0)
    tx = laser.transactions
    got = laser.capture_samples(2, 0, 8)
    assert laser.transactions - tx == 1 + 8  # the refused CAPB?, then CAP? per sample
    assert got == [laser.capture_sample(2, i) for i in range(8)]
    tx = laser.transactions
    laser.capture_samples(2, 0, 8)
    assert laser.transactions - tx == 8  # not asked again


def test_capture_block_line_protocol():
    samples = [(f"{-90.0 + i:+.9f}", "OK", "91.5", f"{12.5 + i / 10:.6f}") for i in range(20)]
    reply = p.format_capture_block(3, 7, samples)
    assert len(reply) < p.MAX_LINE_BYTES
    got = p.parse_capture_block(p.split_reply(reply), 3, 7, 20)
    assert 4 <= len(got) < 20 and [s.index for s in got] == list(range(7, 7 + len(got)))
    assert got[1].position_mm == pytest.approx(-89.0) and got[1].t_s == pytest.approx(12.6)
    with pytest.raises(p.ProtocolError, match="asked for axis 3 sample 8"):
        p.parse_capture_block(p.split_reply(reply), 3, 8, 20)
    with pytest.raises(p.ProtocolError, match="asked for at most 2"):
        p.parse_capture_block(p.split_reply(reply), 3, 7, 2)


def test_the_active_table_applies_along_an_on_the_fly_pass_as_at_a_stop(rig):
    """A drive applies its table at the position it passes, not only at a move's target: the
    samples of a pass with a table active differ from those without by the table's value at each
    target (its forward column on an upward pass), not by one constant (its value at the pass's end)."""
    from drivers.interfaces import TableBank

    r, axes, laser = rig
    ax = axes[1]
    table = TableBank(-10.0, 10.0, (20.0, 40.0, 60.0), (-10.0, -30.0, -50.0))
    targets = np.arange(-10.0, 10.5, 1.0)
    ax.write_table(1, table)
    ax.activate_table(1)
    ax.enable()

    def pass_errors_um(enabled: bool) -> np.ndarray:
        ax.set_table_enabled(enabled)
        ax.move_to(-14.0)
        ax.arm_position_compare(-10.0, 1.0, targets.size)
        laser.arm_capture(1, targets.size)
        ax.move_to(14.0, velocity_mm_s=5.0)
        assert laser.capture_count(1) == (targets.size, targets.size)
        pos = np.array([s.position_mm for s in laser.capture_samples(1, 0, targets.size)])
        return (pos - targets) * 1000.0

    off = pass_errors_um(False)
    on = pass_errors_um(True)
    predicted_um = np.interp(targets, [-10.0, 0.0, 10.0], table.error_fwd_um)
    # the drive subtracts the predicted error: the measured error falls by it, target by target
    assert np.allclose(off - on, predicted_um, atol=0.5), off - on - predicted_um
