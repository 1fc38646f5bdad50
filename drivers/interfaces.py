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
)


@dataclass(frozen=True)
class DriveStatus:
    """A snapshot of one drive (one leg).

    `state` is the CiA 402 state name ("switch_on_disabled", "ready_to_switch_on",
    "switched_on", "operation_enabled", "quick_stop_active", "fault", "not_ready").
    `position_mm` is the drive-reported position actual in leg coordinates (with the active
    compensation table applied, as the drive reports it). `following_error_um` is the drive's
    demand minus actual, micrometres. `load_n` is the axial load from the drive's load cell
    input, newtons, compression positive.
    """

    state: str
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
        return self.state == "operation_enabled"


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
    faults, `CommTimeout` when the drive does not answer or does not arrive in time.
    `stop()` is a quick stop; it must be safe to call at any time, also after a fault.
    """

    leg: int

    def identity(self) -> str: ...
    def limits(self) -> DriveLimits: ...
    def status(self) -> DriveStatus: ...
    def enable(self) -> None: ...
    def disable(self) -> None: ...
    def reset_fault(self) -> None: ...
    def move_to(self, target_mm: float, timeout_s: float | None = None) -> DriveStatus: ...
    def stop(self) -> None: ...
    # compensation table
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


@runtime_checkable
class Clock(Protocol):
    """Time source. The simulated rig runs on a virtual clock (see drivers.clock)."""

    def now(self) -> float: ...
    def sleep(self, dt_s: float) -> None: ...
