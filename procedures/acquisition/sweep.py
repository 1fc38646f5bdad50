"""The calibration sweep procedure: move, settle, measure, yield a point; repeat.

It talks only to the `ServoAxis` / `Interferometer` / `Clock` interfaces and yields events; the
runner feeds them to sinks (recorder, progress bar, TUI). Safety: the plan is checked against
every leg's soft limits before anything moves; on any exit (done, fault, abort, kill of the
generator) the axes are stopped and disabled in `finally`.

What it shares with the on-the-fly passes (retries, faults, preparing a leg, the point record):
procedures/acquisition/passes.py.
"""

from __future__ import annotations

import json
import uuid
from typing import TYPE_CHECKING, Iterator, Mapping, Sequence

from drivers.interfaces import Clock, DriverError, Environment, Interferometer, ServoAxis
from procedures.engine import events as ev
from procedures.compensation.applied_table import TableState, applied_tables_devices
from procedures.engine.control import Aborted, RunControl
from procedures.acquisition.onthefly import onthefly_passes
from procedures.acquisition.passes import (
    LaserRecovery,
    RetryPolicy,
    SweepFailed,
    check_reference_limits,
    point_record,
    retry_after,
    start_leg,
    stop_all,
)
from procedures.acquisition.plans import PlanPoint, SweepPlan
from procedures.io.recording.schema import FLAG_FRAMES_LOST, FLAG_REREFERENCED, FLAG_RETRIED_BEAM
from procedures.vocabulary import Outcome

if TYPE_CHECKING:  # the annotation only
    from procedures.metrology.thermal import Material


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
    materials: Mapping[int, Material] | None = None,
    warnings: Sequence[str] = (),
) -> Iterator[ev.Event]:
    """Run `plan`, skipping plan indices in `done_indices` (resume). Yields events.

    `materials`: leg -> its material (expansion coefficient, fixed point), which the adaptive
    stopping rule of an on-the-fly plan normalises with (the composing job gives the station
    config's, station/services/jobs.py; None = the default material).
    `warnings`: said (Message, level "warning") right after SweepStarted, e.g. a laser past its
    calibration due date (the session's identity records them too).

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
        check_reference_limits(plan, lim.min_mm, lim.max_mm, leg)  # where preparing and re-referencing go
    for leg in plan.legs:
        control.on_abort(axes[leg].stop)

    total = plan.total_points
    # one point at a time: a huge plan starts (and aborts) at once instead of being listed first
    points = (p for p in plan.iter_points() if p.index not in done_indices)
    done = sum(1 for i in done_indices if 0 <= i < total)
    if control.aborted:  # asked for before anything began (a huge plan being built): nothing moved or written
        yield ev.SweepFinished(Outcome.ABORTED, done, control.reason)
        return
    if plan.onthefly:  # whole passes are grouped: a list (on-the-fly plans are sized like any other)
        points = list(points)
    devices = {f"leg{leg}": axes[leg].identity() for leg in plan.legs}
    devices["interferometer"] = laser.identity()
    devices["laser_air_compensation"] = laser_compensation_record(laser)
    tables = {leg: table_state(axes[leg]) for leg in plan.legs}
    devices.update({f"leg{leg}_compensation": state.text for leg, state in tables.items()})
    devices.update(applied_tables_devices(axes, plan.legs))  # target, bank, sha256: in the file from its creation
    t_start = clock.now() if t0_s is None else t0_s
    yield ev.SweepStarted(session_id or uuid.uuid4().hex[:12], tuple(plan.legs), total, plan.to_dict(), devices, done)
    for text in warnings:
        yield ev.Message(text, level="warning")
    for leg, state in tables.items():
        if state.active:
            yield ev.Message(
                f"leg {leg}: a compensation table is active ({state.text}): this sweep measures the compensated "
                "leg. Right for a verification; for a new calibration roll the table back first "
                "(station rollback), or a table made from this session replaces the active one instead "
                "of adding to it.", "warning")

    outcome, reason = Outcome.COMPLETED, ""
    current_leg: int | None = None
    prev: PlanPoint | None = None
    env: Environment | None = None
    env_t = -1e18
    try:
        if plan.onthefly:  # whole passes at constant speed, captured on the fly (procedures/acquisition/onthefly.py)
            done = yield from onthefly_passes(plan, points, axes, laser, clock, control, retry, t_start, done, total,
                                              materials=materials)
            points = []
        for p in points:
            yield from control.checkpoint()
            if p.leg != current_leg:
                last_leg, current_leg = current_leg, p.leg
                yield from start_leg(plan, axes, laser, clock, control, p, last_leg, t_start)
                prev = None
            flags = 0
            # approach from the pass's side unless we just measured the previous point of this pass
            contiguous = prev is not None and prev.leg == p.leg and prev.run == p.run and prev.index == p.index - 1
            record = None
            attempt = 0
            recovery = LaserRecovery()  # a lost count or a beam break: the laser recovered first
            while record is None:
                yield from control.checkpoint()
                attempt += 1
                try:
                    axis = axes[p.leg]
                    if recovery.before_attempt(plan, axis, laser, p.leg, clock, control) & FLAG_REREFERENCED:
                        flags |= FLAG_REREFERENCED
                        contiguous = False  # re-referenced at mid-stroke: approach the point again
                    if not contiguous:
                        axis.move_to(p.approach_mm(plan.overrun_mm))
                    status = axis.move_to(p.target_mm)
                    clock.sleep(plan.dwell_s)
                    reading = laser.read(p.leg)
                    if env is None or (clock.now() - env_t >= retry.env_interval_s
                                       and p.index not in retry.env_unchanged_at):
                        env = laser.environment()
                        env_t = clock.now()
                    record = point_record(p, reading, env, drive_position_mm=status.position_mm,
                                          time_s=clock.now() - t_start, material_temp_c=env.material_temp_of(p.leg),
                                          load_n=status.load_n,
                                          # a streaming laser's window that lost frames is said so
                                          flags=flags | (FLAG_FRAMES_LOST if getattr(reading, "frames_lost", 0) else 0))
                except Aborted:
                    raise
                except DriverError as exc:
                    flag = yield from retry_after(exc, attempt, retry, control, clock, axes[p.leg], p, t_start)
                    flags |= flag
                    # a beam break: the axis did not move, only re-read; else re-approach so the
                    # point keeps its direction
                    contiguous = flag == FLAG_RETRIED_BEAM
                    recovery.note(exc)
            done += 1
            prev = p
            yield ev.PointMeasured(record, done, total)
    except Aborted as exc:
        outcome, reason = Outcome.ABORTED, str(exc)
    except SweepFailed as exc:
        outcome, reason = Outcome.FAILED, str(exc)
    finally:
        stop_all(axes, plan.legs)
    yield ev.SweepFinished(outcome, done, reason)


def table_state(axis: ServoAxis) -> TableState:
    """The compensation table the drive applies now (TableState.active: table compensation on
    and its active bank holding points)."""
    try:
        st = axis.status()
        if not st.table_enabled:
            return TableState(enabled=False, bank=int(st.active_bank))
        bank = axis.read_table(st.active_bank)
    except DriverError as exc:
        return TableState(error=str(exc))
    return TableState(enabled=True, bank=int(st.active_bank), point_count=bank.point_count,
                      start_mm=bank.start_mm, spacing_mm=bank.spacing_mm)
