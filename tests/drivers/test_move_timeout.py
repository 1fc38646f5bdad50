"""The move timeout of the Modbus client, judged on the clock the drive's motion runs on.

On the simulated rig at time scale 0.02 one real millisecond is 50 ms of the rig's clock, so a
station that looks at a reply late (a busy process, a UI drawing) must not count that delay as
motion time; a drive that really does not arrive (a stall) must still time out. Real sockets,
the simulated drive (issue 17: false `timeout` faults on the UI's simulated rig).
"""

from __future__ import annotations

import time

import pytest

from drivers.errors import CommTimeout
from drivers.modbus.client import MOVE_TIMEOUT_FACTOR, MOVE_TIMEOUT_MARGIN_S
from drivers.states import DriveState

SCALE = 0.02  # the UI's default time scale: 1 virtual s = 20 ms
LATE_S = 0.3  # real seconds the station is "busy" = 15 s on the rig's clock, far beyond any timeout here


def trapezoid_s(sd, distance_mm: float) -> float:
    lim = sd.profile.limits
    v, a = lim.profile_velocity_mm_s, lim.profile_accel_mm_s2
    return 2 * (distance_mm / a) ** 0.5 if distance_mm <= v * v / a else v / a + distance_mm / v


def test_a_reply_looked_at_late_is_not_a_timeout(sim_drives):
    """The station reads "not reached", then is kept off the CPU for 15 s of rig time before it
    looks at the clock: the drive arrived meanwhile, so the next status says so."""
    sd = sim_drives(time_scale=SCALE)
    ax = sd.axis(1, clock=sd.clock)
    ax.enable()
    ax.move_to(0.0)
    status = ax.status
    late = []

    def status_then_busy():
        st = status()
        if not st.target_reached and not late:
            late.append(st.position_mm)
            time.sleep(LATE_S)  # e.g. the UI thread holding the GIL while it draws
        return st

    ax.status = status_then_busy
    timeout_s = MOVE_TIMEOUT_FACTOR * trapezoid_s(sd, 10.0) + MOVE_TIMEOUT_MARGIN_S
    t0 = sd.clock.now()
    st = ax.move_to(10.0)
    assert late, "the move must have been seen under way once"
    assert sd.clock.now() - t0 > timeout_s, "the station's own delay exceeded the timeout on the rig's clock"
    assert st.target_reached and st.position_mm == pytest.approx(10.0, abs=1e-6)


def test_a_move_command_sent_late_is_not_a_timeout(sim_drives):
    """The move command leaves 15 s of rig time after move_to began (the process was busy): the
    timeout counts from the drive's acknowledgement, not from before the request was sent."""
    sd = sim_drives(time_scale=SCALE)
    ax = sd.axis(2, clock=sd.clock)
    ax.enable()
    ax.move_to(0.0)
    move_address = sd.profile.blocks["move_command"].start

    def before_request(kind, unit, address, count):
        if kind == "write" and address == move_address:
            time.sleep(LATE_S)

    ax.bus.on_request = before_request
    try:
        st = ax.move_to(-10.0)
    finally:
        ax.bus.on_request = None
    assert st.target_reached and st.position_mm == pytest.approx(-10.0, abs=1e-6)


@pytest.mark.parametrize("scale", [SCALE, 0.0])
def test_a_stalled_drive_times_out_on_the_rigs_clock_and_is_quick_stopped(sim_drives, scale):
    """A real non-arrival: the axis is stalled, the drive stays enabled and never reports the
    target reached. The move times out after its timeout on the rig's clock, the drive is
    quick-stopped, and once freed the axis moves again."""
    sd = sim_drives(time_scale=scale)
    ax = sd.axis(3, clock=sd.clock)
    ax.enable()
    ax.move_to(0.0)
    sd.server.set_stalled(3)
    timeout_s = MOVE_TIMEOUT_FACTOR * trapezoid_s(sd, 10.0) + MOVE_TIMEOUT_MARGIN_S
    t0, r0 = sd.clock.now(), time.monotonic()
    with pytest.raises(CommTimeout, match=r"leg 3: the drive did not reach 10\.0000 mm within .* \(at 0\.0000 mm\); it was quick-stopped"):
        ax.move_to(10.0)
    elapsed = sd.clock.now() - t0
    assert timeout_s < elapsed < timeout_s + 1.0 + (2.0 / scale if scale else 0.0)
    if scale:
        assert time.monotonic() - r0 < 5.0, "the timeout is on the rig's clock, not wall seconds"
    st = ax.status()
    assert st.state is DriveState.QUICK_STOP_ACTIVE and not st.fault
    assert sd.plants[3].x_mm == pytest.approx(0.0, abs=1e-9), "a stalled nut does not move"
    sd.server.set_stalled(3, False)
    ax.enable()
    st = ax.move_to(10.0)
    assert st.target_reached and st.position_mm == pytest.approx(10.0, abs=1e-6)


def test_a_stall_freed_during_a_move_lets_it_arrive(sim_drives):
    # the rig's clock in real seconds, moved on by jumps (advance): on the UI's scale (0.02) a
    # loaded machine's 10 ms sleep could outlast the whole 2 s (40 ms) move, which then arrived
    # before the stall; here the stall comes 0.5 s into it unless the machine stalls 1.5 s
    sd = sim_drives(time_scale=1.0)
    ax = sd.axis(4, clock=sd.clock)
    ax.enable()
    ax.move_to(0.0)
    p = sd.profile
    words = [p.commands["enable_operation"] | 0x10] + p.registers["target_position"].encode(20.0)
    ax.bus.write(4, p.address("controlword"), words)
    sd.clock.advance(0.5)  # half a second of rig time: under way
    sd.server.set_stalled(4)
    stalled_at = ax.status().position_mm
    assert 0.0 < stalled_at < 20.0
    sd.clock.advance(2.0)  # two seconds of rig time: long enough to have arrived, were it free
    st = ax.status()
    assert not st.target_reached and st.position_mm == pytest.approx(stalled_at, abs=1e-9)
    assert st.following_error_um == 0.0
    sd.server.set_stalled(4, False)
    st = ax.move_to(20.0)
    assert st.target_reached and st.position_mm == pytest.approx(20.0, abs=1e-6)
