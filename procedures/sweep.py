"""The calibration sweep procedure: move, settle, measure, yield a point; repeat.

It talks only to the `ServoAxis` / `Interferometer` / `Clock` interfaces and yields events; the
runner feeds them to sinks (recorder, progress bar, TUI). Safety: the plan is checked against
every leg's soft limits before anything moves; on any exit (done, fault, abort, kill of the
generator) the axes are stopped and disabled in `finally`.

Point record fields and units: see procedures/recording/schema.py. `error_um` = interferometer
reading minus target, micrometres (positive = leg longer than commanded).
"""

from __future__ import annotations

import json
import logging
import uuid
from dataclasses import dataclass
from typing import Any, Iterator, Mapping

from drivers.interfaces import (
    BeamBreak,
    Clock,
    CommTimeout,
    DriveFault,
    DriverError,
    Environment,
    FramingError,
    Interferometer,
    ServoAxis,
)
from procedures import events as ev
from procedures.applied_table import applied_tables_devices
from procedures.control import Aborted, RunControl
from procedures.plans import PlanPoint, SweepPlan
from procedures.onthefly import onthefly_passes
from procedures.recording.schema import FLAG_RETRIED_BEAM, FLAG_RETRIED_DRIVE
from procedures.states import FaultKind, Outcome

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
    # replay instrument again would return the same values; station/jobs.py retry_policy_of)
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


def _kind(exc: BaseException) -> FaultKind:
    if isinstance(exc, BeamBreak):
        return FaultKind.BEAM_BREAK
    if isinstance(exc, DriveFault):
        return FaultKind.DRIVE_FAULT
    if isinstance(exc, CommTimeout):
        return FaultKind.TIMEOUT
    if isinstance(exc, FramingError):
        return FaultKind.FRAMING
    return FaultKind.ERROR


def laser_compensation_record(laser: Interferometer) -> str:
    """How the interferometer compensated its readings for the air, as JSON text for the
    session's devices (procedures/metrology/recorrect.py redoes it from this); "not reported
    (...)" when the instrument cannot say (no COMP? command, a replay)."""
    ask = getattr(laser, "compensation", None)
    if ask is None:
        return "not reported (the interferometer driver has no compensation query)"
    try:
        return json.dumps(ask(), sort_keys=True)
    except DriverError as exc:
        return f"not reported ({exc.args[0] if exc.args else exc})"


def sweep(
    plan: SweepPlan,
    axes: Mapping[int, ServoAxis],
    laser: Interferometer,
    clock: Clock,
    *,
    control: RunControl | None = None,
    done_indices: frozenset[int] | set[int] = frozenset(),
    retry: RetryPolicy = RetryPolicy(),
    session_id: str | None = None,
    t0_s: float | None = None,
    materials: Mapping[int, Any] | None = None,
) -> Iterator[ev.Event]:
    """Run `plan`, skipping plan indices in `done_indices` (resume). Yields events.

    `materials`: leg -> its material (expansion coefficient, fixed point), which the adaptive
    stopping rule of an on-the-fly plan normalises with (the composing job gives the station
    config's, station/jobs.py; None = the default material).

    Ends with `SweepFinished(outcome=...)`: COMPLETED, ABORTED or FAILED (retries exhausted;
    the `Fault` event before it names the point). Pauses at the start of each point and of each
    retry, before any motion (`RunControl.checkpoint`: `Paused` ... `Resumed`).
    """
    control = control or RunControl()
    missing = [leg for leg in plan.legs if leg not in axes]
    if missing:
        raise DriverError(f"no drive connected for leg(s) {missing}")
    # Safety first: check every leg's soft limits before the first motion.
    for leg in plan.legs:
        lim = axes[leg].limits()
        plan.validate_limits(lim.min_mm, lim.max_mm, leg)
    for leg in plan.legs:
        control.on_abort(axes[leg].stop)

    points = [p for p in plan.points() if p.index not in done_indices]
    total = plan.total_points
    done = total - len(points)
    devices = {f"leg{leg}": axes[leg].identity() for leg in plan.legs}
    devices["interferometer"] = laser.identity()
    devices["laser_air_compensation"] = laser_compensation_record(laser)
    tables = {leg: table_state(axes[leg]) for leg in plan.legs}
    devices.update({f"leg{leg}_compensation": text for leg, (_, text) in tables.items()})
    devices.update(applied_tables_devices(axes, plan.legs))  # target, bank, sha256: in the file from its creation
    t_start = clock.now() if t0_s is None else t0_s
    yield ev.SweepStarted(session_id or uuid.uuid4().hex[:12], tuple(plan.legs), total, plan.to_dict(), devices, done)
    for leg, (active, text) in tables.items():
        if active:
            yield ev.Message(
                f"leg {leg}: a compensation table is active ({text}): this sweep measures the compensated "
                "leg. Right for a verification; for a new calibration roll the table back first "
                "(station rollback), or a table made from this session replaces the active one instead "
                "of adding to it.", "warning")

    outcome, reason = Outcome.COMPLETED, ""
    current_leg: int | None = None
    prev: PlanPoint | None = None
    env: Environment | None = None
    env_t = -1e18
    try:
        if plan.onthefly:  # whole passes at constant speed, captured on the fly (procedures/onthefly.py)
            done = yield from onthefly_passes(plan, points, axes, laser, clock, control, retry, t_start, done, total,
                                              _prepare_leg, _recover_axis, _kind, SweepFailed, materials=materials)
            points = []
        for p in points:
            yield from control.checkpoint()
            if p.leg != current_leg:
                last_leg, current_leg = current_leg, p.leg
                yield ev.LegStarted(p.leg)
                try:
                    # in here, so a link failing while switching legs stops the session resumable,
                    # with its fault recorded, like a failure while preparing the leg
                    if last_leg is None:
                        laser.set_averaging(plan.averaging_s)
                    else:
                        axes[last_leg].disable()
                    _prepare_leg(axes[p.leg], laser, p.leg, clock, plan)
                except DriverError as exc:  # recorded like a point's fault: the session says where it stopped
                    if control.aborted:
                        raise Aborted(control.reason) from exc
                    fault = ev.Fault(p.index, p.leg, p.run, 0.0, _kind(exc),
                                     f"preparing leg {p.leg} (enable, zero at mid-stroke): {exc}", 1, True,
                                     clock.now() - t_start)
                    yield fault
                    raise SweepFailed(fault) from exc
                prev = None
            flags = 0
            # approach from the pass's side unless we just measured the previous point of this pass
            contiguous = prev is not None and prev.leg == p.leg and prev.run == p.run and prev.index == p.index - 1
            record = None
            attempt = 0
            while record is None:
                yield from control.checkpoint()
                attempt += 1
                try:
                    axis = axes[p.leg]
                    if not contiguous:
                        axis.move_to(p.approach_mm(plan.overrun_mm))
                    status = axis.move_to(p.target_mm)
                    clock.sleep(plan.dwell_s)
                    reading = laser.read(p.leg)
                    if env is None or (clock.now() - env_t >= retry.env_interval_s
                                       and p.index not in retry.env_unchanged_at):
                        env = laser.environment()
                        env_t = clock.now()
                    record = {
                        "index": p.index, "leg": p.leg, "run": p.run, "direction": p.direction,
                        "target_mm": p.target_mm, "commanded_mm": p.target_mm,
                        "drive_position_mm": status.position_mm, "measured_mm": reading.position_mm,
                        "error_um": (reading.position_mm - p.target_mm) * 1000.0,
                        "time_s": clock.now() - t_start,
                        "air_temp_c": env.air_temp_c, "air_pressure_hpa": env.air_pressure_hpa,
                        "humidity_pct": env.humidity_pct, "material_temp_c": env.material_temp_of(p.leg),
                        "load_n": status.load_n, "signal_pct": reading.signal_pct, "flags": flags,
                    }
                except Aborted:
                    raise
                except DriverError as exc:
                    if control.aborted:
                        raise Aborted(control.reason) from exc
                    kind = _kind(exc)
                    gave_up = attempt > retry.limit_for(kind)
                    fault = ev.Fault(p.index, p.leg, p.run, p.target_mm, kind, str(exc), attempt, gave_up, clock.now() - t_start)
                    yield fault
                    if gave_up:
                        raise SweepFailed(fault) from exc
                    contiguous = False  # re-approach so the point keeps its direction
                    if kind is FaultKind.BEAM_BREAK:
                        flags |= FLAG_RETRIED_BEAM
                        clock.sleep(retry.beam_wait_s)
                        contiguous = True  # the axis did not move: only re-read
                    else:
                        flags |= FLAG_RETRIED_DRIVE
                        _recover_axis(axes[p.leg])
            done += 1
            prev = p
            yield ev.PointMeasured(record, done, total)
    except Aborted as exc:
        outcome, reason = Outcome.ABORTED, str(exc)
    except SweepFailed as exc:
        outcome, reason = Outcome.FAILED, str(exc)
    finally:
        _stop_all(axes, plan.legs)
    yield ev.SweepFinished(outcome, done, reason)


def table_state(axis: ServoAxis) -> tuple[bool, str]:
    """(active, description) of the compensation table the drive applies now. A table counts as
    active when the drive has table compensation on and its active bank holds points."""
    try:
        st = axis.status()
        if not st.table_enabled:
            return False, "table compensation off"
        bank = axis.read_table(st.active_bank)
    except DriverError as exc:
        return False, f"unknown ({exc})"
    if bank.point_count == 0:
        return False, f"bank {st.active_bank} active, empty"
    return True, (f"bank {st.active_bank} active, {bank.point_count} points from {bank.start_mm:+.3f} mm "
                  f"every {bank.spacing_mm:g} mm")


def _prepare_leg(axis: ServoAxis, laser: Interferometer, leg: int, clock: Clock, plan: SweepPlan) -> None:
    """Enable the drive, go to the mid-stroke reference and zero the interferometer there.

    The reference is always approached upwards (from -overrun), so the zero carries the same
    reversal state in every session, with or without a compensation table active."""
    st = axis.status()
    if st.fault:
        axis.reset_fault()
    axis.enable()
    axis.move_to(-max(plan.overrun_mm, 0.5))
    axis.move_to(0.0)
    clock.sleep(plan.dwell_s)
    laser.zero(leg)


def _recover_axis(axis: ServoAxis) -> None:
    try:
        st = axis.status()
        if st.fault:
            axis.reset_fault()
        if not axis.status().enabled:
            axis.enable()
    except DriverError:
        log.warning("axis recovery failed; the next attempt will report it", exc_info=True)


def _stop_all(axes: Mapping[int, ServoAxis], legs) -> None:
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
