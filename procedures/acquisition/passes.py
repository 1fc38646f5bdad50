"""What the stop-and-go sweep (procedures/acquisition/sweep.py) and the on-the-fly passes
(procedures/acquisition/onthefly.py) share: the retry policy and how a fault is named, retried or given up,
preparing a leg (enable, zero at mid-stroke), recovering an axis, recovering the laser after a
lost count or a beam break (`LaserRecovery`), stopping every axis, and the point record both yield.

Point record fields and units: procedures/io/recording/schema.py. `error_um` = interferometer
reading minus target, micrometres (positive = leg longer than commanded).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Generator, Iterator, Mapping

from drivers.errors import CountLost
from drivers.interfaces import (
    BeamBreak,
    Clock,
    CommTimeout,
    DriveFault,
    DriverError,
    Environment,
    FramingError,
    Interferometer,
    LatchingInterferometer,
    Reading,
    ServoAxis,
)
from procedures.engine import events as ev
from procedures.engine.control import Aborted, RunControl
from procedures.acquisition.plans import PlanPoint, SweepPlan
from procedures.vocabulary import PlanError
from procedures.io.recording.schema import FLAG_REREFERENCED, FLAG_RETRIED_BEAM, FLAG_RETRIED_DRIVE, PointRecord
from drivers.interfaces import FaultKind

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RetryPolicy:
    """Bounded retries per point. `beam_wait_s`: wait before re-reading after a beam break."""

    beam_retries: int = 3
    drive_retries: int = 2
    comm_retries: int = 2
    beam_wait_s: float = 0.5
    env_interval_s: float = 10.0  # environment is read at most this often (it changes slowly)
    # point indices at which the environment is not read again: the one held is this point's
    # (a replay: the recording's environment did not change since the point before, so asking the
    # replay instrument again would return the same values; station/services/jobs.py retry_policy_of)
    env_unchanged_at: frozenset[int] = frozenset()

    def limit_for(self, kind: FaultKind) -> int:
        """Retries allowed at one point for a fault of `kind` (beam, drive, else communication)."""
        return {FaultKind.BEAM_BREAK: self.beam_retries, FaultKind.DRIVE_FAULT: self.drive_retries}.get(
            kind, self.comm_retries)


class SweepFailed(Exception):
    """Retries exhausted at a point; the session stops there and can be resumed."""

    def __init__(self, fault: ev.Fault):
        super().__init__(f"{fault.kind} at leg {fault.leg}, run {fault.run}, target {fault.target_mm:.4f} mm: {fault.message}")
        self.fault = fault


def fault_kind(exc: BaseException) -> FaultKind:
    if isinstance(exc, BeamBreak):
        return FaultKind.BEAM_BREAK
    if isinstance(exc, DriveFault):
        return FaultKind.DRIVE_FAULT
    if isinstance(exc, CommTimeout):
        return FaultKind.TIMEOUT
    if isinstance(exc, FramingError):
        return FaultKind.FRAMING
    return FaultKind.ERROR


def start_leg(plan: SweepPlan, axes: Mapping[int, ServoAxis], laser: Interferometer, clock: Clock,
              control: RunControl, first: PlanPoint, last_leg: int | None, t_start: float) -> Iterator[ev.Event]:
    """Switch to `first.leg`: LegStarted, then set the laser's averaging (the first leg) or disable
    the leg before, and prepare the new one. A driver error here (a link failing while switching
    legs too) is recorded like a point's fault and stops the session resumable (SweepFailed)."""
    yield ev.LegStarted(first.leg)
    try:
        if last_leg is None:
            laser.set_averaging(plan.averaging_s)
        else:
            axes[last_leg].disable()
        prepare_leg(axes[first.leg], laser, first.leg, clock, plan, control)
    except DriverError as exc:
        if control.aborted:
            raise Aborted(control.reason) from exc
        fault = ev.Fault(first.index, first.leg, first.run, 0.0, fault_kind(exc),
                         f"preparing leg {first.leg} (enable, zero at mid-stroke): {exc}", 1, True, clock.now() - t_start)
        yield fault
        raise SweepFailed(fault) from exc


def retry_after(exc: DriverError, attempt: int, retry: RetryPolicy, control: RunControl, clock: Clock,
                axis: ServoAxis, p: PlanPoint, t_start: float, what: str = "") -> Generator[ev.Event, None, int]:
    """A driver error at attempt `attempt` of point (or pass) `p`: yield its Fault; give up
    (SweepFailed) once the retries for its kind are spent; else get ready for the next attempt
    (a beam break: wait, the axis did not move; else recover the axis) and return the flag the
    point will carry (FLAG_RETRIED_BEAM or FLAG_RETRIED_DRIVE). `what` prefixes the message."""
    if control.aborted:
        raise Aborted(control.reason) from exc
    kind = fault_kind(exc)
    gave_up = attempt > retry.limit_for(kind)
    fault = ev.Fault(p.index, p.leg, p.run, p.target_mm, kind, f"{what}{exc}", attempt, gave_up, clock.now() - t_start)
    yield fault
    if gave_up:
        raise SweepFailed(fault) from exc
    if kind is FaultKind.BEAM_BREAK:
        clock.sleep(retry.beam_wait_s)
        return FLAG_RETRIED_BEAM
    recover_axis(axis)
    return FLAG_RETRIED_DRIVE


def point_record(p: PlanPoint, reading: Reading, env: Environment, *, drive_position_mm: float, time_s: float,
                 material_temp_c: float, load_n: float, flags: int, speed_mm_s: float = math.nan) -> PointRecord:
    """The record of a measured point. `reading`: the interferometer's (position_mm, signal_pct);
    `speed_mm_s`: an on-the-fly sample's speed (NaN: read at rest)."""
    return PointRecord(
        index=p.index, leg=p.leg, run=p.run, direction=p.direction,
        target_mm=p.target_mm, commanded_mm=p.target_mm,
        drive_position_mm=drive_position_mm, measured_mm=reading.position_mm,
        error_um=(reading.position_mm - p.target_mm) * 1000.0,
        time_s=time_s,
        air_temp_c=env.air_temp_c, air_pressure_hpa=env.air_pressure_hpa,
        humidity_pct=env.humidity_pct, material_temp_c=material_temp_c,
        load_n=load_n, signal_pct=reading.signal_pct, flags=flags, speed_mm_s=speed_mm_s,
    )


def reference_moves_mm(plan: SweepPlan) -> tuple[float, float]:
    """Where preparing (and re-referencing) a leg moves it: the approach below the mid-stroke
    reference, then the reference (0 mm), mm. The sweep checks both against each leg's soft
    limits before anything moves (`check_reference_limits`)."""
    return -max(plan.overrun_mm, 0.5), 0.0


def check_reference_limits(plan: SweepPlan, min_mm: float, max_mm: float, leg: int) -> None:
    """PlanError, before anything moves, when the leg's reference moves (`reference_moves_mm`)
    leave its soft limits [min_mm, max_mm]: a lost count mid-session re-references the leg, so
    they must be as safe as the plan's own travel."""
    for where_mm in reference_moves_mm(plan):
        if not min_mm - 1e-9 <= where_mm <= max_mm + 1e-9:
            raise PlanError(f"leg {leg} is prepared (and re-referenced after a lost count) at its mid-stroke reference, "
                            f"0 mm approached from {reference_moves_mm(plan)[0]:.3f} mm, but {where_mm:.3f} mm lies "
                            f"outside its soft limits {min_mm:.3f} .. {max_mm:.3f} mm; set the drive's soft limits "
                            "around its mid-stroke (or shrink the plan's overrun)")


def prepare_leg(axis: ServoAxis, laser: Interferometer, leg: int, clock: Clock, plan: SweepPlan,
                control: RunControl | None = None) -> None:
    """Enable the drive, go to the mid-stroke reference and zero the interferometer there.

    The reference is always approached upwards (from -overrun), so the zero carries the same
    reversal state in every session, with or without a compensation table active. `control`:
    an abort asked for meanwhile (its stop quick-stops the drive) raises `Aborted` before the
    drive is enabled again or told to move (a re-reference runs in the middle of a session)."""
    check = control.check if control is not None else (lambda: None)
    approach_mm, reference_mm = reference_moves_mm(plan)
    st = axis.status()
    if st.fault:
        axis.reset_fault()
    check()
    axis.enable()
    check()
    axis.move_to(approach_mm)
    check()
    axis.move_to(reference_mm)
    clock.sleep(plan.dwell_s)
    check()
    laser.zero(leg)


class LaserRecovery:
    """What a fault of the laser leaves to do before the next attempt of a point, a reversal probe
    or an on-the-fly pass (the one place the stop-and-go sweep and the on-the-fly passes recover it):

    - a lost count (`CountLost`, a velocity overflow: no position is valid until the origin is
      set again): the leg is re-referenced, `prepare_leg` (to the reference approached upwards,
      the very moves the leg started with, so inside the soft limits it was prepared within; the
      laser zeroed there, which clears its latched flags); the attempt's records carry
      FLAG_REREFERENCED, and a stop-and-go point is approached again;
    - a beam break: a laser that latches its small-signal flag (`LatchingInterferometer`, the
      µLine-F1) has it cleared, so the next attempt judges the beam by its own samples (a
      stop-and-go read clears it itself; a pass's stream cannot: every sample after the break
      carries the latch). The wait for the beam is retry_after's.

    `note(exc)` after a failed attempt; `before_attempt(...)` at the start of the next one, after
    its checkpoint (a pause comes before any motion) and inside its `try`: a fault while
    re-referencing is retried like the attempt's own, the recovery still due; an abort stops the
    re-referencing move as any other (the sweep's on_abort stops the axes)."""

    def __init__(self) -> None:
        self.due: type[BeamBreak] | None = None  # CountLost (re-reference), BeamBreak (clear the latch), None

    def note(self, exc: BaseException) -> None:
        """After attempt's fault `exc`: what the next attempt must do first (a lost count outranks
        a beam break: zeroing clears both)."""
        if isinstance(exc, CountLost):
            self.due = CountLost
        elif isinstance(exc, BeamBreak) and self.due is None:
            self.due = BeamBreak

    def before_attempt(self, plan: SweepPlan, axis: ServoAxis, laser: Interferometer, leg: int,
                       clock: Clock, control: RunControl) -> int:
        """Do what is due (see the class); returns the flag the attempt's records carry
        (FLAG_REREFERENCED after a lost count, else 0). An abort meanwhile: `Aborted`."""
        due = self.due
        if due is None:
            return 0
        if due is CountLost:
            prepare_leg(axis, laser, leg, clock, plan, control)
            self.due = None
            return FLAG_REREFERENCED
        if isinstance(laser, LatchingInterferometer):
            laser.clear_signal_latch(leg)
        self.due = None
        return 0


def recover_axis(axis: ServoAxis) -> None:
    try:
        st = axis.status()
        if st.fault:
            axis.reset_fault()
        if not axis.status().enabled:
            axis.enable()
    except DriverError:
        log.warning("axis recovery failed; the next attempt will report it", exc_info=True)


def stop_all(axes: Mapping[int, ServoAxis], legs) -> None:
    """Quick stop then disable every axis of the plan; never raises (a dead link is logged)."""
    for leg in legs:
        axis = axes.get(leg)
        if axis is None:
            continue
        for action in (axis.stop, axis.disable):
            try:
                action()
            except Exception:
                log.warning("leg %s: %s failed while making the rig safe", leg, action.__name__, exc_info=True)
