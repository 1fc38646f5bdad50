"""The simulated Modbus drive and the station client over real sockets/ptys: CiA 402 state
machine, moves on the virtual clock, soft limits, faults, timeouts."""

from __future__ import annotations

import logging
import time
from dataclasses import replace

import pytest

from drivers.errors import CommTimeout, DriveFault, SoftLimitError
from drivers.modbus.client import BusConfigError, ModbusBus, RequestRefused, connect_axes
from drivers.plant.leg import PlantConfig


def _raw_cw(sd, bus, leg: int, cw: int) -> int:
    """Write a controlword, return the statusword read back."""
    p = sd.profile
    bus.write(leg, p.address("controlword"), [cw])
    return bus.read(leg, p.address("statusword"), 1)[0]


def test_state_machine_follows_cia402(sim_drives):
    sd = sim_drives()
    bus = sd.bus()
    sw = bus.read(2, sd.profile.address("statusword"), 1)[0]
    assert sw & 0x4F == 0x40  # switch on disabled
    # (command, expected statusword under the CiA 402 mask, mask)
    steps = [
        (0x07, 0x40, 0x4F),  # switch on from switch-on-disabled is not a transition
        (0x06, 0x21, 0x6F),  # shutdown -> ready to switch on
        (0x07, 0x23, 0x6F),  # switch on -> switched on
        (0x0F, 0x27, 0x6F),  # enable operation -> operation enabled
        (0x02, 0x07, 0x6F),  # quick stop -> quick stop active
        (0x0F, 0x27, 0x6F),  # enable operation from quick stop active
        (0x07, 0x23, 0x6F),  # disable operation -> switched on
        (0x00, 0x40, 0x4F),  # disable voltage -> switch on disabled
    ]
    for cw, want, mask in steps:
        sw = _raw_cw(sd, bus, 2, cw)
        assert sw & mask == want, f"after controlword 0x{cw:02X}: statusword 0x{sw:04X}"
    assert sd.server.state(2) == "switch_on_disabled"
    # voltage enabled (bit 4) only while the power stage is on
    assert _raw_cw(sd, bus, 2, 0x06) & 0x10
    assert not _raw_cw(sd, bus, 2, 0x00) & 0x10


def test_one_write_per_move_and_one_transaction(sim_drives):
    sd = sim_drives()
    ax = sd.axis(1)
    ax.enable()
    ax.move_to(0.0)
    reads0, writes0 = sd.server.request_counts(1)
    tx0 = ax.bus.transactions
    for t in (1.0, 2.5, -3.0, 7.125):
        st = ax.move_to(t)
        assert st.position_mm == pytest.approx(t, abs=1e-6)
        assert sd.plants[1].x_mm == pytest.approx(t, abs=1e-6)
    reads, writes = sd.server.request_counts(1)
    assert writes - writes0 == 4 and reads - reads0 == 4
    # the default drive serves function 23: the move's write and its status read in one
    # transaction (tests/drivers/test_modbus_read_write.py: two without it)
    assert ax.bus.transactions - tx0 == 4
    sw = ax.bus.read(1, sd.profile.address("statusword"), 1)[0]
    assert sw >> 12 & 1, "set-point acknowledge after a latched set-point"


def test_move_takes_trapezoid_time_on_virtual_clock(sim_drives):
    sd = sim_drives()
    ax = sd.axis(2)
    ax.enable()
    ax.move_to(0.0)
    lim = sd.profile.limits  # profile 10 mm/s, 100 mm/s2: 50 mm takes 0.1 + 5.0 s
    t0 = sd.clock.now()
    ax.move_to(50.0)
    v, a = lim.profile_velocity_mm_s, lim.profile_accel_mm_s2
    assert sd.clock.now() - t0 == pytest.approx(v / a + 50.0 / v, rel=1e-9)
    # a profile velocity above the drive's maximum is limited to the maximum
    r = sd.profile.registers["profile_velocity"]
    ax.bus.write(2, r.address, r.encode(3 * lim.max_velocity_mm_s))
    t0 = sd.clock.now()
    ax.move_to(0.0)
    vmax = lim.max_velocity_mm_s
    assert sd.clock.now() - t0 == pytest.approx(vmax / a + 50.0 / vmax, rel=1e-9)


def test_motion_follows_clock_at_positive_time_scale(sim_drives):
    sd = sim_drives(time_scale=0.01)  # 1 virtual s = 10 ms
    ax = sd.axis(3, poll_interval_s=0.001)
    ax.enable()
    p = sd.profile
    words = [p.commands["enable_operation"] | 0x10] + p.registers["target_position"].encode(40.0)
    ax.bus.write(3, p.address("controlword"), words)
    st = ax.status()
    assert st.moving and not st.target_reached
    assert 0.0 <= st.position_mm < 40.0
    assert st.following_error_um > 0.0, "a moving servo lags its demand"
    # the drive keeps the plant current on its own (the interferometer reads the plant)
    deadline = time.monotonic() + 5.0
    while True:
        with sd.lock:
            x = sd.plants[3].x_mm
        if x == pytest.approx(40.0, abs=1e-9) or time.monotonic() > deadline:
            break
        time.sleep(0.005)
    assert x == pytest.approx(40.0, abs=1e-9)
    st = ax.move_to(-10.0)
    assert st.target_reached and st.position_mm == pytest.approx(-10.0, abs=1e-6)
    assert st.following_error_um == 0.0
    assert sd.plants[3].direction == -1


def test_client_refuses_target_beyond_soft_limits_before_any_request(sim_drives):
    sd = sim_drives()
    ax = sd.axis(5)
    ax.enable()
    ax.move_to(10.0)
    counts = sd.server.request_counts(5)
    tx = ax.bus.transactions
    with pytest.raises(SoftLimitError) as info:
        ax.move_to(95.001)
    assert "95.0010 mm" in str(info.value) and "-95.000 .. 95.000 mm" in str(info.value)
    assert sd.server.request_counts(5) == counts, "the drive must not have seen any request"
    assert ax.bus.transactions == tx
    assert sd.plants[5].x_mm == 10.0


def test_drive_refuses_target_beyond_soft_limits_with_fault(sim_drives):
    sd = sim_drives()
    ax = sd.axis(6)
    ax.enable()
    ax.move_to(20.0)
    p = sd.profile
    # a client that does not check (e.g. a hand-written mbpoll command) gets a fault, no motion
    words = [p.commands["enable_operation"] | 0x10] + p.registers["target_position"].encode(-96.0)
    ax.bus.write(6, p.address("controlword"), words)
    st = ax.status()
    assert st.fault and st.fault_code == p.fault_by_name("soft_limit").code
    sw = ax.bus.read(6, p.address("statusword"), 1)[0]
    assert sw >> 11 & 1, "internal limit active"
    assert sd.plants[6].x_mm == 20.0 and st.position_mm == pytest.approx(20.0, abs=1e-6)
    with pytest.raises(DriveFault) as info:
        ax.move_to(0.0)
    assert info.value.code == 0x8612 and "soft_limit" in str(info.value)
    ax.reset_fault()
    ax.enable()
    assert ax.move_to(0.0).position_mm == pytest.approx(0.0, abs=1e-6)


def test_fault_message_names_the_code(sim_drives):
    sd = sim_drives()
    ax = sd.axis(1)
    ax.enable()
    sd.server.inject_fault(1, "overtemperature")
    with pytest.raises(DriveFault) as info:
        ax.move_to(1.0)
    assert info.value.code == 0x4310
    assert "0x4310 overtemperature" in str(info.value)


def test_unresponsive_drive_times_out_within_the_configured_timeout(sim_drives):
    sd = sim_drives()
    ax = sd.axis(3, bus=sd.bus(timeout_s=1.0, retries=1))
    ax.enable()
    sd.server.set_unresponsive(3, True)
    t0 = time.monotonic()
    with pytest.raises(CommTimeout) as info:
        ax.status()
    elapsed = time.monotonic() - t0
    # one timeout, not one per attempt (2 s); the margin is for a loaded CI worker
    assert 0.95 <= elapsed <= 1.0 + 0.75, elapsed
    text = str(info.value)
    assert sd.url in text and "unit id 3" in text and "1 s" in text
    sd.server.set_unresponsive(3, False)
    assert ax.status().enabled, "the bus recovers once the drive answers again"


def test_closed_port_gives_clear_error_quickly(closed_port, profile):
    url = f"tcp://127.0.0.1:{closed_port}"
    t0 = time.monotonic()
    with pytest.raises(CommTimeout) as info:
        connect_axes(url, [1, 2], profile, timeout_s=0.5)
    assert time.monotonic() - t0 <= 0.5 + 0.25
    text = str(info.value)
    assert url in text and "cannot connect" in text and "unit id 1" in text


def test_absent_unit_id_times_out(sim_drives):
    sd = sim_drives(legs=2)
    t0 = time.monotonic()
    with pytest.raises(CommTimeout) as info:
        connect_axes(sd.url, [1, 2, 3], sd.profile, timeout_s=1.0)
    assert time.monotonic() - t0 <= 1.0 + 0.75  # one timeout (not two); the margin is for a loaded CI worker
    assert "unit id 3" in str(info.value)


def test_stop_on_a_dead_link_logs_and_never_raises(sim_drives, caplog):
    sd = sim_drives()
    ax = sd.axis(2, bus=sd.bus(timeout_s=0.2))
    ax.enable()
    sd.server.stop()
    with caplog.at_level(logging.WARNING, logger="drivers.modbus.client"):
        ax.stop()
    assert any("quick stop not delivered" in r.getMessage() for r in caplog.records)
    with pytest.raises(CommTimeout):
        ax.status()


def test_axial_load_register_follows_the_plant(sim_drives):
    cfg = replace(PlantConfig(), load_per_pass_n=(0.0, 450.0))
    sd = sim_drives(configs=[cfg] * 6)
    ax = sd.axis(4)
    ax.enable()
    ax.move_to(10.0)
    assert ax.status().load_n == 0.0
    ax.move_to(-10.0)  # reversal: the plant starts a new pass with the next load
    assert sd.plants[4].load_n == 450.0
    assert ax.status().load_n == pytest.approx(450.0, abs=0.01)


def test_rtu_and_tcp_serve_the_same_drives(sim_drives):
    sd = sim_drives()
    rtu_path = sd.server.start_rtu()
    rtu_axis = sd.axis(2, bus=sd.bus(url=f"rtu://{rtu_path}?baud=115200"))
    tcp_axis = sd.axis(2)
    rtu_axis.enable()
    st = rtu_axis.move_to(-33.3)
    assert st.target_reached
    assert tcp_axis.status().position_mm == pytest.approx(-33.3, abs=1e-6)
    assert "SIM-0002" in rtu_axis.identity()


def test_refused_request_reports_the_modbus_exception(sim_drives):
    sd = sim_drives()
    bus = sd.bus()
    with pytest.raises(RequestRefused) as info:
        bus.write(1, sd.profile.address("statusword"), [0])  # read-only
    assert info.value.exception_code == 2 and "illegal data address" in str(info.value)
    with pytest.raises(RequestRefused):
        bus.read(1, 30, 5)  # a gap in the map


@pytest.mark.parametrize(
    "url, words",
    [("http://127.0.0.1:5020", "unknown scheme"), ("tcp://127.0.0.1:notaport", "port"),
     ("rtu://", "no serial port"), ("rtu:///dev/ttyS0?baud=fast", "baud")],
)
def test_bad_drive_url_is_explained(url, words):
    with pytest.raises(BusConfigError) as info:
        ModbusBus.from_url(url)
    assert words in str(info.value) and "tcp://HOST:PORT" in str(info.value)


def test_sim_serves_loopback_only(sim_drives):
    sd = sim_drives()
    with pytest.raises(ValueError, match="loopback"):
        sd.server.start_tcp("0.0.0.0", 0)
