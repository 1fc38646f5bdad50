"""The transports' latency on a bench, apart from the leg's lag (docs/interferometer-protocol.md,
"Time stamps" and "Measuring the latency"; bench/bench_latency.py runs it on the simulated rig).

An on-the-fly pass puts two streams on the station's clock: the drive's position actual, polled
over Modbus and stamped at the middle of each request (`ModbusAxis.move_traced`), and the
laser's readings, latched at the drive's compare pulse (the station's own laser: a wire, no
transport in the time) or streamed and stamped on the stream's frame grid (the µLine-F1,
`LineF1Interferometer.stream_samples`). Three figures, each from what sets it alone:

1. The Modbus poll's round trip (request sent to response in, on the station's clock) and its
   spread, at rest: `Spread` of `polls` polls of position actual alone (`poll_position`), and the
   same of the polls of the traced passes. The middle stamp is right when the request and the
   reply take as long; it is off by at most half the round trip (the asymmetry), and it scatters
   by the round trip's spread.
2. The laser stream's arrival jitter against its own frame grid (a streaming laser): `stream_s`
   seconds at rest, each distance frame's arrival less its number x the period; the floor of that
   (a line through its lowest values, second by second: its slope is how far the instrument's
   rate is from the nominal one, ppm) is the grid; the jitter is what lies above it
   (`StreamJitter`). The grid stamps remove it; the floor's constant part is not seen here.
3. The speed lag: passes at two speeds or more, both directions, `cycles` times; each pass's
   readings at `targets` targets (aligned as an on-the-fly pass aligns them,
   procedures.acquisition.onthefly.align_stream, or latched at the compare pulses), and an
   anchor read at rest where the pass ended. The pass's mean error less its anchor cancels the
   pass's offset; its slope over the signed speed, per direction, is the speed lag
   (`DirectionLag`, ms: um per mm/s). A reading late by d against the drive's polls is off by
   -v x d; the leg lagging its encoder by L is off by -v x L: a pass sees L + d, and both flip
   with the direction. No pass can tell them apart (a delay and a small first-order lag have the
   same effect on any motion slower than the lag: the stop, the start, a dwell's step response
   included); the drive's following error cannot either (it is the encoder behind the demand,
   not the leg behind the encoder, and the passes align on the encoder). What tells them apart
   is a reference without one of them: the same leg measured with a laser latched by the drive's
   compare pulse has L alone, so `transport_delay(streamed, latched)` = d; a pass with the
   reflector on the drive's nut (no leg between) has d alone. Per direction both estimates of d
   must agree (the delay does not know the direction; the leg's lag may): their difference is
   the check.

Safety: the stroke is checked against the drive's soft limits before any motion; an abort, a
fault or any other exit stops the axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterator

import numpy as np

from drivers.interfaces import (
    CapturingInterferometer,
    Clock,
    DriverError,
    Interferometer,
    PositionCompareAxis,
    ServoAxis,
    StreamingInterferometer,
    TracingAxis,
)
from procedures.acquisition.onthefly import TRACE_INTERVAL_S, CaptureShort, align_stream
from procedures.engine import events as ev
from procedures.engine.control import RunControl
from procedures.vocabulary import InputError


@dataclass(frozen=True)
class Spread:
    """A set of times, ms: how many, median, 95th percentile, largest, smallest, standard deviation."""

    count: int
    median_ms: float
    p95_ms: float
    max_ms: float
    min_ms: float
    std_ms: float

    @classmethod
    def of(cls, values_s) -> "Spread":
        v = np.asarray(values_s, dtype=float) * 1000.0
        if v.size == 0:
            return cls(0, math.nan, math.nan, math.nan, math.nan, math.nan)
        return cls(int(v.size), float(np.median(v)), float(np.percentile(v, 95)), float(v.max()), float(v.min()),
                   float(v.std(ddof=1)) if v.size > 1 else math.nan)

    def text(self) -> str:
        return (f"median {self.median_ms:.3f} ms, 95 % {self.p95_ms:.3f} ms, max {self.max_ms:.3f} ms, "
                f"s {self.std_ms:.3f} ms ({self.count})")


@dataclass(frozen=True)
class StreamJitter:
    """A streaming laser's arrivals at rest against its frame grid: `frames` received over
    `span_s`, `lost` numbers missing among them, `drift_ppm` how much longer the instrument's
    period is than `period_s` on the station's clock, `jitter` the arrivals above the grid's floor."""

    frames: int
    lost: int
    span_s: float
    period_s: float
    drift_ppm: float
    jitter: Spread


@dataclass(frozen=True)
class DirectionLag:
    """The speed lag of one direction (+1 up, -1 down), ms (= um of error per mm/s, the sign
    such that a reading lagging behind the drive is positive), with its standard error (NaN with
    as many passes as unknowns), from `passes` passes at `speeds_mm_s`."""

    direction: int
    lag_ms: float
    stderr_ms: float
    passes: int
    speeds_mm_s: tuple[float, ...]


@dataclass(frozen=True)
class LatencyReport:
    """What `measure_latency` measured on `leg` with a laser that is `laser` ("latched": at the
    drive's compare pulse; "streamed": aligned on the clock)."""

    leg: int
    laser: str
    poll_rest: Spread
    poll_traced: Spread | None
    stream: StreamJitter | None
    lags: tuple[DirectionLag, ...]

    @property
    def lag_ms(self) -> float:
        """The speed lag over both directions (their mean), ms."""
        return float(np.mean([d.lag_ms for d in self.lags]))

    @classmethod
    def from_dict(cls, data: dict, where: str = "latency report") -> "LatencyReport":
        """The report `dataclasses.asdict` made (a saved one, e.g. the latched reference)."""
        try:
            stream = data.get("stream")
            traced = data.get("poll_traced")
            return cls(int(data["leg"]), str(data["laser"]), Spread(**data["poll_rest"]),
                       Spread(**traced) if traced else None,
                       StreamJitter(**{**stream, "jitter": Spread(**stream["jitter"])}) if stream else None,
                       tuple(DirectionLag(**{**d, "speeds_mm_s": tuple(d["speeds_mm_s"])}) for d in data["lags"]))
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise InputError(f"{where}: not a latency report ({type(exc).__name__}: {exc}); save one with "
                             "bench/bench_latency.py --save") from None


@dataclass(frozen=True)
class TransportDelay:
    """The constant delay of a streamed laser's stamps behind the drive's polls, ms: the
    streamed speed lag less the latched one (the leg's own), per direction and their mean, with
    the mean's standard error; `disagreement_ms` the difference between the directions' (the
    delay has no direction: more than a few standard errors means something else differs)."""

    delay_ms: float
    stderr_ms: float
    per_direction_ms: tuple[tuple[int, float], ...]
    disagreement_ms: float


@dataclass(frozen=True)
class LatencyMeasured(ev.Event):
    report: LatencyReport


def transport_delay(streamed: LatencyReport, reference: LatencyReport) -> TransportDelay:
    """d = streamed lag - reference lag per direction (module docstring, 3): `reference` measured
    on the same leg with a laser latched at the compare pulse (or with the reflector on the nut:
    then the reference's lag is the delay of its own laser, and this its difference)."""
    if streamed.leg != reference.leg:
        raise InputError(f"the streamed laser's lag is of leg {streamed.leg}, the reference's of leg "
                         f"{reference.leg}: the delay is their difference on one leg; measure both on the same leg")
    ref = {d.direction: d for d in reference.lags}
    per, var = [], []
    for d in streamed.lags:
        r = ref.get(d.direction)
        if r is None:
            continue
        per.append((d.direction, d.lag_ms - r.lag_ms))
        var.append((d.stderr_ms if math.isfinite(d.stderr_ms) else 0.0) ** 2
                   + (r.stderr_ms if math.isfinite(r.stderr_ms) else 0.0) ** 2)
    if not per:
        raise InputError("the streamed and the reference measurement share no direction of travel: measure both ways")
    values = [v for _, v in per]
    return TransportDelay(float(np.mean(values)), float(math.sqrt(sum(var)) / len(var)), tuple(per),
                          float(max(values) - min(values)))


def stream_jitter(arrivals: list[tuple[int, float]], period_s: float, chunk_s: float = 1.0) -> StreamJitter:
    """The arrival jitter of (frame number, arrival s) against the frames' grid (module docstring, 2)."""
    if len(arrivals) < 2:
        raise InputError(f"{len(arrivals)} stream frames at rest: too few to measure their jitter (is the stream on?)")
    n = np.array([a for a, _ in arrivals], dtype=float)
    t = np.array([b for _, b in arrivals], dtype=float)
    off = t - n * period_s
    # the floor: the lowest offset of each chunk (some frame in it came through fast), a line
    # through them: its slope the instrument's rate against the nominal one
    edges = np.arange(t[0], t[-1] + chunk_s, chunk_s)
    lows_t, lows_o = [], []
    for a, b in zip(edges, edges[1:]):
        inside = (t >= a) & (t < b)
        if inside.any():
            k = int(np.argmin(np.where(inside, off, np.inf)))
            lows_t.append(t[k])
            lows_o.append(off[k])
    slope = float(np.polyfit(lows_t, lows_o, 1)[0]) if len(lows_t) >= 3 else 0.0
    above = off - slope * t
    above -= above.min()
    span = float(t[-1] - t[0])
    lost = int(n[-1] - n[0] + 1 - n.size)
    # arrival - n T grows by (T' - T) a frame, i.e. slope = (T' - T) / T' ~ the period's excess
    return StreamJitter(int(n.size), lost, span, float(period_s), slope * 1e6, Spread.of(above))


def _lag(direction: int, speeds: list[float], y_mm: list[float]) -> DirectionLag:
    """The slope of pass mean less anchor over the signed speed: error = static - v x lag."""
    v, y = np.asarray(speeds, dtype=float), np.asarray(y_mm, dtype=float)
    if np.unique(np.round(np.abs(v), 9)).size < 2:
        raise InputError(f"passes at {sorted(set(np.abs(v).tolist()))} mm/s moving {'up' if direction > 0 else 'down'}: "
                         "the speed lag needs two speeds or more")
    a = np.column_stack([v, np.ones_like(v)])
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    stderr = math.nan
    if v.size > 2:
        resid = y - a @ coef
        cov = np.linalg.inv(a.T @ a) * float(resid @ resid) / (v.size - 2)
        stderr = float(math.sqrt(cov[0, 0])) * 1000.0
    return DirectionLag(direction, float(-coef[0] * 1000.0), stderr, int(v.size),
                        tuple(sorted(set(float(abs(s)) for s in speeds))))


def measure_latency(leg: int, axis: ServoAxis, laser: Interferometer, clock: Clock, control: RunControl,
                    lo_mm: float, hi_mm: float, speeds_mm_s: tuple[float, ...] = (10.0, 20.0), cycles: int = 2,
                    targets: int = 6, overrun_mm: float = 5.0, polls: int = 200, stream_s: float = 10.0,
                    dwell_s: float = 0.5, averaging_s: float = 0.5) -> Iterator[ev.Event]:
    """Measure the transports of `leg` (module docstring) between `lo_mm` and `hi_mm` (inside the
    drive's soft limits; the targets `overrun_mm` inside them), the axis enabled; the laser is
    zeroed at `lo_mm` and left with `averaging_s`. Yields progress messages and `LatencyMeasured`;
    returns the `LatencyReport`."""
    streaming = not isinstance(laser, CapturingInterferometer) and isinstance(laser, StreamingInterferometer)
    if streaming and not isinstance(axis, TracingAxis):
        raise DriverError(f"leg {leg}: the drive's position cannot be traced during a move, so a streamed laser "
                          "cannot be aligned with it")
    if not streaming and not (isinstance(laser, CapturingInterferometer) and isinstance(axis, PositionCompareAxis)):
        raise DriverError(f"leg {leg}: the laser neither streams nor latches at the drive's compare pulse; "
                          "no speed lag can be measured with it")
    speeds = tuple(float(s) for s in speeds_mm_s)
    if len(set(speeds)) < 2 or min(speeds) <= 0 or cycles < 1 or targets < 2 or polls < 2 or overrun_mm <= 0:
        raise InputError(f"speeds {speeds} mm/s, {cycles} cycles, {targets} targets, {polls} polls, overrun "
                         f"{overrun_mm} mm: two distinct speeds > 0 or more, a cycle, two targets, two polls and "
                         "an overrun > 0 are needed")
    lim = axis.limits()
    if not (lim.min_mm <= lo_mm < hi_mm <= lim.max_mm) or hi_mm - lo_mm <= 2 * overrun_mm:
        raise InputError(f"leg {leg}: the stroke {lo_mm:g}..{hi_mm:g} mm must lie inside the drive's soft limits "
                         f"{lim.min_mm:g}..{lim.max_mm:g} mm and be longer than twice the overrun ({overrun_mm:g} mm)")
    if max(speeds) > lim.max_velocity_mm_s:
        raise InputError(f"leg {leg}: {max(speeds):g} mm/s is above the drive's {lim.max_velocity_mm_s:g} mm/s")
    seq_up = np.linspace(lo_mm + overrun_mm, hi_mm - overrun_mm, int(targets))
    step = float(seq_up[1] - seq_up[0])
    period_s = float(getattr(laser, "period_s", 0.04))
    kind = "streamed" if streaming else "latched"
    try:
        yield from control.checkpoint()
        axis.move_to(lo_mm)
        clock.sleep(dwell_s)
        laser.zero(leg)
        laser.set_averaging(averaging_s)

        # 1. the Modbus poll at rest
        poll = getattr(axis, "poll_position", None)
        trips = []
        for _ in range(int(polls)):
            if poll is not None:
                t_a, t_b, _ = poll()
            else:  # a drive without a single-register poll: its status read
                t_a = clock.now()
                axis.status()
                t_b = clock.now()
            trips.append(t_b - t_a)
            clock.sleep(TRACE_INTERVAL_S)
        poll_rest = Spread.of(trips)
        yield ev.Message(f"leg {leg}: Modbus poll at rest: {poll_rest.text()}", "info")

        # 2. the stream at rest
        jitter = None
        if streaming:
            yield from control.checkpoint()
            t0 = clock.now()
            clock.sleep(stream_s)
            t1 = clock.now()
            clock.sleep(4 * period_s)  # the span's last frames are in by then (late by the transport)
            laser.stream_samples(leg, t0, t1)  # type: ignore[attr-defined]  # waits for the span, judges the beam
            arrivals = getattr(laser, "stream_arrivals", None)
            if arrivals is not None:
                jitter = stream_jitter(arrivals(t0, t1), period_s)
                yield ev.Message(f"leg {leg}: stream arrivals over {jitter.span_s:.1f} s: jitter {jitter.jitter.text()}, "
                                 f"rate {jitter.drift_ppm:+.0f} ppm from nominal, {jitter.lost} lost", "info")

        # 3. passes: (signed speed, mean error - anchor error) per direction
        by_dir: dict[int, tuple[list[float], list[float]]] = {1: ([], []), -1: ([], [])}
        traced_trips: list[float] = []
        for cycle in range(int(cycles)):
            for v in speeds:
                for d in (1, -1):
                    yield from control.checkpoint()
                    seq = seq_up if d > 0 else seq_up[::-1]
                    end_mm = hi_mm if d > 0 else lo_mm
                    errors_mm, status = _pass(leg, axis, laser, clock, streaming, seq, d * step, end_mm, v,
                                              period_s, dwell_s)
                    traced_trips += list(getattr(axis, "trace_round_trips_s", []) if streaming else [])
                    anchor_mm = laser.read(leg).position_mm - status.position_mm
                    by_dir[d][0].append(d * v)
                    by_dir[d][1].append(float(np.mean(errors_mm)) - anchor_mm)
            yield ev.Message(f"leg {leg}: cycle {cycle + 1} of {cycles} of the passes at {speeds} mm/s done", "info")
        lags = tuple(_lag(d, *by_dir[d]) for d in (1, -1))
    except BaseException:
        try:
            axis.stop()
        except DriverError:
            pass
        raise
    report = LatencyReport(leg, kind, poll_rest, Spread.of(traced_trips) if traced_trips else None, jitter, lags)
    for lag in lags:
        yield ev.Message(f"leg {leg}: speed lag moving {'up' if lag.direction > 0 else 'down'} with the {kind} laser: "
                         f"{lag.lag_ms:.4f} ms (s {lag.stderr_ms:.4f} ms, {lag.passes} passes)", "info")
    yield LatencyMeasured(report)
    return report


def _pass(leg: int, axis, laser, clock: Clock, streaming: bool, seq: np.ndarray, step_mm: float, end_mm: float,
          speed: float, period_s: float, dwell_s: float):
    """One pass through `seq` to `end_mm` at `speed`: the laser's error at each target (laser
    less drive, mm) and the drive's status at rest after the dwell."""
    if streaming:
        status, trace = axis.move_traced(end_mm, speed, TRACE_INTERVAL_S)
        clock.sleep(max(dwell_s, 4 * period_s))  # the stream is in by then
        t_tr = [t for t, x in trace if min(seq[0], seq[-1]) - abs(step_mm) <= x <= max(seq[0], seq[-1]) + abs(step_mm)]
        if len(t_tr) < 3:
            raise DriverError(f"leg {leg}: {len(t_tr)} drive polls over the targets (the move stopped short)")
        stream = laser.stream_samples(leg, t_tr[0] - 3 * period_s, t_tr[-1] + 3 * period_s)
        readings = align_stream(seq, trace, stream, leg, period_s)
    else:
        n = int(seq.size)
        axis.arm_position_compare(float(seq[0]), step_mm, n)
        laser.arm_capture(leg, n)
        status = axis.move_to(end_mm, velocity_mm_s=speed)
        axis.arm_position_compare(float(seq[0]), step_mm, 0)  # off
        captured, _ = laser.capture_count(leg)
        if captured < n:
            raise CaptureShort(f"leg {leg}: the laser latched {captured} of {n} samples (trigger wiring, or the move "
                               "stopped short)")
        readings = laser.capture_samples(leg, 0, n)
        clock.sleep(dwell_s)
    return [r.position_mm - float(x) for r, x in zip(readings, seq)], status
