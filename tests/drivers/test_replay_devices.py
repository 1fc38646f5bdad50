"""Replay devices over the real protocols: the station's Modbus and serial clients against the
replay drive server (TCP on 127.0.0.1) and the replay interferometer (pty), answering from a
recording built in the test. Exact values, recorded faults, mismatches, the clock, and the
ServoAxis / Interferometer conformance suites."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from servo_conformance import CHECKS, AxisUnderTest

import interferometer_conformance as conformance
from drivers.errors import BeamBreak, CommTimeout, DriveFault, FramingError
from drivers.interferometer import protocol as p
from drivers.interferometer.client import SerialInterferometer
from drivers.modbus.client import ModbusBus, ModbusServoAxis, connect_axes
from drivers.replay import ReplayClock, ReplayDataError, ReplayMismatch, ReplayRig, ReplayScript
from procedures.io.recording.schema import FAULT_DTYPE, POINT_DTYPE

TARGETS = (-40.0, -12.5, 0.0, 7.25, 33.0)
OVERRUN = 2.0


def make_points(legs=(1, 2), cycles: int = 2, seed: int = 0) -> np.ndarray:
    """A recording in the sweep's order, with values that need all 17 digits: a protocol that
    printed them with fixed decimals would change them."""
    rng = np.random.default_rng(seed)
    rows = []
    index = 0
    t = 0.0
    for leg in legs:
        run = 0
        for _ in range(cycles):
            for direction, seq in ((1, TARGETS), (-1, TARGETS[::-1])):
                run += 1
                for target in seq:
                    t += float(rng.uniform(1.5, 3.0))
                    measured = target + float(rng.normal(0.0, 2e-3))
                    rows.append((
                        index, leg, run, direction, target, target,
                        round(target / 1e-6) * 1e-6,  # drive position as its register reports it
                        measured, (measured - target) * 1000.0, t,
                        20.0 + float(rng.normal(0, 0.01)), 1013.25 + float(rng.normal(0, 0.1)),
                        45.0 + float(rng.normal(0, 0.3)), 20.5 + float(rng.normal(0, 0.05)),
                        int(rng.integers(0, 50000)) * 0.01,  # load as the 0.01 N register reports it
                        np.float32(92.0 + rng.normal(0, 0.3)), 0, np.nan,
                    ))
                    index += 1
    return np.array(rows, dtype=POINT_DTYPE)


def fault_rows(specs) -> np.ndarray:
    """specs: (index, leg, run, target_mm, time_s, kind, attempt, gave_up, message)."""
    return np.array([(i, leg, run, tgt, t, kind.encode(), att, int(gu), msg.encode())
                     for i, leg, run, tgt, t, kind, att, gu, msg in specs], dtype=FAULT_DTYPE)


class Bench:
    """A started replay rig with the station's clients connected to it."""

    def __init__(self, script: ReplayScript, speed=None, legs=(1, 2)):
        self.rig = ReplayRig(script, speed=speed).start()
        self.axes = connect_axes(self.rig.drive_url, legs, timeout_s=1.0)
        self.laser = SerialInterferometer(self.rig.laser_port, timeout_s=0.1, retries=1)
        for axis in self.axes.values():
            axis.enable()

    def goto(self, leg: int, target_mm: float, direction: int):
        """Approach `target_mm` from the `direction` side, as the sweep does."""
        self.axes[leg].move_to(target_mm - direction * OVERRUN)
        return self.axes[leg].move_to(target_mm)

    def close(self) -> None:
        self.laser.close()
        for axis in self.axes.values():
            axis.close()
        self.rig.stop()


@pytest.fixture
def bench():
    made: list[Bench] = []

    def make(script: ReplayScript, **kw) -> Bench:
        b = Bench(script, **kw)
        made.append(b)
        return b

    yield make
    for b in made:
        b.close()
        assert not b.rig.laser_server.failures, b.rig.laser_server.failures


def test_readings_environment_load_and_time_are_the_recorded_values_bit_for_bit(bench):
    pts = make_points()
    b = bench(ReplayScript.from_arrays(pts, source="rec.h5"))
    fixed = 0
    for row in pts:
        st = b.goto(int(row["leg"]), float(row["target_mm"]), int(row["direction"]))
        r = b.laser.read(int(row["leg"]))
        env = b.laser.environment()
        assert r.position_mm == row["measured_mm"], (r.position_mm, row["measured_mm"])
        assert (r.position_mm - row["target_mm"]) * 1000.0 == row["error_um"]
        assert np.float32(r.signal_pct) == row["signal_pct"]
        assert (env.air_temp_c, env.air_pressure_hpa, env.humidity_pct) == (
            row["air_temp_c"], row["air_pressure_hpa"], row["humidity_pct"])
        assert env.material_temp_of(int(row["leg"])) == row["material_temp_c"]
        assert st.load_n == row["load_n"] and st.position_mm == row["drive_position_mm"]
        assert b.rig.clock.now() == row["time_s"], "the clock shows the recorded time of the point"
        # the protocol's own 9-decimal format would not have carried this value
        fixed += float(p.format_position(1, row["measured_mm"], "OK", 90.0, 0.0).split(b",")[2]) != row["measured_mm"]
    assert fixed > len(pts) // 2, "the test values must need more than 9 decimals"
    assert b.rig.served == len(pts) and b.rig.mismatch is None


def test_reading_again_without_moving_gives_the_same_value_and_does_not_advance(bench):
    pts = make_points(legs=(1,), cycles=1)
    b = bench(ReplayScript.from_arrays(pts, source="rec.h5"), legs=(1,))
    b.goto(1, TARGETS[0], 1)
    first = b.laser.read(1)
    again = b.laser.read(1)
    assert again.position_mm == first.position_mm == pts[0]["measured_mm"]
    assert b.rig.served == 1
    b.axes[1].move_to(TARGETS[1])
    assert b.laser.read(1).position_mm == pts[1]["measured_mm"]


def test_recorded_faults_come_back_in_attempt_order_at_their_times(bench):
    pts = make_points(legs=(1,), cycles=1)
    k = 3  # the fourth point of run 1
    tgt = float(pts[k]["target_mm"])
    faults = fault_rows([
        (k, 1, 1, tgt, 101.5, "beam_break", 1, 0, "beam interrupted"),
        (k, 1, 1, tgt, 102.0, "drive_fault", 2, 0, "leg 1: drive fault 0x2310 overcurrent: ... on the move"),
        (k, 1, 1, tgt, 103.0, "timeout", 3, 0, "interferometer did not answer"),
        (k, 1, 1, tgt, 104.0, "framing", 4, 0, "malformed reply"),
        (k, 1, 1, tgt, 105.0, "error", 5, 0, "refused POS? 1"),
    ])
    b = bench(ReplayScript.from_arrays(pts, faults, source="rec.h5"), legs=(1,))
    ax, laser = b.axes[1], b.laser
    for row in pts[:k]:
        b.goto(1, float(row["target_mm"]), 1)
        laser.read(1)
    ax.move_to(tgt)  # contiguous with the previous point, as in the sweep
    with pytest.raises(BeamBreak):
        laser.read(1)
    assert b.rig.clock.now() == 101.5
    with pytest.raises(DriveFault) as info:
        ax.move_to(tgt)  # the sweep re-commands the target after a beam break
    assert info.value.code == 0x2310 and b.rig.clock.now() == 102.0
    ax.reset_fault()
    ax.enable()
    b.goto(1, tgt, 1)
    t0 = time.monotonic()
    with pytest.raises(CommTimeout):
        laser.read(1)
    assert time.monotonic() - t0 < 2.0 and b.rig.clock.now() == 103.0
    b.goto(1, tgt, 1)
    with pytest.raises(FramingError):
        laser.read(1)
    assert b.rig.clock.now() == 104.0
    b.goto(1, tgt, 1)
    with pytest.raises(p.InstrumentError, match="refused POS"):
        laser.read(1)
    b.goto(1, tgt, 1)
    assert laser.read(1).position_mm == pts[k]["measured_mm"]
    assert b.rig.clock.now() == pts[k]["time_s"]
    assert b.rig.mismatch is None


@pytest.mark.parametrize("case", ["target", "leg", "order", "exhausted", "not_moved"])
def test_a_request_the_recording_does_not_hold_names_the_first_mismatch(bench, case):
    pts = make_points(legs=(1,), cycles=1)
    b = bench(ReplayScript.from_arrays(pts, source="rec.h5"), legs=(1, 2))
    if case == "target":
        b.goto(1, TARGETS[0], 1)
        b.laser.read(1)
        b.goto(1, 12.5, 1)
        want = ["leg 1 run 1 target 12.5000 mm (direction +1) was not recorded in rec.h5",
                "targets -40.0000, -12.5000, 0.0000, 7.2500, 33.0000 mm for leg 1"]
        axis = 1
    elif case == "leg":
        b.goto(2, TARGETS[0], 1)
        want = ["leg 2 was not recorded in rec.h5 (the recording has legs 1)"]
        axis = 2
    elif case == "order":
        b.goto(1, TARGETS[2], 1)
        want = ["leg 1 run 1 target 0.0000 mm (direction +1) is not the next point rec.h5 holds for leg 1",
                "leg 1 run 1 target -40.0000 mm (direction +1, point index 0)"]
        axis = 1
    elif case == "exhausted":
        for row in pts:
            b.goto(1, float(row["target_mm"]), int(row["direction"]))
            b.laser.read(1)
        b.goto(1, TARGETS[0], 1)
        want = [f"was asked after all {len(pts)} recorded points of leg 1 in rec.h5 were replayed"]
        axis = 1
    else:
        want = ["leg 1 was read before its drive moved to a recorded point of rec.h5"]
        axis = 1
    with pytest.raises(p.InstrumentError, match="replay: "):
        b.laser.read(axis)
    assert isinstance(b.rig.mismatch, ReplayMismatch)
    for text in want:
        assert text in str(b.rig.mismatch), str(b.rig.mismatch)


def test_a_cut_short_recording_ends_where_it_stops_and_calls_on_end(bench):
    pts = make_points(legs=(1,), cycles=1)[:4]
    b = bench(ReplayScript.from_arrays(pts, source="cut.h5", outcome="aborted"), legs=(1,))
    ended: list[str] = []
    b.rig.on_end = ended.append
    for row in pts:
        b.goto(1, float(row["target_mm"]), 1)
        b.laser.read(1)
    b.axes[1].move_to(TARGETS[4])
    with pytest.raises(p.InstrumentError):
        b.laser.read(1)
    assert ended and "cut.h5 ends here (its outcome was aborted; 4 points replayed)" in ended[0]
    assert b.rig.mismatch is None and b.rig.ended == ended[0]


# -- the recording as data ----------------------------------------------------------------------

def test_unknown_values_and_fault_kinds_are_refused_naming_point_and_field():
    pts = make_points(legs=(1,), cycles=1)
    pts["load_n"][3] = np.nan
    with pytest.raises(ReplayDataError, match=r"rec.h5: point index 3 \(leg 1 run 1 target 7.2500 mm\) has no recorded load_n"):
        ReplayScript.from_arrays(pts, source="rec.h5")
    pts = make_points(legs=(1,), cycles=1)
    pts["material_temp_c"][:] = np.nan  # no material sensor: reported as NAN, allowed
    assert ReplayScript.from_arrays(pts).value_points == len(pts)
    bad = fault_rows([(2, 1, 1, 0.0, 1.0, "aborted", 1, 0, "")])
    with pytest.raises(ReplayDataError, match="fault row 0 .* kind 'aborted'"):
        ReplayScript.from_arrays(pts, bad, source="rec.h5")


def test_an_unknown_signal_level_is_allowed_only_for_a_reading_taken_on_the_move():
    """A streamed on-the-fly pass (the µLine-F1) records no signal level at its targets; a point
    read at rest must have one (the protocol carries it, the replay sends it)."""
    pts = make_points(legs=(1,), cycles=1)
    pts["signal_pct"][3] = np.nan
    with pytest.raises(ReplayDataError, match=r"point index 3 .* has no recorded signal_pct"):
        ReplayScript.from_arrays(pts, source="rec.h5")
    pts["speed_mm_s"][3] = 10.0  # read on the move
    script = ReplayScript.from_arrays(pts, source="rec.h5")
    assert np.isnan(script.legs[1][3].signal_pct) and script.value_points == len(pts)


def test_a_point_resumed_after_giving_up_keeps_the_episode_of_the_run_that_measured_it():
    pts = make_points(legs=(1,), cycles=1)
    tgt = float(pts[2]["target_mm"])
    faults = fault_rows([(2, 1, 1, tgt, 5.0 + a, "beam_break", a, a == 2, "") for a in (1, 2)]
                        + [(2, 1, 1, tgt, 9.0, "beam_break", 1, 0, "")])
    script = ReplayScript.from_arrays(pts, faults)
    assert [(f.attempt, f.time_s) for f in script.legs[1][2].faults] == [(1, 9.0)]
    # the point never measured (session ended failed there): the give-up episode is replayed
    cut = ReplayScript.from_arrays(pts[:2], faults[:2], outcome="failed", directions={2: 1})
    last = cut.legs[1][-1]
    assert not last.has_value and last.direction == 1 and [f.attempt for f in last.faults] == [1, 2]


# -- the clock ------------------------------------------------------------------------------------

def test_clock_speed_max_never_waits_and_speed_n_paces_recorded_time():
    fast = ReplayClock(None)
    fast.sleep(1.0)
    fast.set_recorded(3600.0)
    t0 = time.monotonic()
    fast.sleep(1.0)
    assert time.monotonic() - t0 < 0.05 and fast.now() == 3601.0

    paced = ReplayClock(speed=20.0)
    paced.sleep(0.0)  # anchor
    t0 = time.monotonic()
    paced.set_recorded(2.0)  # 2 recorded seconds = 0.1 s at 20x
    paced.sleep(0.0)
    elapsed = time.monotonic() - t0
    assert 0.09 <= elapsed < 0.5, elapsed
    paced.set_recorded(1.0)  # time going back (a resumed session) re-anchors: no wait
    t0 = time.monotonic()
    paced.sleep(0.0)
    assert time.monotonic() - t0 < 0.05
    with pytest.raises(ValueError, match="positive"):
        ReplayClock(0)


def test_clock_after_a_pause_keeps_its_speed_instead_of_catching_up():
    clock = ReplayClock(speed=10.0)
    clock.sleep(0.0)
    threading.Event().wait(0.6)  # the run is paused: 0.6 s of wall time pass without the clock
    clock.sleep(0.0)  # late: re-anchors here
    t0 = time.monotonic()
    clock.set_recorded(1.0)  # 1 recorded second = 0.1 s at 10x, counted from the resume
    clock.sleep(0.0)
    assert time.monotonic() - t0 >= 0.09


def test_clock_wait_ends_when_cancelled():
    clock = ReplayClock(speed=1.0)
    clock.sleep(0.0)
    clock.set_recorded(3600.0)
    done = threading.Event()
    worker = threading.Thread(target=lambda: (clock.sleep(0.0), done.set()), daemon=True)
    worker.start()
    clock.cancel_waits()
    assert done.wait(2.0), "a cancelled replay must not keep waiting"


# -- conformance --------------------------------------------------------------------------------

LEG = 2


@pytest.fixture
def make_axis():
    rigs: list[ReplayRig] = []
    buses: list[ModbusBus] = []
    script = ReplayScript.from_arrays(make_points(), source="rec.h5")

    def make() -> AxisUnderTest:
        rig = ReplayRig(script).start()
        rigs.append(rig)
        bus = ModbusBus.from_url(rig.drive_url, timeout_s=1.0)
        buses.append(bus)
        return AxisUnderTest(axis=ModbusServoAxis(bus, LEG, rig.profile),
                             inject_fault=lambda code: rig.drive_server.inject_fault(LEG, code))

    yield make
    for bus in buses:
        bus.close()
    for rig in rigs:
        rig.stop()


@pytest.mark.parametrize("check", CHECKS, ids=[c.__name__.removeprefix("check_") for c in CHECKS])
def test_replay_drive_servo_conformance(check, make_axis):
    check(make_axis)


@pytest.fixture(scope="module")
def replay_laser_port():
    """A replay instrument with each leg's drive standing at its first recorded point."""
    legs = (1, 2, 3, 4, 5, 6)
    pts = make_points(legs=legs, cycles=1)
    with ReplayRig(ReplayScript.from_arrays(pts, source="rec.h5")) as rig:
        axes = connect_axes(rig.drive_url, legs)
        for leg, axis in axes.items():
            axis.enable()
            axis.move_to(TARGETS[0] - OVERRUN)
            axis.move_to(TARGETS[0])
        yield rig.laser_port
        for axis in axes.values():
            axis.close()
        assert not rig.laser_server.failures, rig.laser_server.failures
        assert rig.mismatch is None, rig.mismatch


# check_zero does not apply: a replay reports the recorded readings, relative to the zero of
# the recorded session, wherever `zero()` is called (docs/replay.md)
REPLAY_CHECKS = [c for c in conformance.ALL_CHECKS if c is not conformance.check_zero]


@pytest.mark.parametrize("check", REPLAY_CHECKS, ids=lambda c: c.__name__)
def test_replay_interferometer_conformance(check, replay_laser_port):
    check(lambda: SerialInterferometer(replay_laser_port, timeout_s=0.5, retries=1), axes=(1, 2, 3, 4, 5, 6))


def test_identity_names_the_replayed_recording(bench):
    script = ReplayScript.from_arrays(make_points(legs=(1,), cycles=1), source="rec.h5", sha256="ab12cd34" * 8,
                                      session_id="5e55101d")
    b = bench(script, legs=(1,))
    assert b.axes[1].identity().startswith("StationReplay ") and "s/n Rab12cd34-0001" in b.axes[1].identity()
    assert b.laser.identity() == "StationReplay,LI-6,Rab12cd34,5e55101d"
