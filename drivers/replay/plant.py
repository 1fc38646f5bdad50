"""The replay plant: what the simulated drive and interferometer read instead of a physical leg.

One `ReplayPlant` per leg follows that leg's recorded points in order (a cursor). The drive
tells it where each move arrived (`arrived(commanded_mm, direction)`); when that is the next
recorded point's target, approached in its direction, the drive reports the recorded load and
position there, and raises the recorded drive fault if one is due. The interferometer asks
`reading()` when the station reads the axis: the recorded beam breaks, time-outs, line noise
and errors come first, in attempt order, then the recorded reading, and the cursor moves on.
A reading asked anywhere else is a mismatch (or, after the last recorded point of a session
that was cut short, the end of the recording).

All methods run under the rig lock shared by both servers (as the simulated plants do).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Callable

from drivers.replay.clock import ReplayClock
from drivers.replay.replay_errors import ReplayMismatch
from drivers.replay.script import ReplayFault, ReplayPoint, ReplayScript
from drivers.states import FaultKind

ONTHEFLY_FAULTS = (FaultKind.BEAM_BREAK, FaultKind.ERROR, FaultKind.TIMEOUT, FaultKind.FRAMING)
"""Faults of an on-the-fly pass a replay reproduces, the laser's: the pass's attempt fails the same
way at the recorded time, at the capture's read-back (a beam break: a sample latched without beam;
an error: the capture comes up short; a time-out or line noise: the count asked is not answered,
or garbled). The recorded text (e.g. a µLine-F1's gap in the stream) is not the replay's. A drive
fault inside a pass is not reproduced (station.services.replay_job refuses such a session)."""


@dataclass(frozen=True)
class LaserAnswer:
    """What the interferometer does for one position query.

    kind: "value" (answer `point`'s reading), "beam" (beam interrupted), "silent" (no reply),
    "garbage" (a corrupted reply), "error" (an ERR reply with `text`), "mismatch" / "end" (an
    ERR reply; the rig keeps the full message)."""

    kind: str
    point: ReplayPoint | None = None
    text: str = ""


class ReplayState:
    """What the legs share: the script, the clock, the count of readings served, the first
    mismatch and the end of the recording."""

    def __init__(self, script: ReplayScript, clock: ReplayClock, target_tol_mm: float = 1e-6):
        self.script = script
        self.clock = clock
        self.target_tol_mm = float(target_tol_mm)
        self.served = 0
        self.last_served: ReplayPoint | None = None
        self.mismatch: ReplayMismatch | None = None
        self.ended = ""  # why the recording ended ("" while it has not)
        self.on_end: Callable[[str], None] | None = None

    @property
    def all_served(self) -> bool:
        return self.served >= self.script.value_points

    def environment(self, plants: dict[int, "ReplayPlant"], axes: int) -> tuple[float, float, float, list[float]]:
        """(air_temp_c, air_pressure_hpa, humidity_pct, material temperature per axis): the air of
        the point served last (the first point before any), each leg's last material temperature."""
        p = self.last_served or self.script.first
        air = (p.air_temp_c, p.air_pressure_hpa, p.humidity_pct) if p else (20.0, 1013.25, 45.0)
        temps = [plants[a].material_temp_c() if a in plants else math.nan for a in range(1, axes + 1)]
        return air[0], air[1], air[2], temps


class ReplayPlant:
    """One leg of a replay. Offers what the simulated drive reads from a `LegPlant` (`x_mm`,
    `direction`, `load_n`, `move`) and what the simulated interferometer uses (`zero_here`)."""

    def __init__(self, leg: int, state: ReplayState):
        self.leg = leg
        self.state = state
        self.points: tuple[ReplayPoint, ...] = state.script.legs.get(leg, ())
        self.x_mm = 0.0
        self.direction = 1
        first = next((p for p in self.points if p.has_value), None)
        self.load_n = first.load_n if first else 0.0
        self.reported_position_mm: float | None = None  # recorded drive position while at a point
        self._cursor = 0
        self._pending: deque = deque(self.points[0].faults if self.points else ())
        self._at: str | None = None  # "cursor": at the next point; "served": still at the point just read
        self._laser_mode: str | None = None  # "silent" / "garbage" until the next move
        self._arrival: tuple[float, int] | None = None  # last (commanded mm, direction)
        self._last_served: ReplayPoint | None = None
        self._failing: ReplayFault | None = None  # a recorded fault of an on-the-fly pass, being replayed

    # -- what LegPlant offers the simulated servers ---------------------------------------------
    def move(self, to_mm: float, t_end_s: float) -> None:
        travel = to_mm - self.x_mm
        if travel:
            self.direction = 1 if travel > 0 else -1
        self.x_mm = float(to_mm)

    def zero_here(self, t_s: float) -> None:
        """The recorded readings are already relative to the zero of the recorded session."""

    def material_temp_c(self, t_s: float | None = None) -> float:
        p = self._last_served or next((q for q in self.points if q.has_value), None)
        return p.material_temp_c if p else math.nan

    # -- the replay ----------------------------------------------------------------------------
    @property
    def current(self) -> ReplayPoint | None:
        """The next recorded point of this leg (None once all are replayed)."""
        return self.points[self._cursor] if self._cursor < len(self.points) else None

    def arrived(self, commanded_mm: float, direction: int) -> int | None:
        """The drive arrived at `commanded_mm`, last moving in `direction`. Returns the code of
        a recorded drive fault to raise now, else None."""
        self._laser_mode = None
        self._arrival = (float(commanded_mm), int(direction))
        p = self.current
        if p is None or p.direction != direction or abs(commanded_mm - p.target_mm) > self.state.target_tol_mm:
            self._at = None
            self.reported_position_mm = None
            return None
        self._at = "cursor"
        if p.has_value:
            self.load_n = p.load_n
            self.reported_position_mm = p.drive_position_mm
        if self._pending and self._pending[0].kind == FaultKind.DRIVE_FAULT:
            fault = self._pending.popleft()
            self.state.clock.set_recorded(fault.time_s)
            return fault.code
        return None

    def reading(self) -> LaserAnswer:
        """What the interferometer answers to a position query of this leg now."""
        if self._laser_mode:
            return LaserAnswer(self._laser_mode)
        if self._at == "served":  # read again without moving: the same reading
            return LaserAnswer("value", self._last_served)
        if self._at != "cursor":
            return self._not_recorded()
        p = self.current
        assert p is not None
        if self._pending:
            fault = self._pending[0]
            if fault.kind == FaultKind.DRIVE_FAULT:
                return self._mismatch(
                    f"replay: {self.state.script.source} records a drive fault (attempt {fault.attempt}) at "
                    f"{p.describe()} before its reading, but the drive was not commanded to the target again"
                )
            self._pending.popleft()
            self.state.clock.set_recorded(fault.time_s)
            if fault.kind == FaultKind.BEAM_BREAK:
                return LaserAnswer("beam", p)
            if fault.kind in (FaultKind.TIMEOUT, FaultKind.FRAMING):
                # the client retries a silent or garbled reply: stay so until the next move
                self._laser_mode = "silent" if fault.kind == FaultKind.TIMEOUT else "garbage"
                return LaserAnswer(self._laser_mode, p)
            return LaserAnswer("error", p, f"replayed fault: {fault.message}")
        if not p.has_value:
            return self._not_recorded()
        self.state.clock.set_recorded(p.time_s)
        self._last_served = p
        self.state.last_served = p
        self.state.served += 1
        self._cursor += 1
        nxt = self.current
        self._pending = deque(nxt.faults if nxt else ())
        self._at = "served"
        return LaserAnswer("value", p)

    def capture(self) -> ReplayPoint | FaultKind | None:
        """A compare pulse of an on-the-fly pass: the next recorded point, served as the sample
        latched at it (the drive's nut is at the pulse's position now).

        A pass the recording retried holds its failed attempts' faults at its first point; the
        reproducible kinds (`ONTHEFLY_FAULTS`) are replayed one attempt each, from that point's
        pulse on until the client asks what fails it (`capture_asked`): the kind is returned for
        every pulse of that attempt, and the instrument latches a BEAM sample (beam_break) or
        nothing (the others). None where a cut-short recording ends
        (`state.ended`; the instrument ends the run at the capture's count, as `reading` does),
        and, with the mismatch kept, when the next recorded point is not at this position and
        direction, holds a fault of another kind, or there is none."""
        if self._failing is not None:
            return self._failing.kind
        p = self.current
        if (p is None or not (p.has_value or self._pending)) and self.end_of_recording():
            return None  # a cut-short recording ends here: the instrument says so when asked the count
        x, d = self.x_mm, self.direction
        if p is None or p.direction != d or abs(x - p.target_mm) > max(self.state.target_tol_mm, 1e-5):
            self._arrival = (x, d)
            self._mismatch(self._describe_mismatch())
            return None
        if self._pending:
            fault = self._pending[0]
            if fault.kind not in ONTHEFLY_FAULTS:
                self._arrival = (x, d)
                self._mismatch(self._describe_mismatch() + f" (its recorded {fault.kind} fault is not replayed on the fly)")
                return None
            self._failing = self._pending.popleft()
            return fault.kind
        if not p.has_value:
            self._arrival = (x, d)
            self._mismatch(self._describe_mismatch())
            return None
        self.state.clock.set_recorded(p.time_s)
        self.load_n = p.load_n
        self._last_served = p
        self.state.last_served = p
        self.state.served += 1
        self._cursor += 1
        nxt = self.current
        self._pending = deque(nxt.faults if nxt else ())
        self._at = None
        return p

    def capture_asked(self, count: bool) -> str | None:
        """The client asks the capture's count (`count`) or its samples: where a recorded fault of
        a pass is being replayed, this is where its attempt fails, so the clock is set to the
        fault's recorded time (the client raises at once, and the sweep stamps the fault with
        it). An error: the count is short (latched nothing); a beam break: the first sample has
        no beam; a time-out or line noise: the count is answered with silence ("silent") or a
        garbled reply ("garbage"), also to the client's own retries, until the capture is armed
        again (`capture_armed`). Returns that mode, else None (answer as the instrument does)."""
        f = self._failing
        if f is None or (f.kind is FaultKind.BEAM_BREAK) == count:
            return None
        self.state.clock.set_recorded(f.time_s)
        if f.kind is FaultKind.TIMEOUT:
            return "silent"
        if f.kind is FaultKind.FRAMING:
            return "garbage"
        self._failing = None
        return None

    def capture_armed(self) -> None:
        """The capture is armed: a new attempt (a replayed time-out or line noise has ended)."""
        if self._failing is not None and self._failing.kind in (FaultKind.TIMEOUT, FaultKind.FRAMING):
            self._failing = None

    # -- when the recording does not hold what is asked -----------------------------------------
    def _not_recorded(self) -> LaserAnswer:
        ended = self.end_of_recording()
        if ended:
            return LaserAnswer("end", None, ended)
        return self._mismatch(self._describe_mismatch())

    def end_of_recording(self) -> str:
        """Why the recording has nothing more for this leg because it was cut short (every point
        replayed, outcome not completed), kept in `state.ended`; "" if that is not the case."""
        st = self.state
        script = st.script
        if st.all_served and script.outcome != "completed" and not (self.current and self.current.has_value):
            st.ended = st.ended or (
                f"replay: the recording {script.source} ends here (its outcome was {script.outcome}; "
                f"{script.value_points} points replayed)"
            )
            return st.ended
        return ""

    def _mismatch(self, message: str) -> LaserAnswer:
        if self.state.mismatch is None:
            self.state.mismatch = ReplayMismatch(message)
        return LaserAnswer("mismatch", None, message)

    def _describe_mismatch(self) -> str:
        script = self.state.script
        src = script.source
        leg = self.leg
        if not self.points:
            have = ", ".join(str(x) for x in script.legs) or "none"
            return f"replay: leg {leg} was not recorded in {src} (the recording has legs {have})"
        if self._arrival is None:
            return f"replay: leg {leg} was read before its drive moved to a recorded point of {src}"
        x, d = self._arrival
        cur = self.current
        targets = script.targets_of(leg)
        run = f" run {cur.run}" if cur is not None and cur.direction == d else ""
        asked = f"leg {leg}{run} target {x:.4f} mm (direction {d:+d})"
        if not any(abs(x - t) <= self.state.target_tol_mm for t in targets):
            return (f"replay: {asked} was not recorded in {src} (the recording has "
                    f"{_targets_text(targets)} for leg {leg})")
        if cur is None:
            return (f"replay: {asked} was asked after all {len(self.points)} recorded points of leg {leg} "
                    f"in {src} were replayed")
        return (f"replay: {asked} is not the next point {src} holds for leg {leg}; that is {cur.describe()} "
                "(a replay follows the recorded order)")


def _targets_text(targets: list[float]) -> str:
    if len(targets) <= 8:
        return "targets " + ", ".join(f"{t:.4f}" for t in targets) + " mm"
    head = ", ".join(f"{t:.4f}" for t in targets[:3])
    return f"{len(targets)} targets from {targets[0]:.4f} to {targets[-1]:.4f} mm ({head}, ...)"
