"""Sweep plans: which targets, in which order, how often, on which legs.

A plan is data (JSON-able via `to_dict`/`from_dict`) and expands into an ordered list of
`PlanPoint`s. The order is the ISO 230-2 linear cycle: for every leg, `cycles` times an upward
pass over all targets (direction +1, odd run numbers) followed by a downward pass (direction -1,
even run numbers). Each pass starts with an approach from `overrun_mm` beyond its first target,
so every target is reached from the pass's direction and reversal happens outside the measured
range.

Positions are mm relative to the leg's mid-stroke reference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, Iterable, Iterator

import numpy as np

from procedures.vocabulary import PlanError
from procedures.io.numbers import parse_finite

PAPER_STEP_MM = 0.5
PAPER_HALF_STROKE_MM = 90.0


PROBE_GAP_MM = 1.0
"""Reversal probes: the downward reading this far below the upward one (a short move each way)."""
PROBE_AVERAGING_S = 0.3
"""Reversal probes: laser averaging per reading, s (0.3 s: the white noise below the pass offsets
the probes sample, at a third of the anchors' 1 s)."""
PROBE_MIN_PAIRS = 12
"""Reversal probes with a target (SweepPlan.probe_target_um): the fewest pairs, and the pairs of one
climb (or descent) of the stroke. Why 12: the pairs' scatter, from which the standard error is
judged, is itself known only to 1 / sqrt(2 (n - 1)) of itself, 21 % at 12 pairs (27 % at 8); a
rule that stopped on a scatter that happened to come out low would stop with too few pairs
(procedures/acquisition/probe_rule.py)."""


@dataclass(frozen=True)
class PlanPoint:
    index: int  # position in the whole plan, unique: the key for resume
    leg: int
    run: int  # one-direction pass number within the leg, 1-based
    direction: int  # +1 / -1
    target_mm: float

    def approach_mm(self, overrun_mm: float) -> float:
        """Where to start so the target is approached in this point's direction."""
        return self.target_mm - self.direction * overrun_mm


@dataclass(frozen=True)
class SweepPlan:
    """A bidirectional sweep over `targets_mm` (ascending) on each of `legs`.

    `dwell_s`: settle time at each target before reading; `averaging_s`: interferometer
    averaging per reading; `overrun_mm`: distance beyond the end targets before reversing.

    On-the-fly capture (docs/onthefly.md) when `speeds_mm_s` is not empty: each pass runs
    through all targets at constant speed without stopping, and the interferometer latches a
    reading as the drive's position passes each target (position compare), so the targets must
    be evenly spaced and `overrun_mm` is the run-up to full speed. Cycle c runs at
    `speeds_mm_s[(c - 1) % n]`, the order reversed every other round of n cycles (a slow drift
    then weighs on every speed alike). `adaptive`: repeat rounds only until the cross-validated
    held-out error stops improving (procedures/acquisition/adaptive.py), `cycles` being the most.

    `reversal_probes` (on the fly only): after a leg's passes, that many stop-and-go reversal
    pairs (docs/onthefly.md, "Reversal probes"): a reading approached upwards at `probe_up_mm(k)`,
    then one approached downwards `probe_gap_mm` below it, and so on up the stroke, every reading
    right after a reversal (so each carries a pass offset of its own), after `dwell_s`, averaged
    over `probe_averaging_s`. They fix the table's reversal (procedures/fit/reversal_probes.py):
    each pair is one more sample of the pass-to-pass offsets that decide it, at a few seconds
    each instead of a whole pair of passes. Each reading is a run of its own (run numbers after
    the passes), flagged FLAG_PROBE.

    `probe_target_um` > 0 (the adaptive probe count, procedures/acquisition/probe_rule.py): the
    sweep takes pairs only until the reversal's standard error reaches it, at least
    `PROBE_MIN_PAIRS`, at most `reversal_probes` (then the most). The pairs then lie in blocks of
    `PROBE_MIN_PAIRS`, each spread over the whole stroke, climbing and descending in turn, each
    block's positions between the last ones' (`probe_up_mm`): wherever the rule stops, the pairs
    taken cover the stroke. 0: all `reversal_probes` pairs, in one climb.
    """

    kind: str
    targets_mm: tuple[float, ...]
    cycles: int
    legs: tuple[int, ...] = (1,)
    overrun_mm: float = 2.0
    dwell_s: float = 1.0
    averaging_s: float = 0.1
    notes: tuple[str, ...] = field(default=())
    speeds_mm_s: tuple[float, ...] = field(default=())
    adaptive: bool = False
    reversal_probes: int = 0
    probe_gap_mm: float = PROBE_GAP_MM
    probe_averaging_s: float = PROBE_AVERAGING_S
    probe_target_um: float = 0.0

    def __post_init__(self) -> None:
        t = np.asarray(self.targets_mm, dtype=float)
        if t.size < 2:
            raise PlanError(f"a sweep needs at least 2 targets, got {t.size}")
        if not np.all(np.isfinite(t)):
            raise PlanError("sweep targets must be finite numbers")
        if np.any(np.diff(t) <= 0):
            raise PlanError("sweep targets must be strictly increasing (no duplicates)")
        if self.cycles < 1:
            raise PlanError(f"cycles must be >= 1, got {self.cycles}")
        if not self.legs or any(leg < 1 for leg in self.legs) or len(set(self.legs)) != len(self.legs):
            raise PlanError(f"legs must be distinct numbers >= 1, got {list(self.legs)}")
        if self.overrun_mm < 0 or self.dwell_s < 0 or self.averaging_s < 0:
            raise PlanError("overrun_mm, dwell_s and averaging_s must be >= 0")
        if self.speeds_mm_s:
            if not all(math.isfinite(v) and v > 0 for v in self.speeds_mm_s):
                raise PlanError(f"on-the-fly speeds must be positive mm/s, got {list(self.speeds_mm_s)}")
            steps = np.diff(t)
            if np.ptp(steps) > 1e-6:
                raise PlanError("on-the-fly capture needs evenly spaced targets (the drive's position compare "
                                "fires every step); use a uniform step")
        elif self.adaptive:
            raise PlanError("adaptive stopping needs an on-the-fly plan (speeds_mm_s)")
        if self.reversal_probes:
            if not self.speeds_mm_s:
                raise PlanError("reversal probes belong to an on-the-fly plan (a stop-and-go plan's passes are its probes)")
            if self.reversal_probes < 1 or not (0 < self.probe_gap_mm < t[-1] - t[0]) or self.probe_averaging_s < 0:
                raise PlanError(f"reversal probes: a count >= 1, a gap between 0 and the stroke, an averaging >= 0 "
                                f"(got {self.reversal_probes}, {self.probe_gap_mm:g} mm, {self.probe_averaging_s:g} s)")
        if not (math.isfinite(self.probe_target_um) and self.probe_target_um >= 0):
            raise PlanError(f"reversal probes: the standard error to reach must be >= 0 um (0: take every pair), "
                            f"got {self.probe_target_um!r}")

    # -- on-the-fly ----------------------------------------------------------------------
    @property
    def onthefly(self) -> bool:
        return bool(self.speeds_mm_s)

    @property
    def step_mm(self) -> float:
        return float(self.targets_mm[1] - self.targets_mm[0])

    def speed_of_run(self, run: int) -> float:
        """Speed (mm/s, > 0) of pass `run` of an on-the-fly plan (0.0: a stop-and-go plan)."""
        if not self.speeds_mm_s:
            return 0.0
        n = len(self.speeds_mm_s)
        c = (run - 1) // 2  # 0-based cycle
        rnd, k = divmod(c, n)
        order = self.speeds_mm_s if rnd % 2 == 0 else self.speeds_mm_s[::-1]
        return float(order[k])

    # -- expansion -----------------------------------------------------------------------
    @property
    def points_per_leg(self) -> int:
        return 2 * self.cycles * self.points_per_pass + 2 * self.reversal_probes

    def is_probe_run(self, run: int) -> bool:
        """Whether pass `run` of a leg is a reversal probe (runs after the plan's cycles)."""
        return run > 2 * self.cycles

    @property
    def probe_block(self) -> int:
        """Probe pairs per climb (or descent) of the stroke: all of them with a fixed count, else
        `PROBE_MIN_PAIRS` (SweepPlan)."""
        n = self.reversal_probes
        return min(PROBE_MIN_PAIRS, n) if self.probe_target_um > 0 else n

    def probe_up_mm(self, k: int) -> float:
        """Where probe pair `k` (0-based) reads approaching upwards: the pairs spread evenly over
        the stroke, the downward reading `probe_gap_mm` below (so every target lies inside it).
        In blocks (`probe_block`): block b climbs when b is even and descends when odd, its pairs
        offset from the block's spacing by (0.5 + van der Corput(b)) mod 1 (0.5, 0, 0.75, 0.25, ...),
        so every block falls between the ones before it. One block (a fixed count): evenly up the
        stroke, at (k + 0.5) / n of it."""
        lo, hi = self.targets_mm[0] + self.probe_gap_mm, self.targets_mm[-1]
        size = self.probe_block
        b, j = divmod(k, size)
        n = min(size, self.reversal_probes - b * size)  # pairs in this block (the last may be short)
        if b % 2:
            j = n - 1 - j  # a descending block
        vdc, base, x = 0.0, 0.5, b
        while x:
            x, bit = divmod(x, 2)
            vdc += bit * base
            base /= 2
        return float(lo + (hi - lo) * (j + (0.5 + vdc) % 1.0) / n)

    def probe_via_mm(self, run: int) -> float | None:
        """Where probe `run` is approached from when the reading before it in the plan
        (`before_probe_mm`) lies on the probe's other side (a descending block's upward reading,
        below the pair before): `probe_gap_mm` short of it, so it is still reached in its
        direction, after a reversal. None: approached straight from the reading before."""
        j = run - 2 * self.cycles - 1
        k, down = divmod(j, 2)
        target = self.probe_up_mm(k) - (self.probe_gap_mm if down else 0.0)
        d = -1 if down else 1
        if (target - self.before_probe_mm(run)) * d > 1e-9:
            return None
        return target - d * self.probe_gap_mm

    def before_probe_mm(self, run: int) -> float:
        """Where the plan's order leaves the axis before probe `run` (a probe run of a leg), reached
        moving against the probe's direction: the reading before it, i.e. the pair's upward
        reading before its downward one, the previous pair's downward reading before an upward
        one, and the leg's last (downward) pass's anchor before the first. A probe approached from
        here follows a reversal, as in an uninterrupted run (onthefly.py re-approaches a resumed or
        retried probe this way)."""
        j = run - 2 * self.cycles - 1  # 0-based reading among the leg's probes
        k, down = divmod(j, 2)
        if down:
            return self.probe_up_mm(k)
        return self.anchor_mm(-1) if k == 0 else self.probe_up_mm(k - 1) - self.probe_gap_mm

    @property
    def points_per_pass(self) -> int:
        """Targets of a pass, plus on the fly its anchor (a reading at rest at the pass's end)."""
        return len(self.targets_mm) + (1 if self.speeds_mm_s else 0)

    def anchor_mm(self, direction: int) -> float:
        """On the fly: where a pass in `direction` ends, at rest, and reads its anchor: the
        overrun beyond its last target (docs/onthefly.md)."""
        last = self.targets_mm[-1] if direction > 0 else self.targets_mm[0]
        return float(last + direction * self.overrun_mm)

    @property
    def total_points(self) -> int:
        return self.points_per_leg * len(self.legs)

    def points(self) -> list[PlanPoint]:
        return list(self.iter_points())

    def iter_points(self) -> Iterator[PlanPoint]:
        """The plan's points in order, one at a time (a huge plan is never a list in memory)."""
        up = self.targets_mm
        down = up[::-1]
        index = 0
        for leg in self.legs:
            run = 0
            for _ in range(self.cycles):
                for direction, seq in ((1, up), (-1, down)):
                    run += 1
                    for target in seq:
                        yield PlanPoint(index, leg, run, direction, float(target))
                        index += 1
                    if self.speeds_mm_s:  # the pass's anchor, read at rest where it ends
                        yield PlanPoint(index, leg, run, direction, self.anchor_mm(direction))
                        index += 1
            for k in range(self.reversal_probes):  # after a downward pass: each reading follows a reversal
                up_mm = self.probe_up_mm(k)
                for direction, target in ((1, up_mm), (-1, up_mm - self.probe_gap_mm)):
                    run += 1
                    yield PlanPoint(index, leg, run, direction, float(target))
                    index += 1

    def travel_range_mm(self) -> tuple[float, float]:
        return (self.targets_mm[0] - self.overrun_mm, self.targets_mm[-1] + self.overrun_mm)

    def validate_limits(self, min_mm: float, max_mm: float, leg: int | None = None) -> None:
        """Refuse the plan before anything moves if any commanded position (targets and
        overrun approach positions) lies outside the soft limits [min_mm, max_mm]."""
        lo, hi = self.travel_range_mm()
        where = f" of leg {leg}" if leg is not None else ""
        if lo < min_mm - 1e-9:
            raise PlanError(
                f"the plan moves to {lo:.3f} mm (first target {self.targets_mm[0]:.3f} mm minus the "
                f"{self.overrun_mm:g} mm overrun), below the soft limit {min_mm:.3f} mm{where}; "
                "shrink the target range or the overrun"
            )
        if hi > max_mm + 1e-9:
            raise PlanError(
                f"the plan moves to {hi:.3f} mm (last target {self.targets_mm[-1]:.3f} mm plus the "
                f"{self.overrun_mm:g} mm overrun), above the soft limit {max_mm:.3f} mm{where}; "
                "shrink the target range or the overrun"
            )

    def estimated_duration_s(self, velocity_mm_s: float) -> float:
        """Rough duration: travel at `velocity_mm_s` plus dwell and averaging at each point (on
        the fly: each pass at its own speed, and the return to its start)."""
        span = self.targets_mm[-1] - self.targets_mm[0] + 2 * self.overrun_mm
        return estimate_duration_s(span, len(self.targets_mm), self.cycles, len(self.legs), self.dwell_s,
                                   self.averaging_s, self.speeds_mm_s, velocity_mm_s, self.reversal_probes,
                                   self.probe_block)

    # -- serialisation -------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        # field by field, not asdict(): that copies every target one by one (seconds for a huge plan)
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        d["targets_mm"] = np.asarray(self.targets_mm, dtype=float).tolist()
        d["legs"] = list(self.legs)
        d["notes"] = list(self.notes)
        d["speeds_mm_s"] = list(self.speeds_mm_s)
        if self.speeds_mm_s:  # on the fly; a stop-and-go plan is stored as before these fields existed
            d["speeds_mm_s"] = [float(v) for v in self.speeds_mm_s]
        else:
            del d["speeds_mm_s"], d["adaptive"]
        if not self.reversal_probes:  # stored as before probes existed
            del d["reversal_probes"], d["probe_gap_mm"], d["probe_averaging_s"]
        if not self.probe_target_um:  # a fixed count: stored as before the adaptive count existed
            del d["probe_target_um"]
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "SweepPlan":
        try:
            return cls(
                kind=str(d["kind"]),
                targets_mm=tuple(float(x) for x in d["targets_mm"]),
                cycles=int(d["cycles"]),
                legs=tuple(int(x) for x in d["legs"]),
                overrun_mm=float(d.get("overrun_mm", 2.0)),
                dwell_s=float(d.get("dwell_s", 1.0)),
                averaging_s=float(d.get("averaging_s", 0.1)),
                notes=tuple(d.get("notes", ())),
                speeds_mm_s=tuple(float(v) for v in d.get("speeds_mm_s", ())),
                adaptive=bool(d.get("adaptive", False)),
                reversal_probes=int(d.get("reversal_probes", 0)),
                probe_gap_mm=float(d.get("probe_gap_mm", PROBE_GAP_MM)),
                probe_averaging_s=float(d.get("probe_averaging_s", PROBE_AVERAGING_S)),
                probe_target_um=float(d.get("probe_target_um", 0.0)),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise PlanError(f"the stored sweep plan is incomplete or malformed ({exc!r})") from exc


def estimate_duration_s(travel_mm: float, n_targets: int, cycles: int, n_legs: int, dwell_s: float,
                        averaging_s: float, speeds_mm_s: tuple[float, ...] = (), velocity_mm_s: float = 10.0,
                        reversal_probes: int = 0, probe_block: int = 0) -> float:
    """A plan's rough time on the rig, s, from its figures alone (procedures/acquisition/plan_size.py sizes a
    plan with it before building one): `travel_mm` per pass (targets and overrun); stop-and-go,
    travel at `velocity_mm_s` plus dwell and averaging at every target; on the fly (`speeds_mm_s`),
    each pass at its own speed plus its return and its anchor's dwell and averaging, then the
    `reversal_probes` pairs (a climb through the stroke at the faster speed, two short moves, dwells
    and readings a pair; in blocks of `probe_block` pairs, a climb or descent each, a descending
    block's pairs with a third short move: SweepPlan.probe_up_mm)."""
    if speeds_mm_s:
        n = len(speeds_mm_s)
        blocks = -(-reversal_probes // probe_block) if probe_block else 1
        descending = sum(min(probe_block, reversal_probes - b * probe_block) for b in range(1, blocks, 2))
        per_leg = reversal_probes * 2 * (0.5 + dwell_s + PROBE_AVERAGING_S) + 0.5 * descending + (
            blocks * travel_mm / max(speeds_mm_s) if reversal_probes else 0.0)
        for c in range(cycles):  # the speed of cycle c, as SweepPlan.speed_of_run
            rnd, k = divmod(c, n)
            speed = (speeds_mm_s if rnd % 2 == 0 else speeds_mm_s[::-1])[k]
            per_leg += 2 * (travel_mm / speed + 1.0 + dwell_s + averaging_s)
        return per_leg * n_legs
    per_leg = 2 * cycles * (travel_mm / max(velocity_mm_s, 1e-9) + n_targets * (dwell_s + averaging_s))
    return per_leg * n_legs


# -- plan builders ---------------------------------------------------------------------------

def _lead_warning(step_mm: float, lead_mm: float | None) -> list[str]:
    if not lead_mm:
        return []
    ratio = step_mm / lead_mm
    if abs(ratio - round(ratio)) < 1e-6 and round(ratio) >= 1:
        return [
            f"uniform spacing {step_mm:g} mm is a multiple of the {lead_mm:g} mm screw lead: the "
            "once-per-revolution error is sampled at one phase only (ISO 230-2 advises against it)"
        ]
    return []


def uniform_targets(min_mm: float, max_mm: float, step_mm: float) -> tuple[float, ...]:
    if step_mm <= 0:
        raise PlanError(f"step must be > 0 mm, got {step_mm}")
    if max_mm <= min_mm:
        raise PlanError(f"target range is empty: {min_mm} .. {max_mm} mm")
    n = int(math.floor((max_mm - min_mm) / step_mm + 1e-9)) + 1
    # numpy: the same values as round(min_mm + i * step_mm, 9) one by one, a hundred times faster
    return tuple(np.round(min_mm + np.arange(n) * step_mm, 9).tolist())


def irregular_targets(min_mm: float, max_mm: float, n_targets: int, seed: int = 0) -> tuple[float, ...]:
    """ISO 230-2 style irregular spacing: nominal uniform positions, the inner ones shifted by a
    deterministic pseudo-random fraction (up to +/-30 %) of the spacing, ends kept."""
    if n_targets < 2:
        raise PlanError(f"need at least 2 targets, got {n_targets}")
    base = np.linspace(min_mm, max_mm, n_targets)
    step = (max_mm - min_mm) / (n_targets - 1)
    rng = np.random.default_rng(seed)
    shift = rng.uniform(-0.3, 0.3, n_targets) * step
    shift[0] = shift[-1] = 0.0
    return tuple(float(round(x, 4)) for x in base + shift)


def iso230_plan(
    legs: Iterable[int] = (1,),
    min_mm: float = -90.0,
    max_mm: float = 90.0,
    n_targets: int | None = None,
    step_mm: float | None = None,
    cycles: int = 5,
    irregular: bool = True,
    lead_mm: float | None = 5.0,
    seed: int = 0,
    overrun_mm: float = 2.0,
    dwell_s: float = 1.0,
    averaging_s: float = 0.1,
) -> SweepPlan:
    """The ISO 230-2 standard test cycle: at least 5 targets and at least 5 per metre,
    bidirectional, `cycles` (standard: 5) approaches per direction, overrun before reversing."""
    length_m = (max_mm - min_mm) / 1000.0
    minimum = max(5, int(math.ceil(5 * length_m)) + 1)
    notes: list[str] = []
    if step_mm is not None:
        targets = uniform_targets(min_mm, max_mm, step_mm)
        notes += _lead_warning(step_mm, lead_mm)
    else:
        n = n_targets or max(minimum, 11)
        targets = irregular_targets(min_mm, max_mm, n, seed) if irregular else uniform_targets(min_mm, max_mm, (max_mm - min_mm) / (n - 1))
        if not irregular:
            notes += _lead_warning((max_mm - min_mm) / (n - 1), lead_mm)
    if len(targets) < minimum:
        notes.append(f"ISO 230-2 asks for at least {minimum} targets over this length; the plan has {len(targets)}")
    if cycles < 5:
        notes.append(f"ISO 230-2 asks for 5 approaches per direction; the plan has {cycles}")
    return SweepPlan("iso230-2", targets, cycles, tuple(legs), overrun_mm, dwell_s, averaging_s, tuple(notes))


def paper_plan(legs: Iterable[int] = (1, 2, 3, 4, 5, 6), cycles: int = 6, overrun_mm: float = 2.0,
               dwell_s: float = 1.0, averaging_s: float = 0.1) -> SweepPlan:
    """The seed paper's sweep: 361 targets, -90..+90 mm at 0.5 mm, six sets per leg (here as six
    bidirectional cycles, so direction effects are visible)."""
    targets = uniform_targets(-PAPER_HALF_STROKE_MM, PAPER_HALF_STROKE_MM, PAPER_STEP_MM)
    return SweepPlan("paper", targets, cycles, tuple(legs), overrun_mm, dwell_s, averaging_s)


ONTHEFLY_SPEEDS_MM_S = (10.0, 20.0)
"""Two speeds, so the speed-proportional dynamic error can be extrapolated to standstill."""
ONTHEFLY_OVERRUN_MM = 4.0  # run-up to 20 mm/s: v^2/2a + v*a/(2 jerk) = 2.5 mm at 100 mm/s^2, 2000 mm/s^3


def onthefly_plan(legs: Iterable[int] = (1,), cycles: int = 6, speeds_mm_s: tuple[float, ...] = ONTHEFLY_SPEEDS_MM_S,
                  step_mm: float = PAPER_STEP_MM, min_mm: float = -PAPER_HALF_STROKE_MM,
                  max_mm: float = PAPER_HALF_STROKE_MM, overrun_mm: float = ONTHEFLY_OVERRUN_MM,
                  adaptive: bool = False, dwell_s: float = 1.0, averaging_s: float = 1.0,
                  reversal_probes: int = 0, probe_target_um: float = 0.0) -> SweepPlan:
    """On-the-fly capture at the paper's 361 positions (0.5 mm), `cycles` bidirectional passes
    cycling through `speeds_mm_s`; `adaptive` stops a leg's passes once the held-out error of
    its table stops improving (then `cycles` is the most). Nothing stops at the targets; each
    pass ends at rest `overrun_mm` beyond its last target and reads an anchor there after
    `dwell_s` (settling) with `averaging_s` averaging: a static reading sharing the pass's offset,
    from which the speed-dependent error is found (procedures/fit/dynamic.py). `reversal_probes`:
    stop-and-go reversal pairs after each leg's passes (SweepPlan), which fix the table's reversal;
    `probe_target_um` > 0: only until its standard error reaches it (`reversal_probes` the most)."""
    if len(speeds_mm_s) < 2 or len(set(speeds_mm_s)) < 2:
        raise PlanError("on-the-fly capture needs two different speeds, to separate the speed-dependent error")
    if cycles < len(speeds_mm_s):
        raise PlanError(f"an on-the-fly plan needs at least {len(speeds_mm_s)} cycles (one per speed), got {cycles}")
    targets = uniform_targets(min_mm, max_mm, step_mm)
    kind = "onthefly-adaptive" if adaptive else "onthefly"
    notes = _lead_warning(step_mm, 5.0)
    return SweepPlan(kind, targets, cycles, tuple(legs), overrun_mm, dwell_s, averaging_s, tuple(notes),
                     tuple(float(v) for v in speeds_mm_s), adaptive, reversal_probes,
                     probe_target_um=probe_target_um)


def targets_from_file(path) -> tuple[float, ...]:
    """Targets from a text file: one number (mm) per line, or a CSV with a `target_mm` column.
    Blank lines and lines starting with # are ignored."""
    from pathlib import Path

    p = Path(path)
    lines = p.read_text().splitlines()
    values: list[float] = []
    col = None
    for lineno, raw in enumerate(lines, start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        cells = [c.strip() for c in line.split(",")]
        if col is None and "target_mm" in cells:
            col = cells.index("target_mm")
            continue
        cell = cells[col if col is not None else 0]
        values.append(parse_finite(cell, f"{p}: line {lineno}: target", PlanError, hint=" (mm expected)", sep=" "))
    if not values:
        raise PlanError(f"{p}: no targets found (one number in mm per line, or a target_mm column)")
    s = sorted(values)
    if len(set(s)) != len(s):
        raise PlanError(f"{p}: duplicate targets")
    return tuple(s)


def parse_legs(text: str) -> tuple[int, ...]:
    """'1-6' -> (1..6); '1,3,5' -> (1,3,5); '2' -> (2,)."""
    legs: list[int] = []
    try:
        for part in text.split(","):
            part = part.strip()
            if "-" in part:
                a, b = part.split("-", 1)
                legs.extend(range(int(a), min(int(b), 7) + 1))  # beyond 6: refused below, never listed
            elif part:
                legs.append(int(part))
    except ValueError:
        raise PlanError(f"legs {text!r}: use a number, a range like 1-6, or a list like 1,3,5") from None
    if not legs or any(leg < 1 or leg > 6 for leg in legs):
        raise PlanError(f"legs {text!r}: leg numbers run from 1 to 6")
    return tuple(dict.fromkeys(legs))
