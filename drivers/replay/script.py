"""What the replay devices answer: a recording's points and faults, per leg, in recorded order.

Built from the arrays of a session file (field names of procedures/io/recording/schema.py; this
module takes plain structured arrays so drivers never import procedures). Every value a device
reports over its protocol must be known, so a point with an unknown (NaN) measured position,
drive position, load, time or air value is refused here, when the replay is opened, with the
point and field named; a material temperature may be unknown (the instrument reports NAN), and so
may the signal level of a point read on the move (`speed_mm_s` recorded): a streaming laser's pass
(the µLine-F1) has no signal level at a target, so the replay instrument sends `UNKNOWN_SIGNAL_PCT`
for it and the replay's recorder writes the recorded NaN back (station.services.jobs).

Faults are attached to the point they hit (by plan index), in attempt order. A session that was
resumed after giving up at a point holds two episodes for that point: the one that ended the
first run (gave up) and the one of the resumed run; a replay runs once, so it keeps the episode
that led to the recorded outcome (see `_episode`).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from drivers.replay.replay_errors import ReplayDataError
from drivers.states import FaultKind

FAULT_KINDS = tuple(FaultKind)
"""Fault kinds the replay devices reproduce (the sweep's `Fault.kind` values: every `FaultKind`)."""

DEFAULT_DRIVE_FAULT_CODE = 0x8611  # following error: used when a recorded message names no code

# Fields the devices report over their protocols: unknown values cannot be sent.
_REPORTED = ("measured_mm", "drive_position_mm", "time_s", "air_temp_c", "air_pressure_hpa",
             "humidity_pct", "load_n", "signal_pct")
UNKNOWN_SIGNAL_PCT = 0.0
"""What the replay instrument sends for a recorded unknown (NaN) signal level (a point of a streamed
pass): the station's protocol must carry a number in 0..100 there."""
_CODE = re.compile(r"0x([0-9A-Fa-f]{4})")


@dataclass(frozen=True)
class ReplayFault:
    """One recorded fault at a point: `kind` (FAULT_KINDS), the sweep's `attempt` number,
    `time_s` on the session clock (s since the session start), the recorded `message`, and for
    drive faults the drive's fault `code` (taken from the message, else a following-error code)."""

    attempt: int
    kind: FaultKind
    time_s: float
    message: str
    gave_up: bool
    code: int = 0


@dataclass(frozen=True)
class ReplayPoint:
    """One recorded point (units in the names; error = measured - target, direction +1 =
    approached upwards). `has_value` is False for a point that only holds faults (the session
    stopped there): the replay reproduces its faults and then has nothing to read."""

    index: int
    leg: int
    run: int
    direction: int
    target_mm: float
    has_value: bool = True
    drive_position_mm: float = math.nan
    measured_mm: float = math.nan
    time_s: float = math.nan
    air_temp_c: float = math.nan
    air_pressure_hpa: float = math.nan
    humidity_pct: float = math.nan
    material_temp_c: float = math.nan
    load_n: float = math.nan
    signal_pct: float = math.nan
    faults: tuple[ReplayFault, ...] = field(default=())

    def describe(self) -> str:
        return f"leg {self.leg} run {self.run} target {self.target_mm:.4f} mm (direction {self.direction:+d}, point index {self.index})"


@dataclass(frozen=True)
class ReplayScript:
    """Per leg, the points in recorded order (`legs[leg]`), plus where they came from.

    `source` names the recording in messages; `outcome` is its outcome ("completed",
    "aborted", "failed", "incomplete"); `sha256` and `session_id` identify it (the replay
    devices put them into their identity strings).
    """

    legs: Mapping[int, tuple[ReplayPoint, ...]]
    source: str = "the recording"
    outcome: str = "completed"
    sha256: str = ""
    session_id: str = ""

    @property
    def value_points(self) -> int:
        """Points with a recorded reading (what a replay serves)."""
        return sum(1 for pts in self.legs.values() for p in pts if p.has_value)

    @property
    def first(self) -> ReplayPoint | None:
        """The first recorded point with a value (environment before anything was replayed)."""
        candidates = [p for pts in self.legs.values() for p in pts if p.has_value]
        return min(candidates, key=lambda p: p.index) if candidates else None

    def targets_of(self, leg: int) -> list[float]:
        return sorted({p.target_mm for p in self.legs.get(leg, ())})

    @classmethod
    def from_arrays(
        cls,
        points: np.ndarray,
        faults: np.ndarray | None = None,
        *,
        source: str = "the recording",
        outcome: str = "completed",
        sha256: str = "",
        session_id: str = "",
        directions: Mapping[int, int] | None = None,
    ) -> "ReplayScript":
        """Build the script from a session's /points and /faults rows (file order).

        `directions` maps plan index -> direction for points that only hold faults (their
        direction is not in the fault rows); without it, odd runs count as +1 (the sweep's
        numbering). Raises ReplayDataError naming the point and field of the first problem.
        """
        points = np.asarray(points)
        faults = np.asarray(faults) if faults is not None else None
        by_index: dict[int, dict] = {}
        order: list[int] = []
        for row in points:
            index = int(row["index"])
            if index in by_index:
                raise ReplayDataError(f"{source}: point index {index} is recorded twice; the file is inconsistent")
            where = f"{source}: point index {index} (leg {int(row['leg'])} run {int(row['run'])} target {float(row['target_mm']):.4f} mm)"
            on_the_move = "speed_mm_s" in row.dtype.names and math.isfinite(float(row["speed_mm_s"]))
            for name in _REPORTED:
                if name == "signal_pct" and on_the_move:
                    continue  # a streamed pass's reading has no signal level (see the module's doc)
                if not math.isfinite(float(row[name])):
                    raise ReplayDataError(
                        f"{where} has no recorded {name} (NaN); the replay devices report it over the "
                        "drive/interferometer protocol, which cannot carry an unknown value"
                    )
            direction = int(row["direction"])
            if direction not in (1, -1):
                raise ReplayDataError(f"{where}: direction {direction} is not +1 or -1")
            by_index[index] = dict(
                index=index, leg=int(row["leg"]), run=int(row["run"]), direction=direction,
                target_mm=float(row["target_mm"]), has_value=True,
                drive_position_mm=float(row["drive_position_mm"]), measured_mm=float(row["measured_mm"]),
                time_s=float(row["time_s"]), air_temp_c=float(row["air_temp_c"]),
                air_pressure_hpa=float(row["air_pressure_hpa"]), humidity_pct=float(row["humidity_pct"]),
                material_temp_c=float(row["material_temp_c"]), load_n=float(row["load_n"]),
                signal_pct=float(row["signal_pct"]),
            )
            order.append(index)
        grouped: dict[int, list[ReplayFault]] = {}
        fault_rows: dict[int, np.void] = {}
        for i, row in enumerate(faults if faults is not None else ()):
            kind = _text(row["kind"])
            index = int(row["index"])
            if kind not in FAULT_KINDS:
                raise ReplayDataError(
                    f"{source}: fault row {i} (point index {index}) has kind {kind!r}, which the replay devices "
                    f"cannot reproduce (they reproduce {', '.join(FAULT_KINDS)})"
                )
            message = _text(row["message"])
            code = 0
            kind = FaultKind(kind)
            if kind is FaultKind.DRIVE_FAULT:
                m = _CODE.search(message)
                code = int(m.group(1), 16) if m else DEFAULT_DRIVE_FAULT_CODE
            grouped.setdefault(index, []).append(ReplayFault(
                attempt=int(row["attempt"]), kind=kind, time_s=float(row["time_s"]), message=message,
                gave_up=bool(row["gave_up"]), code=code,
            ))
            fault_rows.setdefault(index, row)
        for index, row in fault_rows.items():
            if index not in by_index:  # the session stopped at this point: no reading recorded
                run = int(row["run"])
                d = (directions or {}).get(index)
                by_index[index] = dict(
                    index=index, leg=int(row["leg"]), run=run, direction=int(d) if d else (1 if run % 2 else -1),
                    target_mm=float(row["target_mm"]), has_value=False,
                )
        legs: dict[int, list[ReplayPoint]] = {}
        value_order = {index: n for n, index in enumerate(order)}
        # recorded points in file order; a point holding only faults goes before the first
        # recorded point with a larger plan index (the sweep runs in plan order)
        def position(index: int) -> tuple[int, int]:
            if index in value_order:
                return (value_order[index], 1)
            later = [value_order[i] for i in order if i > index]
            return (min(later) if later else len(order), 0)

        for index in sorted(by_index, key=position):
            d = by_index[index]
            episode = _episode(grouped.get(index, []), d["has_value"])
            legs.setdefault(d["leg"], []).append(ReplayPoint(**d, faults=episode))
        return cls({leg: tuple(pts) for leg, pts in sorted(legs.items())}, source, outcome, sha256, session_id)


def _episode(faults: list[ReplayFault], has_value: bool) -> tuple[ReplayFault, ...]:
    """The faults a single run meets at one point.

    Episodes end at a fault that gave up (the session stopped and was resumed later). A point
    with a reading keeps the faults after the last give-up (those of the run that measured it);
    a point without one keeps its trailing faults, or else the last episode that gave up.
    """
    episodes: list[list[ReplayFault]] = [[]]
    for f in faults:
        episodes[-1].append(f)
        if f.gave_up:
            episodes.append([])
    if has_value or episodes[-1]:
        return tuple(episodes[-1])
    return tuple(episodes[-2]) if len(episodes) > 1 else ()


def _text(value) -> str:
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    return str(value)
