"""procedures.acquisition.passes: the fault handling and the point record both passes (stop-and-go and on
the fly) share. End-to-end retries on the real simulated rig: tests/station/test_sweep_integration.py
and the committed fault sample (tests/station/test_replay.py)."""

from __future__ import annotations

import pytest

from drivers.interfaces import BeamBreak, CommTimeout, DriveFault, Environment, Reading
from procedures.engine import events as ev
from procedures.engine.control import Aborted, RunControl
from procedures.acquisition.passes import RetryPolicy, SweepFailed, point_record, retry_after
from procedures.acquisition.plans import PlanPoint
from procedures.io.recording.schema import FLAG_RETRIED_BEAM, FLAG_RETRIED_DRIVE
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
