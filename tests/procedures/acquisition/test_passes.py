"""procedures.acquisition.passes: the fault handling and the point record both passes (stop-and-go and on
the fly) share. End-to-end retries on the real simulated rig: tests/station/test_sweep_integration.py
and the committed fault sample (tests/station/test_replay.py)."""

from __future__ import annotations

import pytest

from drivers.interfaces import BeamBreak, CommTimeout, DriveFault, DriveLimits, Environment, Reading
from procedures.engine import events as ev
from procedures.engine.control import Aborted, RunControl
from drivers.errors import CountLost
from procedures.acquisition.passes import (
    LaserRecovery,
    RetryPolicy,
    SweepFailed,
    check_reference_limits,
    point_record,
    retry_after,
)
from procedures.acquisition.plans import PlanPoint, SweepPlan, onthefly_plan
from procedures.acquisition.sweep import sweep
from procedures.vocabulary import PlanError
from procedures.io.recording.schema import FLAG_REREFERENCED, FLAG_RETRIED_BEAM, FLAG_RETRIED_DRIVE
from procedures.io.recording.writer import point_row
from drivers.interfaces import FaultKind

P = PlanPoint(index=7, leg=2, run=3, direction=-1, target_mm=12.5)


class Clock:
    def __init__(self):
        self.t, self.slept = 100.0, []

    def now(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.slept.append(s)
        self.t += s


class Axis:
    """Records the recovery calls retry_after makes (the real drive's are tested with the sim)."""

    def __init__(self):
        self.calls = []

    def status(self):
        self.calls.append("status")
        return type("St", (), {"fault": True, "enabled": False})()

    def reset_fault(self):
        self.calls.append("reset_fault")

    def enable(self):
        self.calls.append("enable")

    def move_to(self, target_mm, velocity_mm_s=None):
        self.calls.append(("move_to", target_mm))


class Laser:
    """A laser whose calls LaserRecovery makes are recorded; `latching`: it has the small-signal
    latch to clear (drivers.interfaces.LatchingInterferometer), as the µLine-F1."""

    def __init__(self, calls: list):
        self.calls = calls

    def zero(self, axis):
        self.calls.append(("zero", axis))


class LatchingLaser(Laser):
    def clear_signal_latch(self, axis):
        self.calls.append(("clear_signal_latch", axis))


PLAN = onthefly_plan((2,), cycles=2, step_mm=5.0, min_mm=-20.0, max_mm=20.0, dwell_s=0.2, averaging_s=0.2)


def run(gen):
    """Drive a retry_after generator: (events yielded, value returned)."""
    events = []
    try:
        while True:
            events.append(next(gen))
    except StopIteration as stop:
        return events, stop.value


def test_a_beam_break_waits_and_re_reads_without_moving():
    clock, axis = Clock(), Axis()
    exc = BeamBreak("beam interrupted")
    events, flag = run(retry_after(exc, 1, RetryPolicy(beam_wait_s=0.7), RunControl(),
                                   clock, axis, P, t_start=90.0, what="pass: "))
    assert flag == FLAG_RETRIED_BEAM and clock.slept == [0.7] and axis.calls == []
    (fault,) = events
    assert fault == ev.Fault(7, 2, 3, 12.5, FaultKind.BEAM_BREAK, f"pass: {exc}", 1, False, 10.0)


def test_a_drive_fault_recovers_the_axis():
    clock, axis = Clock(), Axis()
    events, flag = run(retry_after(DriveFault("following error"), 2, RetryPolicy(drive_retries=2), RunControl(),
                                   clock, axis, P, t_start=0.0))
    assert flag == FLAG_RETRIED_DRIVE and clock.slept == []
    assert axis.calls == ["status", "reset_fault", "status", "enable"]
    assert events[0].kind == FaultKind.DRIVE_FAULT and not events[0].gave_up


def test_retries_spent_give_up_with_the_fault_yielded_first():
    gen = retry_after(CommTimeout("no answer"), 3, RetryPolicy(comm_retries=2), RunControl(), Clock(), Axis(), P, 0.0)
    fault = next(gen)
    assert fault.gave_up and fault.kind == FaultKind.TIMEOUT and fault.attempt == 3
    with pytest.raises(SweepFailed) as info:
        next(gen)
    assert info.value.fault is fault and "leg 2, run 3, target 12.5000 mm: no answer" in str(info.value)


def test_an_abort_wins_over_a_retry():
    control = RunControl()
    control.abort("operator")
    with pytest.raises(Aborted):
        next(retry_after(BeamBreak("x"), 1, RetryPolicy(), control, Clock(), Axis(), P, 0.0))


def test_the_point_record_is_a_valid_session_row():
    env = Environment(20.5, 1012.0, 45.0, (20.0, 21.25))
    reading = Reading(axis=2, position_mm=12.5021, beam_ok=True, signal_pct=88.0, t_s=5.0)
    rec = point_record(P, reading, env, drive_position_mm=12.5001, time_s=5.0, material_temp_c=21.25,
                       load_n=3.0, flags=FLAG_RETRIED_BEAM, speed_mm_s=-4.0)
    row = point_row(rec)[0]
    assert rec["error_um"] == pytest.approx(2.1)
    assert (row["index"], row["leg"], row["run"], row["direction"]) == (7, 2, 3, -1)
    assert row["commanded_mm"] == 12.5 and row["material_temp_c"] == 21.25 and row["speed_mm_s"] == -4.0
    assert row["flags"] == FLAG_RETRIED_BEAM and row["signal_pct"] == 88.0 and row["air_pressure_hpa"] == 1012.0


def test_a_lost_count_re_references_the_leg_before_the_next_attempt_once():
    clock, axis = Clock(), Axis()
    laser = LatchingLaser(axis.calls)
    recovery = LaserRecovery()
    assert recovery.before_attempt(PLAN, axis, laser, 2, clock, RunControl()) == 0 and axis.calls == []
    recovery.note(CountLost("velocity overflow"))
    recovery.note(BeamBreak("small signal"))  # a lost count outranks it: zeroing clears both latches
    assert recovery.before_attempt(PLAN, axis, laser, 2, clock, RunControl()) == FLAG_REREFERENCED
    # as the leg was prepared: up to the approach below the reference, up to it, settle, zero there
    assert [c for c in axis.calls if c not in ("status", "reset_fault")] == [
        "enable", ("move_to", -PLAN.overrun_mm), ("move_to", 0.0), ("zero", 2)]
    assert clock.slept == [PLAN.dwell_s]
    axis.calls.clear()
    assert recovery.before_attempt(PLAN, axis, laser, 2, clock, RunControl()) == 0 and axis.calls == []


def test_a_beam_break_clears_a_latching_lasers_flag_and_nothing_else():
    clock, axis = Clock(), Axis()
    recovery = LaserRecovery()
    recovery.note(BeamBreak("small signal"))
    assert recovery.before_attempt(PLAN, axis, LatchingLaser(axis.calls), 2, clock, RunControl()) == 0
    assert axis.calls == [("clear_signal_latch", 2)] and clock.slept == []
    recovery.note(BeamBreak("beam interrupted"))  # the station's own laser latches nothing
    assert recovery.before_attempt(PLAN, axis, Laser(axis.calls), 2, clock, RunControl()) == 0
    assert axis.calls == [("clear_signal_latch", 2)]
    recovery.note(DriveFault("following error"))  # not the laser's: the axis's recovery is retry_after's
    assert recovery.before_attempt(PLAN, axis, LatchingLaser(axis.calls), 2, clock, RunControl()) == 0
    assert axis.calls == [("clear_signal_latch", 2)]


def test_an_abort_before_re_referencing_neither_enables_nor_moves():
    control = RunControl()
    control.abort("operator")
    axis = Axis()
    recovery = LaserRecovery()
    recovery.note(CountLost("velocity overflow"))
    with pytest.raises(Aborted):
        recovery.before_attempt(PLAN, axis, LatchingLaser(axis.calls), 2, Clock(), control)
    assert "enable" not in axis.calls and not any(isinstance(c, tuple) for c in axis.calls)


class _LimitedAxis(Axis):
    """A leg whose soft limits hold the plan's travel but not its reference (0 mm)."""

    def limits(self):
        return DriveLimits(1.0, 95.0, 20.0, 200.0)


def test_a_plan_whose_reference_moves_leave_the_soft_limits_is_refused_before_anything_moves():
    plan = SweepPlan("limits", (10.0, 20.0, 30.0), cycles=1, legs=(2,), overrun_mm=4.0)
    plan.validate_limits(1.0, 95.0, 2)  # its own travel (6 .. 34 mm) is inside the leg's limits
    axis = _LimitedAxis()
    with pytest.raises(PlanError, match=r"leg 2 is prepared \(and re-referenced after a lost count\) at its "
                                        r"mid-stroke reference, 0 mm approached from -4.000 mm, but -4.000 mm lies "
                                        r"outside its soft limits 1.000 .. 95.000 mm"):
        list(sweep(plan, {2: axis}, LatchingLaser(axis.calls), Clock()))
    assert axis.calls == []  # nothing asked of the drive, nothing moved
    check_reference_limits(plan, -4.0, 95.0, 2)  # at the limit: allowed
    with pytest.raises(PlanError, match="but 0.000 mm lies outside"):
        check_reference_limits(plan, -4.0, -0.5, 2)
