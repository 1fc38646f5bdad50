"""The small interfaces every driver implements, and the values they exchange.

`procedures/` imports only this module (and `drivers.errors`) from `drivers/`: it never sees a
concrete driver class, so a live, simulated or replayed leg look the same to it.

Conventions (used everywhere in the project):
- Positions are in millimetres relative to the leg's mid-stroke reference (the paper's
  1095.85 mm nominal length), positive = leg longer.
- Errors are *measured minus commanded*, in micrometres: a positive error means the leg is
  longer than it was told to be.
- Direction of approach: +1 = arriving while the position increases, -1 = while it decreases.
- Times are seconds; `t_s` values are on the rig's clock (virtual on the simulated rig).
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

from drivers.errors import (  # noqa: F401  (re-exported for procedures)
    BeamBreak,
    CommTimeout,
    DriveFault,
    DriverError,
    FramingError,
    SoftLimitError,
    TableError,
    TableRefused,
)
from drivers.states import DriveState, FaultKind  # noqa: F401  (re-exported for procedures)


@dataclass(frozen=True)
class DriveStatus:
    """A snapshot of one drive (one leg).

    `state` is the CiA 402 state (a `DriveState`, equal to its name: "switch_on_disabled",
    "ready_to_switch_on", "switched_on", "operation_enabled", "quick_stop_active", "fault",
    "not_ready").
    `position_mm` is the drive-reported position actual in leg coordinates (with the active
    compensation table applied, as the drive reports it). `following_error_um` is the drive's
    demand minus actual, micrometres. `load_n` is the axial load from the drive's load cell
    input, newtons, compression positive.
    """

    state: DriveState
    fault: bool
    fault_code: int
    moving: bool
    target_reached: bool
    position_mm: float
    following_error_um: float
    load_n: float
    active_bank: int
    table_enabled: bool

    @property
    def enabled(self) -> bool:
        return self.state == DriveState.OPERATION_ENABLED


def table_sha256(table: "TableBank") -> str:
    """SHA-256 (hex) of a table's content: start, spacing (1e-6 mm) and both entry lists
    (1e-4 um), as canonical JSON. Independent of the bank and of the stored checksum: the one
    identity of a table for the audit log, the session and every table holder (drive or station)."""
    doc = {
        "start_mm": round(float(table.start_mm), 6),
        "spacing_mm": round(float(table.spacing_mm), 6),
        "error_fwd_um": [round(float(v), 4) for v in table.error_fwd_um],
        "error_rev_um": [round(float(v), 4) for v in table.error_rev_um],
    }
    return hashlib.sha256(json.dumps(doc, separators=(",", ":"), sort_keys=True).encode()).hexdigest()


@dataclass(frozen=True)
class TableBank:
    """One compensation table as held by a drive.

    `error_fwd_um[i]` / `error_rev_um[i]` are the predicted errors (measured minus commanded,
    um) at `start_mm + i * spacing_mm` when approaching in the positive / negative direction.
    The drive *subtracts* them from the command. `checksum` is CRC-16/MODBUS over the entry
    registers as stored (fwd then rev), as the drive computes it.
    """

    start_mm: float
    spacing_mm: float
    error_fwd_um: tuple[float, ...]
    error_rev_um: tuple[float, ...]
    checksum: int = 0

    @property
    def point_count(self) -> int:
        return len(self.error_fwd_um)

    def positions_mm(self) -> list[float]:
        return [self.start_mm + i * self.spacing_mm for i in range(self.point_count)]


@dataclass(frozen=True)
class TableSpec:
    """What compensation table a device holds: the one description of its limits.

    `max_points` per direction; `max_correction_um` the largest |entry|; `entry_resolution_um`
    um per stored count (entries are rounded to it; 0 = stored as given); `min_step_mm` the
    finest spacing; `banks` how many tables it holds (2 = write the inactive bank, then switch,
    so a failed write leaves the active table untouched; 1 = a file replaced whole).
    A drive without any table has no TableSpec (`ServoAxis.table_spec()` returns None).
    """

    max_points: int = 512
    max_correction_um: float = 300.0
    entry_resolution_um: float = 0.01
    min_step_mm: float = 0.001
    banks: int = 2
    holder: str = "the drive"  # who holds it, for messages: "the drive", "LinuxCNC", ...

    def check(self, table: "TableBank", where: str = "table", limits: "DriveLimits | None" = None,
              point_name=None, min_points: int = 2) -> None:
        """Refuse (TableRefused naming `where`, the point and the field) a table this device must
        not get: unequal directions, fewer than 2 or more than `max_points` points, a step that is
        not a finite number >= `min_step_mm`, positions beyond the soft `limits` (when given), or
        an entry that is not finite or beyond +/-`max_correction_um`.

        `point_name(i)` names point i (0-based) in messages (default "point i+1 (x mm)"; a CSV
        reader passes its row numbers). `min_points`: 2 for a table to push; a drive also holds an
        empty table (no correction) or a single constant, which have no step to check."""
        n = len(table.error_fwd_um)
        name = point_name or (lambda i: f"point {i + 1} ({table.start_mm + i * table.spacing_mm:+.4f} mm)")
        if len(table.error_rev_um) != n:
            raise TableRefused(f"{where}: the table has {n} forward but {len(table.error_rev_um)} reverse entries; "
                               "both directions need the same points.")
        if n < min_points:
            raise TableRefused(f"{where}: the table has {n} point(s); a table needs at least {min_points}.")
        if n > self.max_points:
            raise TableRefused(f"{where}: the table has {n} points ({name(self.max_points)} is one too many); "
                               f"{self.holder} holds at most {self.max_points}: make it with a coarser step "
                               "(`station table --step`).")
        if not (math.isfinite(table.start_mm) and math.isfinite(table.spacing_mm)) \
                or (n >= 2 and not table.spacing_mm >= self.min_step_mm - 1e-12):
            raise TableRefused(f"{where}, {name(1)}, field position_mm: the step {table.spacing_mm:g} mm is not a number >= the minimum "
                               f"step of {self.holder}, {self.min_step_mm:g} mm (positions must increase strictly).")
        end = table.start_mm + (n - 1) * table.spacing_mm
        if limits is not None and (table.start_mm < limits.min_mm - POSITION_TOL_MM or end > limits.max_mm + POSITION_TOL_MM):
            raise TableRefused(f"{where}: the table covers {table.start_mm:+.3f} .. {end:+.3f} mm, beyond the soft "
                               f"limits {limits.min_mm:+.3f} .. {limits.max_mm:+.3f} mm; make it with a step that ends "
                               "within them (`station table --step`).")
        for field_name, values in (("error_fwd_um", table.error_fwd_um), ("error_rev_um", table.error_rev_um)):
            for i, v in enumerate(values):
                if not math.isfinite(v) or abs(v) > self.max_correction_um:
                    raise TableRefused(f"{where}, {name(i)}, field {field_name}: {v:g} um is beyond the "
                                       f"correction limit of {self.holder}, +/-{self.max_correction_um:g} um.")

    def quantize(self, table: "TableBank") -> "TableBank":
        """`table` as this device will hold it: entries rounded to `entry_resolution_um`,
        positions to 1e-6 mm, checksum cleared (the device computes it)."""
        q = self.entry_resolution_um

        def r(vals: tuple[float, ...]) -> tuple[float, ...]:
            if not q > 0:
                return tuple(vals)
            return tuple(round(v / q) * q if math.isfinite(v) else v for v in vals)

        return TableBank(round(table.start_mm, 6), round(table.spacing_mm, 6), r(table.error_fwd_um), r(table.error_rev_um))


POSITION_TOL_MM = 1e-6
"""Table positions are stored to 1e-6 mm: an end this close beyond a soft limit is within it."""


@dataclass(frozen=True)
class DriveLimits:
    """Soft travel limits and motion limits from the drive (read from its registers)."""

    min_mm: float
    max_mm: float
    max_velocity_mm_s: float
    max_accel_mm_s2: float


@runtime_checkable
class ServoAxis(Protocol):
    """One leg's servo drive.

    `move_to` returns once the drive reports the target reached, and raises `SoftLimitError`
    (before any motion) for a target outside the soft limits, `DriveFault` when the drive
    faults, `CommTimeout` when the drive does not answer or does not arrive in time. Its
    `velocity_mm_s` is the speed of that move only (limited to `limits().max_velocity_mm_s`);
    None = the drive's own profile velocity (what a sweep uses).
    `stop()` is a quick stop; it must be safe to call at any time, also after a fault.
    `table_spec()` says what compensation table the drive holds (None: none; then the
    compensation lives elsewhere, see docs/compensation.md), and the table methods use it.
    `fault_text(code)` is the drive's own description of a fault code (`DriveStatus.fault_code`),
    e.g. "0x8612 soft_limit: target beyond ...", so a front end shows it without knowing the drive family.
    """

    leg: int

    def identity(self) -> str: ...
    def limits(self) -> DriveLimits: ...
    def status(self) -> DriveStatus: ...
    def enable(self) -> None: ...
    def disable(self) -> None: ...
    def reset_fault(self) -> None: ...
    def move_to(self, target_mm: float, timeout_s: float | None = None,
                velocity_mm_s: float | None = None) -> DriveStatus: ...
    def stop(self) -> None: ...
    def fault_text(self, code: int) -> str: ...
    # compensation table
    def table_spec(self) -> TableSpec | None: ...
    def read_table(self, bank: int) -> TableBank: ...
    def write_table(self, bank: int, table: TableBank) -> None: ...
    def activate_table(self, bank: int) -> None: ...
    def active_bank(self) -> int: ...
    def close(self) -> None: ...


@dataclass(frozen=True)
class Reading:
    """One interferometer position reading of one axis (leg).

    `position_mm` is the measured leg displacement relative to the zero set with `zero()`
    (normally mid-stroke), already corrected for the air refractive index by the instrument.
    `signal_pct` is the beam signal strength, 0-100. `beam_ok` is False when the beam is
    interrupted; the position is then meaningless (the driver raises `BeamBreak` instead of
    returning such a reading from `read`).
    """

    axis: int
    position_mm: float
    beam_ok: bool
    signal_pct: float
    t_s: float


@dataclass(frozen=True)
class Environment:
    """Environment sensors of the interferometer: air and per-leg material temperature."""

    air_temp_c: float
    air_pressure_hpa: float
    humidity_pct: float
    material_temp_c: tuple[float, ...] = field(default_factory=tuple)  # index 0 = leg 1

    def material_temp_of(self, leg: int) -> float:
        if 1 <= leg <= len(self.material_temp_c):
            return self.material_temp_c[leg - 1]
        return float("nan")


@runtime_checkable
class Interferometer(Protocol):
    """A (multi-axis) laser interferometer; axis n measures leg n."""

    def identity(self) -> str: ...
    def read(self, axis: int) -> Reading: ...
    def environment(self) -> Environment: ...
    def zero(self, axis: int) -> None: ...
    def set_averaging(self, averaging_s: float) -> None: ...
    def close(self) -> None: ...


# -- on-the-fly capture (docs/onthefly.md): optional abilities of an axis and an interferometer --

@runtime_checkable
class PositionCompareAxis(Protocol):
    """A drive with a position-compare output wired to the interferometer's trigger input: a
    pulse each time its position actual passes `start_mm + i * step_mm`, i = 0..count-1,
    moving in the direction of the sign of `step_mm`. Arming again replaces the list."""

    def arm_position_compare(self, start_mm: float, step_mm: float, count: int) -> None: ...


@runtime_checkable
class CapturingInterferometer(Protocol):
    """An interferometer that latches a reading at each trigger pulse (`arm_capture`), read
    back after the pass (`capture_sample`, or `capture_samples` for a run of them; BeamBreak for
    a sample taken without beam)."""

    def arm_capture(self, axis: int, count: int) -> None: ...
    def capture_count(self, axis: int) -> tuple[int, int]: ...
    def capture_sample(self, axis: int, index: int) -> Reading: ...
    def capture_samples(self, axis: int, start: int, count: int) -> list[Reading]: ...


@dataclass(frozen=True)
class StreamSample:
    """One sample of a streaming interferometer: `t_s` its time stamp on the station's clock,
    `position_mm` its reading (air-compensated, relative to the zero, + = leg longer)."""

    t_s: float
    position_mm: float


@runtime_checkable
class StreamingInterferometer(Protocol):
    """An interferometer that streams samples without a trigger input (the µLine-F1): an
    on-the-fly pass aligns its samples with the drive's traced positions on the station's clock
    (docs/onthefly.md, "A laser without trigger input")."""

    def stream_samples(self, axis: int, t0_s: float, t1_s: float) -> list[StreamSample]: ...


@runtime_checkable
class LatchingInterferometer(Protocol):
    """An interferometer that latches a lost signal (the µLine-F1's small-signal flag): every
    sample after a beam break carries it until `clear_signal_latch` (a stop-and-go reading clears
    it as its window opens; an on-the-fly pass's retry has it cleared first,
    procedures/acquisition/passes.py LaserRecovery)."""

    def clear_signal_latch(self, axis: int) -> None: ...


@runtime_checkable
class TracingAxis(Protocol):
    """A drive whose position actual can be polled during a move (`move_traced`): (time on the
    station's clock, position mm) per poll."""

    def move_traced(self, target_mm: float, velocity_mm_s: float, interval_s: float = 0.02,
                    timeout_s: float | None = None) -> tuple[DriveStatus, list[tuple[float, float]]]: ...


@runtime_checkable
class Clock(Protocol):
    """Time source. The simulated rig runs on a virtual clock (see drivers.clock)."""

    def now(self) -> float: ...
    def sleep(self, dt_s: float) -> None: ...
