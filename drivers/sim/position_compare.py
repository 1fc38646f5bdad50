"""The simulated drive's position-compare output and the trigger line to the interferometer.

A real servo drive compares its position actual (the encoder, in hardware) with a list of
positions and gives a pulse on a digital output at each crossing; the pulse goes by wire to the
laser's trigger input, which latches its reading (docs/onthefly.md). Here the wire is a
`TriggerLine`: the drive calls `pulse(leg, t_s)` with the plant already at the crossing, and the
simulated (or replayed) interferometer's capture takes its sample then.

Compare positions: `start_mm + i * step_mm` for i = 0 .. count - 1, crossed in the direction of
the sign of `step_mm`. Positions already passed when armed fire at the first motion that passes
them (the same as a real compare unit seeing the counter go by).
"""

from __future__ import annotations

from typing import Callable


class TriggerLine:
    """The wire from the drives' compare outputs to the interferometer's trigger inputs."""

    def __init__(self) -> None:
        self._listeners: list[Callable[[int, float], None]] = []

    def connect(self, listener: Callable[[int, float], None]) -> None:
        """`listener(leg, t_s)` is called at every pulse (under the rig lock)."""
        self._listeners.append(listener)

    def pulse(self, leg: int, t_s: float) -> None:
        for listener in self._listeners:
            listener(leg, t_s)


class PositionCompare:
    """One drive's compare unit. `arm(start, step, count)`; `due(motion, t_from, t_to)` lists the
    pulses a motion gives between two times as (index, position_mm, t_s, velocity_mm_s)."""

    def __init__(self) -> None:
        self.start_mm = 0.0
        self.step_mm = 0.0
        self.count = 0
        self.fired = 0

    def arm(self, start_mm: float, step_mm: float, count: int) -> None:
        self.start_mm, self.step_mm, self.count, self.fired = float(start_mm), float(step_mm), int(count), 0

    @property
    def armed(self) -> bool:
        return self.fired < self.count and self.step_mm != 0.0

    def next_mm(self) -> float:
        return self.start_mm + self.fired * self.step_mm

    def due(self, motion, t_from: float, t_to: float,
            offset_mm: float | Callable[[float], float] = 0.0) -> list[tuple[int, float, float, float]]:
        """Pulses of `motion` (a drivers.sim.motion.SmoothedMove of the nut) in (t_from, t_to];
        `offset_mm` = position actual minus nut position (the active table's shift): a constant,
        or a function of the compare position (a table applied along the move)."""
        out: list[tuple[int, float, float, float]] = []
        if motion is None or not self.armed:
            return out
        direction = 1.0 if self.step_mm > 0 else -1.0
        if motion.sign != direction:
            return out  # the output counts in one direction only
        t = t_from
        while self.armed:
            pos = self.next_mm()
            shift = offset_mm(pos) if callable(offset_mm) else offset_mm
            t_hit = motion.time_at(pos - shift, t)
            if t_hit is None or t_hit > t_to:
                break
            out.append((self.fired, pos, t_hit, motion.velocity(t_hit)))
            self.fired += 1
            t = t_hit
        return out
