"""The on-the-fly passes of a sweep (docs/onthefly.md): move through all targets at constant
speed; the drive's position-compare output triggers the interferometer at every target.

For each pass: move (at the profile speed) to the run-up start `overrun_mm` before the first
target, arm the drive's compare list (first target, step signed by the direction, count) and
the laser's capture, move at the pass speed to `overrun_mm` beyond the last target, then read
the samples back. A sample's position is the compare position (the drive's position actual at
the pulse, by construction), its reading the laser's latched one, its time the instrument's
time of the pulse, its speed the central difference of positions over those times. Then, at
rest where the pass ended (`overrun_mm` beyond its last target), after the dwell, one averaged
reading: the pass's anchor (FLAG_ANCHOR), which shares the pass's offset and so tells the
speed-dependent error from it (procedures/fit/dynamic.py). The
environment (air, material temperature) is read after every pass and holds for its samples.

A laser without trigger input that streams (the µLine-F1, drivers.interfaces.StreamingInterferometer)
takes the compare and capture's place with the clock: the drive's move is traced (its position
actual polled, `TracingAxis.move_traced`), the laser's samples of the pass read after the dwell,
and `align_stream` makes each target's reading from the two on the station's clock
(docs/onthefly.md, "A laser without trigger input").

A fault during a pass (a sample taken without beam, fewer samples than pulses expected, a drive
fault) is retried as the stop-and-go sweep retries a point (procedures/acquisition/passes.py), but for the
whole pass (a moving axis cannot go back for one sample): its readings are dropped; after a lost
count the leg is re-referenced first and after a beam break a latching laser's flag cleared, as
for a point (passes.LaserRecovery; the pass's records say so: FLAG_REREFERENCED, FLAG_RETRIED_BEAM). `sweep()` calls `onthefly_passes` in
place of its loop over points; safety (limits checked before any motion, stop and disable on
every exit) stays with `sweep()`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Iterator, Mapping

import numpy as np

from drivers.interfaces import (
    CapturingInterferometer,
    Clock,
    DriverError,
    Interferometer,
    PositionCompareAxis,
    Reading,
    ServoAxis,
    StreamingInterferometer,
    TracingAxis,
)
from procedures.engine import events as ev
from procedures.acquisition.adaptive import AdaptiveRule
from procedures.acquisition.probe_rule import ProbeRule
from procedures.engine.control import Aborted, RunControl
from procedures.acquisition.passes import LaserRecovery, RetryPolicy, point_record, retry_after, start_leg
from procedures.acquisition.plans import PlanPoint, SweepPlan
from procedures.io.recording.schema import FLAG_ANCHOR, FLAG_PROBE, POINT_DTYPE
from procedures.io.recording.writer import point_row

if TYPE_CHECKING:  # the annotation only
    from procedures.metrology.thermal import Material


class CaptureShort(DriverError):
    """The laser latched fewer samples than the drive's compare list should have fired."""


def _passes(points: list[PlanPoint]) -> list[list[PlanPoint]]:
    out: list[list[PlanPoint]] = []
    for p in points:
        if out and out[-1][0].leg == p.leg and out[-1][0].run == p.run:
            out[-1].append(p)
        else:
            out.append([p])
    return out


TRACE_INTERVAL_S = 0.02
"""How often the drive's position actual is polled during a pass with a streaming laser (a
Modbus TCP read takes about a millisecond; 50 polls a second leave the line to the rest)."""


MERGE_MM = 0.05
"""Stream samples closer than this along a pass are averaged into one before interpolating."""


class StreamAlignment(DriverError):
    """A pass with a streaming laser whose samples cannot be aligned with the drive's trace
    (no samples near a target: a gap in the stream, or the trace does not cover the targets)."""


def align_stream(seq_mm: np.ndarray, trace: list[tuple[float, float]], samples: list, leg: int,
                 period_s: float) -> list[Reading]:
    """The readings of a pass with a streaming laser (docs/onthefly.md, "A laser without trigger
    input"): both time-stamped on the station's clock, the drive's traced position actual
    (`trace`: (t s, position mm) per poll) and the laser's samples (`samples`: t_s, position_mm).

    The drive's path is the cubic spline through its polls while it moved (its acceleration
    at the ends of the pass included); for each target, in pass order (`seq_mm`), the time the
    drive passed it on that path; each laser sample's error against the drive's position on the
    path at its time stamp; the reading at the target is the error interpolated there, a cubic
    spline through the samples' errors over position (not smoothed: at 20 mm/s the samples lie
    0.8 mm apart, and a straight line through the three or four about a target took a third off
    the screw's 5 mm wobble). A reading's `t_s` is the time the drive passed its target. The
    samples are late on the drive's polls by what the two transports' latencies differ: a
    constant delay, v x delay along the pass, which the dynamic fit takes as part of the speed
    lag (procedures/fit/dynamic.py), as it takes the leg's own lag behind the encoder."""
    from scipy.interpolate import CubicSpline

    t_tr = np.array([t for t, _ in trace], dtype=float)
    x_tr = np.array([x for _, x in trace], dtype=float)
    sign = 1.0 if seq_mm.size < 2 or seq_mm[-1] >= seq_mm[0] else -1.0
    # the polls while it moved: each past the one before, later than it
    keep = [0]
    for k in range(1, t_tr.size):
        if sign * (x_tr[k] - x_tr[keep[-1]]) > 0 and t_tr[k] > t_tr[keep[-1]]:
            keep.append(k)
    t_m, x_m = t_tr[keep], x_tr[keep]
    t_smp = np.array([x.t_s for x in samples], dtype=float)
    l_smp = np.array([x.position_mm for x in samples], dtype=float)
    if t_smp.size < 2 or t_m.size < 4:
        raise StreamAlignment(f"leg {leg}: {t_smp.size} laser samples and {t_m.size} drive polls while moving in "
                              "the pass: too few to align")
    lo, hi = (x_m[0], x_m[-1]) if sign > 0 else (x_m[-1], x_m[0])
    if not (lo <= float(np.min(seq_mm)) and float(np.max(seq_mm)) <= hi):
        raise StreamAlignment(f"leg {leg}: the drive's trace ({lo:.3f}..{hi:.3f} mm) does not cover the pass's "
                              "targets (the move stopped short)")
    x_of_t = CubicSpline(t_m, x_m)
    t_of_x = CubicSpline(sign * x_m, t_m)
    inside = (t_smp >= t_m[0]) & (t_smp <= t_m[-1])
    t_smp, l_smp = t_smp[inside], l_smp[inside]
    x_smp = x_of_t(t_smp)  # the drive's position at each sample's time stamp
    e_smp = l_smp - x_smp
    # the samples over the targets (and a few mm more), along the pass; samples closer than
    # MERGE_MM (the drive slowing at the ends) averaged into one: a spline through two noisy
    # values a hair apart swings wide between them
    span = (x_smp >= float(np.min(seq_mm)) - 2.0) & (x_smp <= float(np.max(seq_mm)) + 2.0)
    order = np.argsort(sign * x_smp[span], kind="stable")
    u_all, e_all = sign * x_smp[span][order], e_smp[span][order]
    xs_l: list[float] = []
    es_l: list[list[float]] = []
    for u, e in zip(u_all, e_all):
        if xs_l and u - xs_l[-1] < MERGE_MM:
            es_l[-1].append(float(e))
        else:
            xs_l.append(float(u))
            es_l.append([float(e)])
    xs = np.array(xs_l)
    es = np.array([float(np.mean(v)) for v in es_l])
    if xs.size < 2:
        raise StreamAlignment(f"leg {leg}: {xs.size} laser samples along the pass: too few to align")
    e_at = CubicSpline(xs, es) if xs.size >= 4 else (lambda u: np.interp(u, xs, es))
    out: list[Reading] = []
    for x_i in seq_mm:
        t_i = float(t_of_x(sign * x_i))
        v_i = float(x_of_t(t_i, 1))
        # a sample on either side within 1.5 stream periods of travel, else a gap in the stream
        u = sign * x_i
        below, above = xs[xs <= u], xs[xs >= u]
        reach = 1.5 * abs(v_i) * period_s
        if not (below.size and above.size and u - below[-1] <= reach and above[0] - u <= reach):
            raise StreamAlignment(f"leg {leg}: no laser sample on both sides within {1.5 * period_s:.3f} s of the "
                                  f"drive passing {x_i:.3f} mm (a gap in the stream)")
        e_i = float(e_at(u))
        out.append(Reading(axis=leg, position_mm=float(x_i) + e_i, beam_ok=True, signal_pct=float("nan"), t_s=t_i))
    return out


def speeds_of(positions_mm: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """Signed speed at each sample, mm/s: central differences (one-sided at the ends)."""
    if positions_mm.size < 2:
        return np.zeros(positions_mm.size)
    return np.gradient(positions_mm, t_s)


def _probe(plan: SweepPlan, p: PlanPoint, axis: ServoAxis, laser: Interferometer, clock: Clock,
           control: RunControl, retry: RetryPolicy, t_start: float, done: int, total: int,
           set_averaging: bool, in_place: bool) -> Iterator[ev.Event]:
    """One reversal probe (SweepPlan, docs/onthefly.md "Reversal probes"): a stop-and-go reading
    at `p.target_mm` approached in `p.direction` right after a reversal, after the dwell, averaged
    over the plan's probe averaging (`set_averaging`: set it first; the probes of a leg follow
    one another, and the next leg's first pass sets the anchors' back). `in_place`: the reading
    before it in the plan (the probe before, or the leg's last pass) has just left the axis on
    the other side; else (a resume among the probes, after preparing the leg) and on a retry
    (recovered wherever it stopped) the axis goes back there first, arriving against the probe's
    direction (`SweepPlan.before_probe_mm`), so the probe follows the same reversal over the
    same travel as in an uninterrupted run; and where the reading before lies on the probe's far
    side (a descending block of an adaptive count), it is approached from `probe_gap_mm` short of
    it (`SweepPlan.probe_via_mm`). Returns the count of points done and the probe's record."""
    flags = FLAG_PROBE
    attempt = 0
    recovery = LaserRecovery()  # a lost count (re-referenced: then approached again) or a beam break
    while True:
        yield from control.checkpoint()
        attempt += 1
        try:
            flags |= recovery.before_attempt(plan, axis, laser, p.leg, clock, control)
            # at the plan's faster pass speed: the leg runs it on the fly anyway, and the probes'
            # moves (up the stroke in steps, a gap down) are most of their time after the dwell
            speed = max(plan.speeds_mm_s)
            if attempt > 1 or not in_place:
                before_mm = plan.before_probe_mm(p.run)
                # beyond it on the probe's side (inside the plan's travel: the stroke or the anchor's gap)
                axis.move_to(before_mm + p.direction * plan.probe_gap_mm, velocity_mm_s=speed)
                axis.move_to(before_mm, velocity_mm_s=speed)
            via_mm = plan.probe_via_mm(p.run)
            if via_mm is not None:  # the reading before lies on the probe's far side (a descending block)
                axis.move_to(via_mm, velocity_mm_s=speed)
            status = axis.move_to(p.target_mm, velocity_mm_s=speed)
            clock.sleep(plan.dwell_s)
            if set_averaging:
                laser.set_averaging(plan.probe_averaging_s)
                set_averaging = False
            reading = laser.read(p.leg)
            env = laser.environment()
            break
        except Aborted:
            raise
        except DriverError as exc:
            flags |= yield from retry_after(exc, attempt, retry, control, clock, axis, p, t_start, "reversal probe: ")
            recovery.note(exc)
    record = point_record(p, reading, env, drive_position_mm=status.position_mm, time_s=clock.now() - t_start,
                          material_temp_c=env.material_temp_of(p.leg), load_n=status.load_n, flags=flags,
                          speed_mm_s=float("nan"))
    done += 1
    yield ev.PointMeasured(record, done, total)
    return done, record


def _judge_probes(plan: SweepPlan, leg: int, rules: dict, measured: dict, probes: list, materials, done_legs: set,
                  left: int) -> Iterator[ev.Event]:
    """After a probe pair of `leg`: whether its probes may stop (ProbeRule; its shape from the leg's
    passes in `measured`, none when resumed among its probes). On a stop `leg` joins `done_legs` and
    the stop is reported (ProbesStopped, a message; `left` planned points not needed)."""
    rule = rules.get(leg)
    if rule is None:
        rule = rules[leg] = ProbeRule(plan.probe_target_um, plan.reversal_probes, material=(materials or {}).get(leg))
        rule.shape(np.concatenate(measured[leg]).astype(POINT_DTYPE) if measured.get(leg) else None, leg)
    reason = rule.after_pair(np.concatenate(probes).astype(POINT_DTYPE), leg)
    if reason is None:
        return
    done_legs.add(leg)
    yield ev.ProbesStopped(leg, rule.pairs, reason, rule.stderr_um, plan.probe_target_um, left)
    yield ev.Message(f"leg {leg}: reversal probes stopped: {reason}"
                     + (f"; {left} planned points not needed" if left else ""), "info")


def onthefly_passes(
    plan: SweepPlan,
    points: list[PlanPoint],
    axes: Mapping[int, ServoAxis],
    laser: Interferometer,
    clock: Clock,
    control: RunControl,
    retry: RetryPolicy,
    t_start: float,
    done: int,
    total: int,
    materials: Mapping[int, Material] | None = None,
) -> Iterator[ev.Event]:
    """Measure the passes of `points` (the plan's points not yet done) on the fly; yields the
    sweep's events and returns the count of points done. Leg changes, faults and retries as the
    stop-and-go sweep (procedures/acquisition/passes.py; retries run out: SweepFailed). `materials`: leg ->
    material the adaptive rule normalises with (procedures.acquisition.adaptive; a leg not in it: the default)."""
    # a laser with a trigger input latches at the drive's compare pulses; a streaming one is
    # aligned with the drive's traced positions on the station's clock
    streaming = not isinstance(laser, CapturingInterferometer) and isinstance(laser, StreamingInterferometer)
    if not streaming and not isinstance(laser, CapturingInterferometer):
        raise DriverError("the interferometer has no capture mode (CAPARM/CAP?) and does not stream, so an on-the-fly "
                          "plan cannot run; use a stop-and-go plan")
    for leg in plan.legs:
        if streaming and not isinstance(axes[leg], TracingAxis):
            raise DriverError(f"leg {leg}: the drive's position cannot be traced during a move; use a stop-and-go plan")
        if not streaming and not isinstance(axes[leg], PositionCompareAxis):
            raise DriverError(f"leg {leg}: the drive has no position-compare output; use a stop-and-go plan")
    all_targets = np.asarray(plan.targets_mm, dtype=float)
    n = all_targets.size
    step = plan.step_mm
    current_leg: int | None = None
    stopped: set[int] = set()
    probes_done: set[int] = set()  # legs whose probe rule stopped them
    rules: dict[int, AdaptiveRule] = {}
    measured: dict[int, list[np.ndarray]] = {}
    planned_left: dict[int, int] = {}
    for p in points:
        if not plan.is_probe_run(p.run):  # what an adaptive stop can skip: the passes
            planned_left[p.leg] = planned_left.get(p.leg, 0) + 1
    probe_rules: dict[int, ProbeRule] = {}
    probes_of: dict[int, list[np.ndarray]] = {}
    probes_left: dict[int, int] = {}
    for p in points:
        if plan.is_probe_run(p.run):
            probes_left[p.leg] = probes_left.get(p.leg, 0) + 1
    prev_temp: tuple[float, float] | None = None
    probing = False  # the laser holds the probes' averaging (a new session sets the plan's at its first leg)
    in_place = False  # the axis stands where the plan's point before the next one left it
    for pas in _passes(points):
        first = pas[0]
        leg, run, d = first.leg, first.run, first.direction
        probe = plan.is_probe_run(run)
        if (leg in stopped and not probe) or (probe and leg in probes_done):
            continue
        yield from control.checkpoint()
        if leg != current_leg:
            last_leg, current_leg = current_leg, leg
            yield from start_leg(plan, axes, laser, clock, control, first, last_leg, t_start)
            prev_temp = None  # (session time, material temperature) of the reading before a pass
            in_place = False  # the leg was just prepared (at mid-stroke), not where its plan's last point left it
        axis = axes[leg]
        if probe:
            done, record = yield from _probe(plan, first, axis, laser, clock, control, retry, t_start, done, total,
                                             set_averaging=not probing, in_place=in_place)
            probing = in_place = True
            probes_left[leg] -= 1
            if plan.probe_target_um > 0:  # the adaptive count (procedures/acquisition/probe_rule.py)
                probes_of.setdefault(leg, []).append(point_row(record))
                if first.direction < 0:  # a pair read: judge it
                    yield from _judge_probes(plan, leg, probe_rules, measured, probes_of[leg], materials,
                                             probes_done, probes_left[leg])
                    if leg in probes_done:
                        total -= probes_left[leg]
            continue
        speed = plan.speed_of_run(run)
        seq = all_targets if d > 0 else all_targets[::-1]
        start_mm = float(seq[0] - d * plan.overrun_mm)
        end_mm = float(seq[-1] + d * plan.overrun_mm)
        flags = 0
        attempt = 0
        samples = None
        # a lost count: the pass's readings are dropped, the leg re-referenced (the laser zeroed
        # at its reference) before it runs again; a beam break: the laser's latch cleared first
        recovery = LaserRecovery()
        while samples is None:
            yield from control.checkpoint()
            attempt += 1
            try:
                flags |= recovery.before_attempt(plan, axis, laser, leg, clock, control)
                if probing:  # the last leg's probes left their averaging: the anchor wants the plan's
                    laser.set_averaging(plan.averaging_s)
                    probing = False
                axis.move_to(start_mm)
                if prev_temp is None or prev_temp[0] is None:
                    # the first pass of the leg: the temperature as it starts (time: its first sample)
                    prev_temp = (None, laser.environment().material_temp_of(leg))
                if streaming:
                    status, trace = axis.move_traced(end_mm, speed, TRACE_INTERVAL_S)  # type: ignore[attr-defined]
                    period_s = float(getattr(laser, "period_s", 0.04))
                    t_tr = [t for t, x in trace if min(seq[0], seq[-1]) - step <= x <= max(seq[0], seq[-1]) + step]
                    if len(t_tr) < 3:
                        raise StreamAlignment(f"leg {leg} pass {run}: {len(t_tr)} drive polls over the targets "
                                              "(the move stopped short, or the drive answers too slowly)")
                    # the anchor's dwell first: the stream is in up to its end by then (on any clock)
                    clock.sleep(max(plan.dwell_s, 4 * period_s))
                    stream = laser.stream_samples(leg, t_tr[0] - 3 * period_s,  # type: ignore[attr-defined]
                                                  t_tr[-1] + 3 * period_s)
                    readings = align_stream(seq, trace, stream, leg, period_s)
                else:
                    axis.arm_position_compare(float(seq[0]), d * step, n)  # type: ignore[attr-defined]
                    laser.arm_capture(leg, n)  # type: ignore[attr-defined]
                    status = axis.move_to(end_mm, velocity_mm_s=speed)
                    axis.arm_position_compare(float(seq[0]), d * step, 0)  # type: ignore[attr-defined]  # off
                    captured, _ = laser.capture_count(leg)  # type: ignore[attr-defined]
                    if captured < n:
                        raise CaptureShort(f"leg {leg} pass {run}: the laser latched {captured} of {n} samples "
                                           "(trigger wiring, or the move stopped short)")
                    readings = laser.capture_samples(leg, 0, n)  # type: ignore[attr-defined]
                # the anchor: at rest where the pass ended, settled, averaged (same pass offset)
                if not streaming:  # (a streaming pass has had its dwell)
                    clock.sleep(plan.dwell_s)
                anchor_reading = laser.read(leg)
                # after every pass: a pass heats the screw by its travel in seconds, so the
                # material temperature of the pass before would be stale (the readings are
                # normalised to 20 degC with it)
                env = laser.environment()
                samples = (readings, status, env, anchor_reading)
            except Aborted:
                raise
            except DriverError as exc:
                flags |= yield from retry_after(exc, attempt, retry, control, clock, axis, first, t_start,
                                                "on-the-fly pass: ")
                recovery.note(exc)
        readings, status, env, anchor_reading = samples
        t_abs = np.array([r.t_s for r in readings], dtype=float)
        v = speeds_of(seq, t_abs)
        by_target = {round(float(x), 9): i for i, x in enumerate(seq)}
        rows = []
        anchor_mm = plan.anchor_mm(d)
        t_after = clock.now() - t_start  # session times, as recorded: a replay computes the same
        temp_after = env.material_temp_of(leg)
        t_rel = t_abs - t_start
        run_up_s = plan.overrun_mm / speed
        # the screw heats by its travel: from the start of the motion (the first pass of a leg:
        # from its first sample, when the reading before it is taken as holding) to its end
        t_heat0 = t_rel[0] if prev_temp is None or prev_temp[0] is None else t_rel[0] - run_up_s
        t_heat1 = t_rel[-1] + run_up_s

        def temp_c(t_s: float) -> float:
            """The material temperature at a sample, interpolated over the pass's motion between
            the reading before it (after the pass before, or before the first pass of the leg)
            and the one after it; a pass heats the screw within seconds, and the readings are
            normalised to 20 degC with it."""
            if prev_temp is None or not t_heat1 > t_heat0:
                return temp_after
            f = min(max((t_s - t_heat0) / (t_heat1 - t_heat0), 0.0), 1.0)
            return prev_temp[1] + (temp_after - prev_temp[1]) * f

        for p in pas:
            is_anchor = abs(p.target_mm - anchor_mm) < 1e-9
            r = anchor_reading if is_anchor else readings[by_target[round(p.target_mm, 9)]]
            if is_anchor:  # read at rest: the drive's own position, time of the reading, no speed
                record = point_record(p, r, env, drive_position_mm=status.position_mm, time_s=t_after,
                                      material_temp_c=temp_after, load_n=status.load_n, flags=flags | FLAG_ANCHOR,
                                      speed_mm_s=float("nan"))
            else:  # the compare fires when position actual passes the target: that is the drive's position
                record = point_record(p, r, env, drive_position_mm=p.target_mm, time_s=r.t_s - t_start,
                                      material_temp_c=temp_c(r.t_s - t_start), load_n=status.load_n, flags=flags,
                                      speed_mm_s=float(v[by_target[round(p.target_mm, 9)]]))
            done += 1
            planned_left[leg] -= 1
            rows.append(record)
            yield ev.PointMeasured(record, done, total)
        prev_temp = (t_after, temp_after)
        in_place = True
        if plan.adaptive or plan.probe_target_um > 0:
            measured.setdefault(leg, []).append(np.concatenate([point_row(r) for r in rows]))
        if plan.adaptive:
            if run % 2 == 0 and planned_left[leg] > 0:  # after every cycle (a direction pair)
                rule = rules.setdefault(leg, AdaptiveRule.for_plan(plan, (materials or {}).get(leg)))
                reason = rule.after_cycle(np.concatenate(measured[leg]).astype(POINT_DTYPE), leg)
                if reason is not None:
                    stopped.add(leg)
                    skipped = planned_left[leg]
                    total -= skipped
                    yield ev.PassesStopped(leg, run // 2, reason, tuple(rule.heldout_um), rule.noise_floor_um, skipped)
                    yield ev.Message(f"leg {leg}: adaptive stop after {run // 2} cycles: {reason}; "
                                     f"{skipped} planned points not needed", "info")
            elif planned_left[leg] == 0:
                rule = rules.setdefault(leg, AdaptiveRule.for_plan(plan, (materials or {}).get(leg)))
                reason = f"the plan's most cycles ({plan.cycles}) measured before the held-out RMS stopped improving"
                yield ev.PassesStopped(leg, run // 2, reason, tuple(rule.heldout_um), rule.noise_floor_um, 0)
                yield ev.Message(f"leg {leg}: {reason}", "info")
    return done
