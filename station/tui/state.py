"""What the UI knows about the current (or last) sweep, folded from procedure events.

Owned and mutated by the app's thread only (the bridge posts events as messages). Screens
read it to draw, so a sweep survives screen changes and redraws; the app tells them when it has
changed with a `SweepChanged` message (station.tui.messages), they never poll it.

The status follows the procedure's events (`apply`): "paused" and "running" again come from its
Paused / Resumed events (procedures.engine.control.RunControl.checkpoint), the outcome from
SweepFinished, never from the operator's request. The one request state is "aborting"
(`request_abort`), set by the app's abort action while the run winds down.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import procedures.engine.events as ev  # the contract: what procedures yield, front ends present
from station.progress import Eta


@dataclass
class LegTrace:
    """Measured points of one leg, split by approach direction (+1 up, -1 down)."""

    up_target_mm: list[float] = field(default_factory=list)
    up_error_um: list[float] = field(default_factory=list)
    down_target_mm: list[float] = field(default_factory=list)
    down_error_um: list[float] = field(default_factory=list)

    def add(self, target_mm: float, error_um: float, direction: int) -> None:
        if direction > 0:
            self.up_target_mm.append(target_mm)
            self.up_error_um.append(error_um)
        else:
            self.down_target_mm.append(target_mm)
            self.down_error_um.append(error_um)

    @property
    def count(self) -> int:
        return len(self.up_target_mm) + len(self.down_target_mm)


@dataclass
class SweepState:
    """status: "idle" / "starting" / "running" / "paused" / "aborting" / then the outcome
    ("completed" / "aborted" / "failed" / "error")."""

    out: Path | None = None
    label: str = "sweep"  # "sweep", or "replay of NAME"
    note: str = ""  # said when it ended (a replay's comparison with its recording)
    legs: tuple[int, ...] = ()
    plan_kind: str = ""
    status: str = "idle"
    session_id: str = ""
    done: int = 0
    total: int = 0
    resumed_points: int = 0
    current_leg: int | None = None
    traces: dict[int, LegTrace] = field(default_factory=dict)
    last_record: dict[str, float] = field(default_factory=dict)
    faults: list[ev.Fault] = field(default_factory=list)
    stops: list[ev.PassesStopped] = field(default_factory=list)  # adaptive stopping: why a leg stopped
    probe_stops: list[ev.ProbesStopped] = field(default_factory=list)  # adaptive probe count: why a leg's probes stopped
    reason: str = ""
    elapsed_s: float = 0.0
    eta_s: float | None = None
    result: Any = None  # what the job returned when it ended (a verification's JobOutcome)
    # lowest and highest target of the plan (mm, from SweepStarted): the live plot's x axis spans
    # it from the first point on (plotext alone would centre it on the first target: -45..-135)
    target_span: tuple[float, float] | None = None
    _eta: Eta = field(default_factory=Eta)

    @property
    def active(self) -> bool:
        """True while the sweep worker runs (the drives may move)."""
        return self.status in ("starting", "running", "paused", "aborting")

    def request_abort(self) -> bool:
        """The operator asked to abort (StationApp.action_abort_sweep, the only caller): show
        "aborting" until SweepFinished says how it ended. False if it was asked already or the
        sweep is not running."""
        if not self.active or self.status == "aborting":
            return False
        self.status = "aborting"
        return True

    def apply(self, event: ev.Event) -> bool:
        """Fold `event` in; True if it changed what the screens show."""
        if isinstance(event, ev.SweepStarted):
            self.session_id = event.session_id
            self.legs = tuple(event.legs)
            self.total = event.total_points
            self.done = self.resumed_points = event.resumed_points
            targets = (event.plan or {}).get("targets_mm") or []
            if len(targets):
                self.target_span = (float(min(targets)), float(max(targets)))
            if self.status != "aborting":
                self.status = "running"
        elif isinstance(event, ev.LegStarted):
            self.current_leg = event.leg
            self.traces.setdefault(event.leg, LegTrace())
        elif isinstance(event, ev.PointMeasured):
            r = event.record
            leg = int(r["leg"])
            self.current_leg = leg
            self.traces.setdefault(leg, LegTrace()).add(float(r["target_mm"]), float(r["error_um"]), int(r["direction"]))
            self.last_record = dict(r)
            self.done, self.total = event.done, event.total
            self.elapsed_s, self.eta_s = self._eta.update(event.done, event.total)
        elif isinstance(event, ev.Fault):
            self.faults.append(event)
        elif isinstance(event, ev.PassesStopped):
            self.stops.append(event)
            self.total -= event.skipped_points  # planned, no longer needed: the bar ends full
        elif isinstance(event, ev.ProbesStopped):
            self.probe_stops.append(event)
            self.total -= event.skipped_points
        elif isinstance(event, ev.Paused):
            if self.status != "aborting":
                self.status = "paused"
        elif isinstance(event, ev.Resumed):
            if self.status != "aborting":
                self.status = "running"
        elif isinstance(event, ev.SweepFinished):
            self.status = event.outcome
            self.done = event.points
            self.reason = event.reason
            self.eta_s = None
        else:
            return False
        return True


@dataclass(frozen=True)
class EventNotice:
    """A notification an event of a running job asks for (the app shows it)."""

    text: str
    title: str
    severity: str  # "information" / "warning" / "error"
    timeout: float


def event_notice(event: ev.Event, label: str) -> EventNotice | None:
    """The notification `event` of the job named `label` ("sweep", "verification of leg 2")
    asks for, by its type: a fault (retrying or given up), a warning message of a sweep (e.g. a
    calibration sweep on a leg whose compensation table is active); None for every other event."""
    if isinstance(event, ev.Fault):
        return EventNotice(f"leg {event.leg} run {event.run} at {event.target_mm:+.3f} mm: {event.message}",
                           f"{event.kind} ({'gave up' if event.gave_up else f'attempt {event.attempt}, retrying'})",
                           "error" if event.gave_up else "warning", 10)
    if isinstance(event, ev.Message) and event.level != "info" and label == "sweep":
        return EventNotice(event.text, "Sweep", "warning", 15)
    return None
