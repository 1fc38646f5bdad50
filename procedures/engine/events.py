"""Events a procedure yields. Frozen dataclasses; front ends and sinks only present them.

The base class, the sweep's lifecycle and what every run may yield (pause, message, fault). An
event carrying a procedure's own payload lives beside that payload (procedures.compensation:
`AuditRecord` in audit.py, `TablePlanned`, `TablePushed`, `OperationFinished` in push.py,
`LegChecked`, `Verified` in verify.py), so the engine imports no domain; a measured point is the
recording schema's `PointRecord` (procedures/io/recording/schema.py, a module of types only).

Units are in the field names; `t_s` is on the rig clock (virtual on the simulated rig).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from drivers.interfaces import FaultKind
from procedures.io.recording.schema import PointRecord
from procedures.vocabulary import Outcome


@dataclass(frozen=True)
class Event:
    pass


@dataclass(frozen=True)
class SweepStarted(Event):
    session_id: str
    legs: tuple[int, ...]
    total_points: int
    plan: dict[str, Any]  # the plan as JSON-able data
    devices: dict[str, str]  # leg/instrument -> identity string
    resumed_points: int = 0  # points already on disk when resuming


@dataclass(frozen=True)
class LegStarted(Event):
    leg: int


@dataclass(frozen=True)
class PointMeasured(Event):
    """One point measured: `record` is its row of the session's /points."""

    record: PointRecord
    done: int  # points done including this one
    total: int


@dataclass(frozen=True)
class Fault(Event):
    """A fault during a sweep. `gave_up` is True once retries are exhausted."""

    index: int
    leg: int
    run: int
    target_mm: float
    kind: FaultKind
    message: str
    attempt: int
    gave_up: bool
    t_s: float = 0.0


@dataclass(frozen=True)
class Paused(Event):
    """The run is paused (yielded by `RunControl.checkpoint`, before any further motion)."""


@dataclass(frozen=True)
class Resumed(Event):
    pass


@dataclass(frozen=True)
class Message(Event):
    text: str
    level: str = "info"  # info / warning / error


@dataclass(frozen=True)
class SweepFinished(Event):
    outcome: Outcome  # COMPLETED / ABORTED / FAILED
    points: int
    reason: str = ""


@dataclass(frozen=True)
class PassesStopped(Event):
    """Adaptive stopping (procedures/acquisition/adaptive.py): `leg` needs no more passes after `cycles`
    cycles. `reason` says why (the rule and the figures); `heldout_um` lists the
    cross-validated held-out RMS after each round, um; `skipped_points` were planned, not measured."""

    leg: int
    cycles: int
    reason: str
    heldout_um: tuple[float, ...]
    noise_floor_um: float | None
    skipped_points: int


@dataclass(frozen=True)
class ProbesStopped(Event):
    """The adaptive probe count (procedures/acquisition/probe_rule.py): `leg` needs no more reversal
    probe pairs after `pairs`. `reason` says why (the target reached, or the most pairs taken);
    `stderr_um` is the reversal's standard error then (None: not known), `target_um` the plan's;
    `skipped_points` were planned, not measured."""

    leg: int
    pairs: int
    reason: str
    stderr_um: float | None
    target_um: float
    skipped_points: int
