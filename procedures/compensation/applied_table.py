"""Which compensation table a leg applies, as a session records it at the start of a sweep.

`applied_table(axis)` reads the leg's table state through the `ServoAxis` interface (a drive's
banks or the station-side table, drivers/station_compensation.py) and returns what a session
stores in its `devices` (meta attribute, written when the file is created, so a session killed
mid-sweep still says which table was applied): key `leg{N}_compensation_table`, a JSON object

    {"target": "drive" | "station", "enabled": bool, "bank": int, "points": int,
     "sha256": str ("" for an empty table), "start_mm": float, "spacing_mm": float,
     "store": path of the station's table store (target station only)}

or {"target": ..., "error": "..."} when the state could not be read.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any, Mapping

from drivers.errors import DriverError
from drivers.interfaces import ServoAxis, table_sha256

DEVICES_KEY = "leg{leg}_compensation_table"
"""The `devices` key of a leg's applied table in a session file."""


@dataclass(frozen=True)
class TableState:
    """Whether a leg's errors are compensated now, and by what: table compensation on or off,
    the active bank and the table in it (`point_count` entries from `start_mm`, every
    `spacing_mm`). `error`: the state could not be read (the other fields are then unknown)."""

    enabled: bool = False
    bank: int | None = None
    point_count: int = 0
    start_mm: float = math.nan
    spacing_mm: float = math.nan
    error: str = ""

    @property
    def active(self) -> bool:
        """Table compensation is on and its active bank holds points."""
        return self.enabled and self.point_count > 0 and not self.error

    @property
    def text(self) -> str:
        """The state in words: what a session records as `leg{N}_compensation` (the same text
        as before this type, which older readers and files hold)."""
        if self.error:
            return f"unknown ({self.error})"
        if not self.enabled:
            return "table compensation off"
        if self.point_count == 0:
            return f"bank {self.bank} active, empty"
        return f"bank {self.bank} active, {self.point_count} points from {self.start_mm:+.3f} mm every {self.spacing_mm:g} mm"

    @classmethod
    def from_record(cls, record: Mapping[str, Any]) -> "TableState":
        """The state a session recorded as `leg{N}_compensation_table` (`applied_table`). Raises
        ValueError or TypeError for a record that is not one."""
        if record.get("error"):
            return cls(error=str(record["error"]))
        points = record.get("points", 0)
        if isinstance(points, bool) or not isinstance(points, int):
            raise TypeError(f"points must be an integer, got {points!r}")
        bank = record.get("bank")
        return cls(enabled=bool(record.get("enabled")), bank=None if bank is None else int(bank), point_count=points,
                   start_mm=float(record.get("start_mm", math.nan)), spacing_mm=float(record.get("spacing_mm", math.nan)))


def compensation_target(axis: ServoAxis) -> str:
    """Where `axis`'s table is applied: "station" for the station-side wrapper (its
    `compensation_target` attribute), else "drive"."""
    return str(getattr(axis, "compensation_target", "drive"))


def target_details(axis: ServoAxis) -> dict[str, Any]:
    """The details naming the target (and the station's store file, where it applies): the start of
    what a session records here, and of every audit entry of a push (procedures/compensation/push.py)."""
    target = compensation_target(axis)
    d: dict[str, Any] = {"target": target}
    store = getattr(getattr(axis, "store", None), "path", None)
    if target == "station" and store is not None:
        d["store"] = str(store)
    return d


def applied_table(axis: ServoAxis) -> dict[str, Any]:
    """The table `axis` applies now (module docstring)."""
    d = target_details(axis)
    try:
        st = axis.status()
        d.update(enabled=bool(st.table_enabled), bank=int(st.active_bank))
        if axis.table_spec() is None:
            d.update(points=0, sha256="")
            return d
        table = axis.read_table(st.active_bank)
    except Exception as exc:  # noqa: BLE001  (a record must never stop the sweep it describes)
        d["error"] = str(exc) if isinstance(exc, DriverError) else f"{type(exc).__name__}: {exc}"
        return d
    d.update(points=table.point_count, sha256=table_sha256(table) if table.point_count else "",
             start_mm=float(table.start_mm), spacing_mm=float(table.spacing_mm))
    return d


def applied_tables_devices(axes: dict[int, ServoAxis], legs) -> dict[str, str]:
    """`devices` entries (JSON text) of every leg in `legs`."""
    return {DEVICES_KEY.format(leg=leg): json.dumps(applied_table(axes[leg]), sort_keys=True) for leg in legs}


def recorded_tables(devices: dict[str, Any]) -> dict[int, dict[str, Any]]:
    """Per leg, the applied table a session's `devices` records ({} for sessions from before)."""
    out: dict[int, dict[str, Any]] = {}
    for key, value in (devices or {}).items():
        if key.startswith("leg") and key.endswith("_compensation_table"):
            try:
                out[int(key[3:-len("_compensation_table")])] = json.loads(value) if isinstance(value, str) else dict(value)
            except (ValueError, TypeError):
                continue
    return out
