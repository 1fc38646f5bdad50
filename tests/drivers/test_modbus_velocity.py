"""`ServoAxis.move_to(..., velocity_mm_s=...)` on the Modbus client against the simulated drive
(real sockets): the speed of that move only, limited to the drive's maximum, the drive's own
profile velocity written back after it, nothing written for a refused target."""

from __future__ import annotations

import pytest

from drivers.errors import DriveFault, SoftLimitError


def profile_velocity(sd, ax) -> float:
    r = sd.profile.registers["profile_velocity"]
    return r.decode(ax.bus.read(ax.unit, r.address, r.words))


def test_a_move_at_a_velocity_takes_that_speed_and_leaves_the_profile_as_it_was(sim_drives):
    sd = sim_drives()
    ax = sd.axis(2)
    ax.enable()
    ax.move_to(0.0)
    lim = sd.profile.limits  # profile 10 mm/s, 100 mm/s2; max 20 mm/s
    a = lim.profile_accel_mm_s2
    t0 = sd.clock.now()
    st = ax.move_to(30.0, velocity_mm_s=2.0)
    assert st.position_mm == pytest.approx(30.0, abs=1e-6)
    assert sd.clock.now() - t0 == pytest.approx(2.0 / a + 30.0 / 2.0, rel=1e-9)
    assert profile_velocity(sd, ax) == pytest.approx(lim.profile_velocity_mm_s)
    # the next move without a velocity (a sweep's) runs at the drive's profile velocity again
    t0 = sd.clock.now()
    ax.move_to(0.0)
    v = lim.profile_velocity_mm_s
    assert sd.clock.now() - t0 == pytest.approx(v / a + 30.0 / v, rel=1e-9)
    # a velocity above the drive's maximum is limited to the maximum
    t0 = sd.clock.now()
    ax.move_to(40.0, velocity_mm_s=10 * lim.max_velocity_mm_s)
    vmax = lim.max_velocity_mm_s
    assert sd.clock.now() - t0 == pytest.approx(vmax / a + 40.0 / vmax, rel=1e-9)
    assert profile_velocity(sd, ax) == pytest.approx(lim.profile_velocity_mm_s)


def test_a_refused_target_or_speed_writes_nothing(sim_drives):
    sd = sim_drives()
    ax = sd.axis(5)
    ax.enable()
    ax.move_to(10.0)
    counts = sd.server.request_counts(5)
    with pytest.raises(SoftLimitError) as info:
        ax.move_to(95.5, velocity_mm_s=1.0)
    assert "-95.000 .. 95.000 mm" in str(info.value)
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="nothing moved"):
            ax.move_to(20.0, velocity_mm_s=bad)
    assert sd.server.request_counts(5) == counts, "the drive must not have seen any request"
    assert sd.plants[5].x_mm == 10.0


def test_the_profile_is_written_back_when_the_move_fails(sim_drives):
    sd = sim_drives()
    ax = sd.axis(4)
    ax.enable()
    ax.move_to(0.0)
    sd.server.inject_fault(4, "overcurrent")
    with pytest.raises(DriveFault):
        ax.move_to(5.0, velocity_mm_s=1.0)
    assert profile_velocity(sd, ax) == pytest.approx(sd.profile.limits.profile_velocity_mm_s)


def test_the_default_timeout_of_a_slow_move_follows_its_speed(sim_drives):
    """At 0.5 mm/s, 20 mm take 40 s: far beyond twice the time at the profile's 10 mm/s (about
    4 s), so the timeout must be reckoned at the move's own speed."""
    from drivers.clock import VirtualClock

    sd = sim_drives(time_scale=0.002)  # 1 virtual s = 2 ms
    ax = sd.axis(1, clock=sd.clock, poll_interval_s=0.05)
    assert isinstance(sd.clock, VirtualClock)
    ax.enable()
    ax.move_to(0.0)
    t0 = sd.clock.now()
    st = ax.move_to(20.0, velocity_mm_s=0.5)
    assert st.position_mm == pytest.approx(20.0, abs=1e-6)
    assert sd.clock.now() - t0 >= 40.0
    assert profile_velocity(sd, ax) == pytest.approx(sd.profile.limits.profile_velocity_mm_s)
